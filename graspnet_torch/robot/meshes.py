"""Mesh files of a URDF: where a ``<mesh filename=...>`` lies, loading (cached) and decimation.

A URI is resolved, first match wins:

- ``package://<pkg>/rel/path``: (a) ``<folder>/rel/path`` for every folder named ``<pkg>`` among
  the URDF's folder and its parents; (b) ``rel/path`` inside an installed Python package named
  ``<pkg>`` (or ``<pkg>`` with ``-`` -> ``_``); (c) ``rel/path`` against the URDF's folder (the
  package prefix stripped).
- ``file:///abs/path`` or ``file://rel/path``, an absolute path, or a relative path: against the
  URDF's folder.

Only files within the robot's own folders are read (:func:`mesh_roots`: the URDF's folder, the
robot config's folder, the repository, installed packages), unless the robot config allows any
path (``allow_outside_paths``); a URI outside gets the same message whether or not a file is there.

Meshes are loaded by :func:`graspnet_torch.meshes.load_mesh` (the package's one loader, without
its vertex merging), cached per (file, modification time, scale): the returned
``trimesh.Trimesh`` objects are shared and must not be modified in place.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from graspnet_torch.errors import ConfigError
from graspnet_torch.files import allowed_roots, confined_file
from graspnet_torch.meshes import check_mesh_file, load_mesh
from graspnet_torch.settings import clip

__all__ = ["PICTURE_FACES", "decimate", "load_link_mesh", "mesh_candidates", "mesh_roots", "package_candidates",
           "package_roots", "resolve_mesh", "urdf_file"]

PICTURE_FACES = 2000  # meshes with more faces are decimated for pictures


def package_roots(pkg: str) -> list[Path]:
    """Folders of an installed Python package named ``pkg`` (or ``pkg`` with '-' -> '_'), found
    without importing it."""
    roots: list[Path] = []
    for name in dict.fromkeys((pkg, pkg.replace("-", "_"))):
        if not name.isidentifier():
            continue
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError):
            continue
        if spec is None:
            continue
        locations = list(spec.submodule_search_locations or [])
        if not locations and spec.origin:
            locations = [str(Path(spec.origin).parent)]
        roots += [Path(p) for p in locations]
    return roots


def package_candidates(pkg: str, rel: str, folder: str | Path) -> list[Path]:
    """The files ``package://<pkg>/<rel>`` may name seen from ``folder``, in the order they are
    tried: ``rel`` in every folder named ``pkg`` among ``folder`` and its parents, then in the
    installed Python package ``pkg`` (:func:`package_roots`). ``rel`` is already unquoted."""
    folder = Path(folder).resolve()
    out = [parent / rel for parent in (folder, *folder.parents) if parent.name == pkg]
    return out + [root / rel for root in package_roots(pkg)]


def urdf_file(raw: str, where: str, bases: tuple[Path, ...], allow_outside: bool) -> Path:
    """The URDF a config names: a path (relative to ``bases``, see :func:`confined_file`) or
    ``package://<python package>/<path>``, resolved like a mesh URI (:func:`package_candidates`:
    a folder named ``<python package>`` above the config, then the installed package, found
    without importing it)."""
    if not raw.startswith("package://"):
        return confined_file(raw, where, bases, ConfigError, allow_outside)
    pkg, _, rel = raw[len("package://"):].partition("/")
    rel = unquote(rel)
    if not pkg or not rel.strip("/") or Path(rel).is_absolute() or "\x00" in rel or len(raw) > 4096:
        raise ConfigError(f"{where}: expected package://<python package>/<path inside it>, got {clip(raw, 120)}")
    if ".." in Path(rel).parts:
        raise ConfigError(f"{where}: {clip(raw, 120)}: '..' would lead out of package '{clip(pkg, 60)}'")
    installed = package_roots(pkg)
    candidates = package_candidates(pkg, rel, bases[0])
    if not candidates:
        hint = f" (pip install {pkg.replace('_', '-')})" if pkg.replace("-", "_").isidentifier() else ""
        raise ConfigError(f"{where}: {clip(raw, 120)}: Python package '{clip(pkg, 60)}' is not installed{hint}")
    found = next((c for c in candidates if _is_file(c)), None)
    if found is None:
        looked = ", ".join(dict.fromkeys(str(c.parent) for c in candidates))
        raise ConfigError(f"{where}: {clip(raw, 120)}: no file '{clip(rel, 120)}' in package '{clip(pkg, 60)}' "
                          f"(looked in {clip(looked, 300)})")
    # the package named is trusted as a base (an editable install may live outside site-packages);
    # '..' or a link leading out of it is refused like any path
    return confined_file(str(found), where, (*bases, *installed), ConfigError, allow_outside)


def mesh_candidates(uri: str, urdf_path: str | Path) -> list[Path]:
    """Every file a mesh URI may name, in the order they are tried (see the module docstring)."""
    folder = Path(urdf_path).resolve().parent
    if uri.startswith("package://"):
        pkg, _, rel = uri[len("package://"):].partition("/")
        rel = unquote(rel)
        return [*package_candidates(pkg, rel, folder), folder / rel]
    if uri.startswith("file://"):
        uri = unquote(uri[len("file://"):])
    return [folder / Path(uri)]  # an absolute path stays absolute


def mesh_roots(uri: str, urdf_path: str | Path, roots: Sequence[str | Path] = ()) -> tuple[Path, ...]:
    """The folders a URDF's mesh may lie in: the URDF's folder, ``roots`` (the robot config's
    folder), for ``package://<pkg>/...`` the folder ``<pkg>`` holding the URDF or its folder (the
    ROS layout ``<pkg>/urdf/``, ``<pkg>/meshes/``) and the installed Python package ``<pkg>``, the
    repository and the installed packages (:func:`graspnet_torch.files.allowed_roots`)."""
    folder = Path(urdf_path).resolve().parent
    own = [folder, *(Path(r) for r in roots)]
    if uri.startswith("package://"):
        pkg = uri[len("package://"):].partition("/")[0]
        own += [p for p in (folder, folder.parent) if p.name == pkg]
        own += [r for r in package_roots(pkg) if _is_file(r / "__init__.py")]  # a package, not any folder on sys.path
    return allowed_roots(tuple(own))


def _is_file(path: Path) -> bool:
    try:
        return path.is_file()
    except (OSError, ValueError):  # a name too long for the file system, a NUL byte
        return False


def _inside(path: Path, roots: tuple[Path, ...]) -> bool:
    try:
        real = path.resolve()  # '..' and symbolic links resolved: neither leads out
    except (OSError, RuntimeError, ValueError):  # a link loop, a NUL byte
        return False
    return any(real == r or real.is_relative_to(r) for r in roots)


def resolve_mesh(uri: str, urdf_path: str | Path, what: str = "mesh", roots: Sequence[str | Path] = (),
                 allow_outside: bool = False) -> Path:
    """The file a mesh URI names, or a one-line :class:`ConfigError` saying where it looked.

    Only files within :func:`mesh_roots` are looked at, unless ``allow_outside``: a URI that
    names nothing inside them is refused with the same message whether or not a file is there.
    """
    candidates = mesh_candidates(uri, urdf_path)
    if not allow_outside:
        allowed = mesh_roots(uri, urdf_path, roots)
        candidates = [c for c in candidates if _inside(c, allowed)]
        if not candidates:
            raise ConfigError(f"{what}: mesh '{clip(uri, 160)}' is outside the URDF's folder, the robot config's "
                              f"folder, the repository and installed packages; set allow_outside_paths=true to use it")
    for path in candidates:
        if _is_file(path):
            return path
    looked = ", ".join(dict.fromkeys(str(p.parent) for p in candidates))
    raise ConfigError(f"{what}: mesh '{clip(uri, 160)}' not found (looked in {clip(looked, 400)})")


def load_link_mesh(uri: str, urdf_path: str | Path, scale=None, what: str = "mesh", roots: Sequence[str | Path] = (),
                   allow_outside: bool = False) -> tuple[Path, object]:
    """The file a URDF ``<mesh>`` names and its ``trimesh.Trimesh``, in its own frame with ``scale``
    (3 numbers, or one) applied; cached and shared (do not modify it). A file that is missing, outside the
    robot's folders (:func:`resolve_mesh`; ``roots``, ``allow_outside``) or that trimesh cannot
    read is a one-line :class:`ConfigError` starting with ``what``."""
    path = resolve_mesh(uri, urdf_path, what, roots, allow_outside)
    s = np.broadcast_to(np.asarray(scale if scale is not None else 1.0, dtype=np.float64), (3,))
    check_mesh_file(path, f"{what}: mesh '{clip(uri, 160)}'", ConfigError, s)  # before trimesh parses it
    try:
        mesh = load_mesh(path.resolve(), s, merge=False)
        if len(mesh.faces) == 0:
            raise ValueError("no triangles")
        return path, mesh
    except Exception as exc:  # trimesh raises assorted types on unreadable or foreign files
        reason = clip(" ".join(f"{type(exc).__name__}: {exc}".split()), 160)
        raise ConfigError(f"{what}: mesh '{clip(uri, 160)}' ({path}) could not be loaded ({reason})") from None


def decimate(mesh, max_faces: int = PICTURE_FACES):
    """A mesh with at most ``max_faces`` faces, for pictures; never fails. Quadric decimation when
    fast_simplification is installed, else vertex clustering on shrinking grids, else an even
    subsample of the faces. mesh: a ``trimesh.Trimesh`` -> a ``trimesh.Trimesh``."""
    import trimesh

    if len(mesh.faces) <= max_faces:
        return mesh
    try:
        out = mesh.simplify_quadric_decimation(face_count=max_faces)
        if 0 < len(out.faces) <= max_faces:
            return out
    except Exception:  # fast_simplification absent or failing: cluster instead
        pass
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    try:
        vertices, faces = _cluster(vertices, faces, max_faces)
    except Exception:  # pragma: no cover - numerical trouble: subsample below
        pass
    if len(faces) > max_faces:
        faces = faces[np.linspace(0, len(faces) - 1, max_faces).astype(np.int64)]
    return trimesh.Trimesh(vertices, faces, process=False)


def _cluster(vertices: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering: vertices (V, 3) merged per cell of an n^3 grid over the bounding box
    (n shrinking until at most ``max_faces`` faces (M, 3) survive), faces that collapse dropped."""
    lo = vertices.min(0)
    span = max(float(np.ptp(vertices, axis=0).max()), 1e-12)
    for n in (64, 48, 32, 24, 16, 12, 8, 6, 4, 3):
        cell = np.minimum(np.floor((vertices - lo) / span * n), n - 1).astype(np.int64)
        _, inverse, counts = np.unique(cell, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1)
        f = inverse[faces]
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
        f = f[np.sort(first)]
        if len(f) <= max_faces:
            break
    merged = np.zeros((len(counts), 3))
    np.add.at(merged, inverse, vertices)
    return merged / counts[:, None], f
