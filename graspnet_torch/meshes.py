"""Mesh files a user names (a problem's object or obstacle, a URDF link's geometry), checked before
anything is built from them.

:func:`check_mesh_file` refuses, in one line naming the file, before the mesh is used:

- a format other than STL, OBJ, PLY, OFF, GLB, glTF and DAE; an archive in particular (zip, tar,
  bz2, 3MF, ...: trimesh unpacks them whole, so a 1 MiB file can inflate to gigabytes), whatever
  its name says;
- more than :func:`max_mesh_faces` triangles (or three times as many vertices): counted from the
  file itself before it is parsed for STL, PLY, OFF and OBJ (a PLY header may declare millions of
  faces in a few bytes), then from what trimesh read for the others;
- a face that names a vertex the file does not have, a vertex that is not finite (for an OBJ, its
  line) or that lies beyond +-10 m once scaled, all on the file as written (trimesh's processing
  drops a NaN vertex and its faces without a word);
- ``solid`` (a problem's shapes, cut into convex pieces): no triangle of non-zero area, or a
  surface flatter than :data:`MIN_THICKNESS_M` (a single triangle, a plane, a tiny scale), which
  has no inside to cut.

:func:`load_trimesh` is trimesh's loader with the side files a mesh names (OBJ materials and
textures, glTF buffers) limited to regular files of at most ``MAX_MESH_BYTES`` in the mesh's folder;
:func:`load_mesh` is the one loader of a mesh file, a problem's object or obstacle or a URDF link's
(cached). :func:`sample_even` spreads points over a mesh's surface (trimesh's even sampling,
without its log line when the sample comes out smaller than asked).
"""

from __future__ import annotations

import os
import re
import stat
from functools import lru_cache
from pathlib import Path

import numpy as np

from graspnet_torch.errors import ConfigError, GraspnetError
from graspnet_torch.files import MAX_MESH_BYTES, regular_file_stat
from graspnet_torch.settings import MAX_LENGTH_M, clip

__all__ = [
    "FACES_VARIABLE",
    "MAX_MESH_FACES",
    "MESH_FORMATS",
    "MIN_THICKNESS_M",
    "check_mesh_file",
    "load_mesh",
    "load_trimesh",
    "max_mesh_faces",
    "mesh_format",
    "mesh_path",
    "sample_even",
]

MAX_MESH_FACES = 200_000  # the largest mesh of pybullet_data has 124,789; a robot's link or an object far fewer
FACES_VARIABLE = "GRASPNET_TORCH_MAX_MESH_FACES"  # raises MAX_MESH_FACES
MESH_FORMATS = ("stl", "obj", "ply", "off", "glb", "gltf", "dae")
ARCHIVES = {b"PK\x03\x04": "zip", b"\x1f\x8b": "gzip", b"BZh": "bzip2", b"\xfd7zXZ\x00": "xz",
            b"7z\xbc\xaf\x27\x1c": "7z", b"\x28\xb5\x2f\xfd": "zstd"}
ARCHIVE_SUFFIXES = ("zip", "gz", "tgz", "bz2", "xz", "7z", "zst", "tar", "zae", "3mf", "3dxml")
MIN_THICKNESS_M = 1e-4  # a solid mesh spans at least 0.1 mm in every direction


def max_mesh_faces() -> int:
    """The most triangles a mesh file may have: :data:`MAX_MESH_FACES`, or the environment
    variable ``GRASPNET_TORCH_MAX_MESH_FACES``."""
    text = os.environ.get(FACES_VARIABLE, "").strip()
    if not text:
        return MAX_MESH_FACES
    value = int(text) if re.fullmatch(r"[0-9]{1,10}", text) else 0
    if not 1 <= value <= 100_000_000:
        raise ConfigError(f"{FACES_VARIABLE}={clip(text, 40)}: expected an integer in [1, 100000000]")
    return value


def mesh_format(path: Path, where: str, error: type[GraspnetError]) -> str:
    """The format trimesh will read ``path`` as (its suffix, lower case), refused unless it is one
    of :data:`MESH_FORMATS`."""
    name = Path(path).name.lower()
    suffix = name.rpartition(".")[2] if "." in name else ""
    if suffix in ARCHIVE_SUFFIXES:
        raise error(f"{where}: {clip(Path(path).name, 80)} is an archive (.{suffix}); name the mesh file "
                    f"itself, unpacked")
    if suffix not in MESH_FORMATS:
        raise error(f"{where}: {clip(Path(path).name, 80)} is not a mesh file: expected one of "
                    f"{', '.join('.' + f for f in MESH_FORMATS)}")
    return suffix


