"""The package's one shape: a box, cylinder, sphere or mesh file, placed by a pose in its parent frame.

A problem's object and obstacles are shapes in the world (``gt.Shape``, read from and written to
problem files here; :mod:`graspnet_torch.tasks.shapes` has the checks that involve a problem); a
URDF link's collision and visual shapes are shapes in their link's frame
(:class:`~graspnet_torch.robot.geometry.LinkShape`).

Every refusal of a file entry is a :class:`~graspnet_torch.errors.ProblemError` with one line that
names the file and the offending entry; files give angles in degrees, :class:`Shape` holds metres
and radians.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from graspnet_torch.errors import ProblemError
from graspnet_torch.files import confined_file
from graspnet_torch.meshes import check_mesh_file, load_mesh
from graspnet_torch.paths import repo_root
from graspnet_torch.robot.transforms import matrix_to_pose_np, pose_to_matrix_np
from graspnet_torch.settings import MAX_ANGLE_DEG, MAX_LENGTH_M, clip, number_list, short

__all__ = ["MAX_SCALE", "SHAPES", "Shape", "check_mesh", "numbers", "pose_degrees", "primitive_mesh", "unknown_keys"]

SHAPES = {"box": 3, "cylinder": 2, "sphere": 1}
MAX_SCALE = 1e6


def numbers(value: Any, n: int, where: str, what: str = "numbers", lo: float = -MAX_LENGTH_M,
            hi: float = MAX_LENGTH_M) -> np.ndarray:
    """n strict numbers (no bools, no strings), finite and within [lo, hi] (default: +-10 m)."""
    return np.asarray(number_list(value, n, where, ProblemError, lo, hi, what), dtype=np.float64)


def pose_degrees(value: Any, where: str) -> np.ndarray:
    """(x, y, z, rx, ry, rz) in metres and degrees -> metres and radians."""
    what = "numbers (x, y, z in m, rx, ry, rz in degrees)"
    p = numbers(value, 6, where, what, -MAX_ANGLE_DEG, MAX_ANGLE_DEG)
    if np.any(np.abs(p[:3]) > MAX_LENGTH_M):
        raise ProblemError(f"{where}: x, y, z must lie within +-{MAX_LENGTH_M:g} m, got {short(value)}")
    return np.concatenate([p[:3], np.radians(p[3:])])


def unknown_keys(data: Mapping, allowed: set[str]) -> list[str]:
    """The keys of ``data`` not in ``allowed``, as short strings (keys may be numbers in YAML)."""
    return sorted(clip(k, 40) for k in data if not isinstance(k, str) or k not in allowed)


@dataclass(frozen=True)
class Shape:
    """A box, cylinder, sphere or mesh file, placed by a pose in its parent frame.

    Attributes:
        kind: 'box' | 'cylinder' | 'sphere' | 'mesh'.
        size: box (x, y, z) full extents; cylinder (radius, height) along its z; sphere (radius,);
            mesh: ().
        pose: (6,) frame of the shape in its parent frame (m, rad): the world for a problem's
            object and obstacles, the link frame for a link's shape (the URDF ``<origin>``). The
            shape is centred on it (a mesh: its file's origin is there).
        mesh: path of a mesh file (kind 'mesh'): STL, OBJ, PLY, GLB, what trimesh reads.
        scale: a mesh's scale, its file's units to metres: one number (a problem file's, e.g.
            0.001 for millimetres) or (x, y, z) per axis (a URDF ``<mesh scale>``).
    """

    kind: str
    size: tuple[float, ...]
    pose: np.ndarray
    mesh: Path | None = None
    scale: float | tuple[float, float, float] = 1.0

    def __post_init__(self) -> None:  # a pose or size given as a list (Python callers) held as the others are
        object.__setattr__(self, "pose", np.asarray(self.pose, dtype=np.float64))
        object.__setattr__(self, "size", tuple(float(v) for v in self.size))
        if isinstance(self.mesh, str):
            object.__setattr__(self, "mesh", Path(self.mesh))

    @classmethod
    def from_mapping(cls, data: Any, where: str, folder: Path | None = None,
                     allow_outside_paths: bool = False) -> Shape:
        """Validate a shape; a mesh path is looked up in ``folder`` (the problem file's), then the
        repository, and must stay within those or an installed package unless ``allow_outside_paths``."""
        if not isinstance(data, Mapping):
            raise ProblemError(f"{where}: expected a mapping with shape, size and pose")
        unknown = unknown_keys(data, {"shape", "size", "pose", "name", "scale"})
        if unknown:
            raise ProblemError(f"{where}: unknown key(s) {', '.join(unknown)}")
        if data.get("scale") is not None and data.get("shape") != "mesh":
            raise ProblemError(f"{where}.scale: only a mesh takes a scale (give a {short(data.get('shape'))}'s size "
                               f"in metres)")
        kind = data.get("shape")
        if kind not in (*SHAPES, "mesh"):
            raise ProblemError(f"{where}.shape: expected box, cylinder, sphere or mesh, got {short(kind)}")
        pose = pose_degrees(data.get("pose", [0, 0, 0, 0, 0, 0]), f"{where}.pose")
        if kind == "mesh":
            size = data.get("size")
            paths = size if isinstance(size, list) else [size]
            if len(paths) != 1 or not isinstance(paths[0], str):
                raise ProblemError(f"{where}.size: a mesh's size is the path of its file")
            bases = (folder, repo_root()) if folder is not None else (repo_root(),)
            path = confined_file(paths[0], f"{where}.size", bases, ProblemError, allow_outside_paths)
            scale = data.get("scale", 1.0)
            if isinstance(scale, bool) or not isinstance(scale, int | float) or not math.isfinite(scale) \
                    or not 0 < scale <= MAX_SCALE:
                raise ProblemError(f"{where}.scale: expected a number in (0, {MAX_SCALE:g}] (the mesh file's unit in "
                                   f"metres, e.g. 0.001 for millimetres), got {short(scale)}")
            scale = float(scale)
            check_mesh(path, f"{where}.size", scale)
            return cls(kind, (), pose, path, scale)
        size = numbers(data.get("size"), SHAPES[kind], f"{where}.size")
        if np.any(size <= 0):
            raise ProblemError(f"{where}.size: dimensions must be positive, got {short(data.get('size'))}")
        return cls(kind, tuple(float(s) for s in size), pose)

    def to_mapping(self) -> dict:
        pose = [*self.pose[:3].tolist(), *np.degrees(self.pose[3:]).tolist()]
        size = [str(self.mesh)] if self.kind == "mesh" else list(self.size)
        out = {"shape": self.kind, "size": size, "pose": pose}
        if self.kind == "mesh" and self.scale != 1.0:
            out["scale"] = self.scale
        return out

    def moved(self, transform: np.ndarray) -> Shape:
        """The shape moved and turned by a rigid transform (4, 4) of its parent frame."""
        return replace(self, pose=matrix_to_pose_np(transform @ pose_to_matrix_np(self.pose)))

    def trimesh(self):
        """The shape as a trimesh.Trimesh in its parent frame (imports trimesh)."""

        if self.kind == "mesh":
            mesh = load_mesh(Path(self.mesh).resolve(), self.scale).copy()
        else:
            mesh = primitive_mesh(self.kind, self.size)
        return mesh.apply_transform(pose_to_matrix_np(self.pose))


def primitive_mesh(kind: str, size: tuple[float, ...], fine: bool = False):
    """A box, cylinder (along z) or sphere of ``size`` as a trimesh.Trimesh at the origin (imports
    trimesh); ``fine``: more facets (a cylinder of 128 sections, a sphere of 4 subdivisions, not 48 and 3)."""
    import trimesh

    if kind == "box":
        return trimesh.creation.box(extents=size)
    if kind == "cylinder":
        return trimesh.creation.cylinder(radius=size[0], height=size[1], sections=128 if fine else 48)
    if kind == "sphere":
        return trimesh.creation.icosphere(subdivisions=4 if fine else 3, radius=size[0])
    raise ValueError(f"no primitive '{kind}'")


def check_mesh(path: Path, where: str, scale: float = 1.0) -> None:
    """The file must be a solid triangle mesh of a sensible size, checked as written before it is
    parsed and processed (:func:`graspnet_torch.meshes.check_mesh_file`: format, face count,
    finite vertices within +-10 m once scaled, not flat), then load as one."""
    check_mesh_file(path, where, ProblemError, scale, solid=True)
    try:
        faces = len(load_mesh(Path(path).resolve(), scale).faces)
    except Exception as exc:  # trimesh raises assorted errors on files it cannot read
        raise ProblemError(f"{where}: {clip(path.name, 80)} is not a mesh trimesh can read "
                           f"({type(exc).__name__})") from None
    if faces == 0:
        raise ProblemError(f"{where}: {clip(path.name, 80)} holds no triangles")