def check_mesh_file(path: str | os.PathLike, where: str, error: type[GraspnetError], scale=1.0,
                    solid: bool = False) -> None:
    """Refuse a mesh file that is not safe and sensible to use (see the module docstring), with
    one line ``where: <file> ...`` of class ``error``.

    Args:
        scale: one number or three (x, y, z): the file's units to metres; bounds are checked scaled.
        solid: the mesh must enclose a volume (a problem's object or obstacle).
    """
    p = Path(path)
    mesh_format(p, where, error)
    st = regular_file_stat(p, error(f"{where}: file not found: {clip(str(p), 120)}"),
                           error(f"{where}: {clip(p.name, 80)} is not a regular file"))
    s = tuple(float(v) for v in np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)))
    reason = _reason(str(p.resolve()), st.st_mtime_ns, st.st_size, s, solid, max_mesh_faces())
    if reason:
        raise error(f"{where}: {clip(p.name, 80)} {reason}")


def load_trimesh(path: str | os.PathLike, **kwargs):
    """``trimesh.load(path, force="mesh", **kwargs)`` with side files limited (module docstring)."""
    import trimesh

    return trimesh.load(Path(path), force="mesh", resolver=_resolver(Path(path)), **kwargs)


def load_mesh(path: str | os.PathLike, scale=1.0, merge: bool = True):
    """A mesh file as one ``trimesh.Trimesh`` (a scene's geometry concatenated), scaled: the one
    loader of the package's meshes, a problem's object or obstacle and a URDF link's alike.

    Args:
        path: the file (a problem's or a URDF's, already resolved and checked by
            :func:`check_mesh_file`).
        scale: one number or (3,) per axis, applied to the vertices.
        merge: also merge vertices split by texture seams or normals, so that a closed surface is
            watertight (a problem's shapes); False leaves trimesh's processing alone (a link's mesh).
    Returns:
        The mesh, cached per (file, modification time, scale, merge) and shared: do not modify it.
    """
    p = Path(path)
    s = tuple(float(v) for v in np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)))
    return _load(p, os.stat(p).st_mtime_ns, s, merge)


@lru_cache(maxsize=1024)
def mesh_path(path: str | os.PathLike) -> Path:
    """A mesh file's absolute path, links resolved: the key of the per-mesh caches (distance grid,
    inside test, convex pieces), remembered per path as given (the searches ask it on every call)."""
    return Path(path).resolve()


@lru_cache(maxsize=256)
def _load(path: Path, mtime_ns: int, scale: tuple[float, float, float], merge: bool):
    mesh = load_trimesh(path)
    if merge:
        mesh.merge_vertices(merge_tex=True, merge_norm=True)
    if scale != (1.0, 1.0, 1.0):
        mesh.apply_scale(np.asarray(scale))
    return mesh


def _resolver(path: Path):
    from trimesh.resolvers import FilePathResolver

    class Bounded(FilePathResolver):
        def absolute(self, name: str) -> Path:
            found = super().absolute(name)
            try:
                st = os.stat(found)
            except OSError:
                return found  # not there: trimesh tries its next candidate
            if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_MESH_BYTES:
                raise ValueError(f"{name}: not a regular file of at most {MAX_MESH_BYTES} bytes")
            return found

    return Bounded(str(path))


@lru_cache(maxsize=256)
def _reason(path: str, mtime_ns: int, size: int, scale: tuple[float, float, float], solid: bool,
            limit: int) -> str | None:
    """Why the file is refused (the line's end, after its name), or None."""
    if size > MAX_MESH_BYTES:
        return f"has {size} bytes, more than the {MAX_MESH_BYTES} allowed"
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_MESH_BYTES + 1)
    except OSError as exc:
        return f"cannot be read ({exc.strerror})"
    for magic, kind in ARCHIVES.items():
        if data.startswith(magic):
            return f"is a {kind} archive, not a mesh; name the mesh file itself, unpacked"
    fmt = path.rpartition(".")[2].lower()
    counts = _declared_counts(data, fmt, limit)
    if counts is not None and (too_many := _too_many(*counts, limit)):
        return too_many
    try:
        mesh = load_trimesh(path, process=False)
        vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
        faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    except Exception as exc:  # trimesh raises assorted types on files it cannot read
        return f"is not a mesh trimesh can read ({type(exc).__name__})"
    if len(faces) == 0:
        return "holds no triangles"
    if too_many := _too_many(len(faces), len(vertices), limit):
        return too_many
    if faces.min() < 0 or faces.max() >= len(vertices):
        k = int(np.flatnonzero((faces < 0).any(1) | (faces >= len(vertices)).any(1))[0])
        return f"has a face (number {k + 1}) naming a vertex it does not have ({len(vertices)} vertices)"
    bad = ~np.isfinite(vertices).all(1)
    if bad.any():
        line = _obj_nonfinite_line(data) if fmt == "obj" else None
        at = f"line {line}" if line else f"vertex {int(np.flatnonzero(bad)[0]) + 1}"
        return f"has a vertex that is not a finite number ({at})"
    scaled = vertices * np.asarray(scale)
    scale_text = f"{scale[0]:g}" if len(set(scale)) == 1 else " ".join(f"{v:g}" for v in scale)
    hint = f"at scale {scale_text} (a mesh's units are metres once scaled: e.g. scale 0.001 for millimetres)"
    if not np.all(np.abs(scaled) <= MAX_LENGTH_M):  # a scale that is not finite too
        return f"has vertices beyond +-{MAX_LENGTH_M:g} m {hint}"
    return _flat(scaled, faces, hint) if solid else None


def _too_many(faces: int, vertices: int, limit: int) -> str | None:
    raise_it = f"set the environment variable {FACES_VARIABLE} to raise it"
    if faces > limit:
        return f"has {faces} triangles, more than the {limit} allowed ({raise_it})"
    if vertices > 3 * limit:
        return f"has {vertices} vertices, more than the {3 * limit} allowed (3 per triangle; {raise_it})"
    return None


def _flat(vertices: np.ndarray, faces: np.ndarray, hint: str) -> str | None:
    """Why a solid mesh has no inside to cut (no triangle with an area, or flat), or None."""
    tri = vertices[faces]
    span = float(np.ptp(tri.reshape(-1, 3), axis=0).max())
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) / 2
    used = tri[area > 1e-12 * span**2].reshape(-1, 3)
    if len(used) == 0:
        return "has no triangle with an area (every one is degenerate): it encloses no volume"
    centred = used - used.mean(0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    thickness = float(np.ptp(centred @ axes.T, axis=0).min())
    if thickness < MIN_THICKNESS_M:
        return (f"is {thickness:.3g} m thick across its thinnest direction {hint}; an object or obstacle must "
                f"enclose a volume at least {MIN_THICKNESS_M * 1000:g} mm thick")
    return None


def _declared_counts(data: bytes, fmt: str, limit: int) -> tuple[int, int] | None:
    """(triangles, vertices) the file holds, read without parsing it (STL, PLY, OFF, OBJ), or None."""
    if fmt == "stl":
        if len(data) >= 84 and 84 + 50 * int.from_bytes(data[80:84], "little") == len(data):
            n = int.from_bytes(data[80:84], "little")  # binary
        else:
            n = data.lower().count(b"endfacet")  # ascii
        return n, 3 * n
    if fmt == "ply":
        end = data.find(b"end_header", 0, 1 << 16)
        counts = dict(re.findall(rb"^element[ \t]+(\w+)[ \t]+(\d{1,18})", data[:max(end, 0)], re.M))
        return int(counts.get(b"face", 0)), int(counts.get(b"vertex", 0))
    if fmt == "off":
        text = re.sub(rb"#[^\n]*", b"", data[:4096]).split()
        numbers = [int(t) for t in text[1:3] if t.isdigit()] if text[:1] == [b"OFF"] else []
        return (numbers[1], numbers[0]) if len(numbers) == 2 else None
    if fmt == "obj":
        return _obj_counts(data, limit)
    return None


def _obj_counts(data: bytes, limit: int) -> tuple[int, int]:
    """(triangles, vertices) of an OBJ: its ``v`` lines, and for each ``f`` line of k vertices
    k - 2 triangles (a polygon is cut into a fan), counted in numpy over the whole file."""
    a = np.frombuffer(data, dtype=np.uint8)
    if len(a) == 0:
        return 0, 0
    starts = np.flatnonzero(a == 10) + 1
    starts = np.concatenate(([0], starts[starts < len(a)]))
    ends = np.append(starts[1:], len(a))
    second = a[np.minimum(starts + 1, len(a) - 1)]
    blank = (second == 32) | (second == 9)
    vertices = int(np.count_nonzero(blank & (a[starts] == ord("v"))))
    face_lines = blank & (a[starts] == ord("f"))
    if not face_lines.any() or np.count_nonzero(face_lines) > limit:  # too many already: no need to cut them
        return int(np.count_nonzero(face_lines)), vertices
    space = (a == 32) | (a == 9)
    token = np.zeros(len(a) + 1, dtype=np.int32)  # token[i + 1]: a word starts at i (after a blank)
    token[2:] = space[:-1] & ~space[1:] & (a[1:] != 10) & (a[1:] != 13)
    np.cumsum(token, out=token)
    corners = token[ends[face_lines]] - token[starts[face_lines]]
    return int(np.maximum(corners - 2, 0).sum()), vertices


def _obj_nonfinite_line(data: bytes) -> int | None:
    """The first line of an OBJ whose vertex (``v x y z``) is not finite, or None."""
    for m in re.finditer(rb"^[ \t]*v[ \t]+([^\n]*)", data, re.M):
        try:
            values = [float(t) for t in m.group(1).split()[:3]]
        except ValueError:
            continue
        if not all(np.isfinite(values)):
            return data.count(b"\n", 0, m.start()) + 1
    return None


def sample_even(mesh, count: int, seed: int = 0) -> np.ndarray:
    """(N, 3) float64 points spread evenly over a ``trimesh.Trimesh``'s surface, N <= ``count``:
    ``trimesh.sample.sample_surface_even`` (the same points for the same ``seed``), with the
    warning it logs when it rejects some of them (N < count) kept off the user's screen."""
    import logging

    import trimesh

    log = logging.getLogger("trimesh.sample")
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        samples, _ = trimesh.sample.sample_surface_even(mesh, count, seed=seed)
    finally:
        log.setLevel(level)
    return np.asarray(samples, dtype=np.float64)
