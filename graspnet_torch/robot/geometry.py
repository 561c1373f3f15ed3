"""Shapes of a URDF's links (boxes, cylinders, spheres, meshes), for pictures and collisions: each
the package's one :class:`~graspnet_torch.robot.shape.Shape`, in its link's frame."""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from graspnet_torch.errors import ConfigError
from graspnet_torch.meshes import sample_even
from graspnet_torch.robot.chain import UrdfModel, origin_matrix, origin_pose
from graspnet_torch.robot.meshes import load_link_mesh
from graspnet_torch.robot.shape import Shape, primitive_mesh
from graspnet_torch.robot.transforms import matrix_to_pose_np

__all__ = ["LinkShape", "link_shapes", "palm_shapes", "support", "surface_points"]

GREY = (0.6, 0.6, 0.6, 1.0)
_SHAPES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # UrdfModel -> source -> its shapes
_POINTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # LinkShape -> (count, vertices) -> points


@dataclass(frozen=True, eq=False)
class LinkShape:
    """A :class:`Shape` attached to a link, with what pictures and collisions use of it.

    Attributes:
        link: link name.
        shape: kind, size, pose (6,) in the link frame (the URDF ``<origin>``'s xyz and rpy), and a
            mesh's file and per-axis scale (x, y, z) (a mesh's size is ()).
        origin: (4, 4) the shape's pose in the link frame as a matrix, exact (made from the URDF's
            numbers, or a product of exact matrices): collisions and pictures place the shape by it.
        rgba: colour from the URDF material (grey if none).
        mesh: a mesh's ``trimesh.Trimesh`` (V vertices, M faces) in the shape's frame, scaled;
            shared with a cache: do not modify it. None for primitives.
    """

    link: str
    shape: Shape
    origin: np.ndarray
    rgba: tuple[float, float, float, float] = GREY
    mesh: object = None

    @property
    def kind(self) -> str:
        """The shape's kind: 'box' | 'cylinder' | 'sphere' | 'mesh'."""
        return self.shape.kind

    @property
    def size(self) -> tuple[float, ...]:
        """The shape's size: box (x, y, z) full extents; cylinder (radius, length) along its z;
        sphere (radius,); mesh ()."""
        return self.shape.size

    @classmethod
    def placed(cls, link: str, kind: str, size: tuple[float, ...], origin: np.ndarray,
               rgba: tuple[float, float, float, float] = GREY) -> LinkShape:
        """A primitive placed by an origin (4, 4) in the link frame, kept exact (its shape's pose
        is the origin's, to round-off)."""
        origin = np.asarray(origin, dtype=np.float64)
        return cls(link, Shape(kind, tuple(size), matrix_to_pose_np(origin)), origin, rgba)


def link_shapes(model: UrdfModel, source: str = "collision", errors: list[str] | None = None) -> list[LinkShape]:
    """Every shape of every link; ``source`` is 'collision' or 'visual'.

    Meshes are loaded (``robot/meshes.py`` resolves their URIs, within the model's folders). A mesh
    that lies outside them, cannot be found or cannot be loaded is a one-line :class:`ConfigError`
    naming the link, the URI and where it looked; when ``errors`` (a list) is given, it is
    skipped instead and that line appended (pictures). Without ``errors``, a model's shapes are read
    once and shared (the same :class:`LinkShape` objects on every call; a new list each time).
    """
    if errors is not None:
        return _read_shapes(model, source, errors)
    cached = _SHAPES.setdefault(model, {})
    if source not in cached:
        cached[source] = tuple(_read_shapes(model, source, None))
    return list(cached[source])


def _read_shapes(model: UrdfModel, source: str, errors: list[str] | None) -> list[LinkShape]:
    """:func:`link_shapes`, read from the URDF and its mesh files."""
    from pytorch_kinematics.urdf_parser_py.urdf import Box, Cylinder, Mesh, Sphere

    materials = {m.name: m for m in model.robot.materials}
    shapes = []
    for link in model.robot.links:
        visual_colors = []
        for v in link.visuals:
            mat = v.material
            color = getattr(mat, "color", None) if mat is not None else None
            if color is None and mat is not None and mat.name in materials:
                color = getattr(materials[mat.name], "color", None)
            visual_colors.append(tuple(color.rgba) if color is not None else GREY)
        elements = link.collisions if source == "collision" else link.visuals
        for k, el in enumerate(elements):
            g = el.geometry
            rgba = visual_colors[k] if k < len(visual_colors) else GREY
            mesh, path, scale = None, None, 1.0
            if isinstance(g, Box):
                kind, size = "box", tuple(float(s) for s in g.size)
            elif isinstance(g, Cylinder):
                kind, size = "cylinder", (float(g.radius), float(g.length))
            elif isinstance(g, Sphere):
                kind, size = "sphere", (float(g.radius),)
            elif isinstance(g, Mesh) and g.filename:
                axes = np.broadcast_to(np.asarray(g.scale if g.scale is not None else 1.0, dtype=np.float64), (3,))
                try:
                    path, mesh = load_link_mesh(g.filename, model.path, axes,
                                                f"{model.path.name}: link '{link.name}' {source}", model.mesh_roots,
                                                model.allow_outside_paths)
                except ConfigError as exc:
                    if errors is None:
                        raise
                    errors.append(str(exc))
                    continue
                kind, size, scale = "mesh", (), tuple(float(s) for s in axes)
            else:
                raise ConfigError(f"{model.path.name}: link '{link.name}' has {type(g).__name__} "
                                  f"{source} geometry; only box, cylinder, sphere and mesh are supported")
            shape = Shape(kind, size, origin_pose(el.origin), path, scale)
            shapes.append(LinkShape(link.name, shape, origin_matrix(el.origin), rgba, mesh))
    return shapes


def support(s: LinkShape, P: np.ndarray, n: np.ndarray) -> float:
    """The largest ``n . x`` (m) over the surface of a shape placed by ``P`` (4, 4) (the shape's
    frame in the frame of ``n`` (3,), unit): how far the shape reaches along ``n``."""
    if s.kind == "mesh":
        vertices = np.asarray(s.mesh.vertices, dtype=np.float64) @ P[:3, :3].T + P[:3, 3]
        return float((vertices @ n).max())
    d, c = P[:3, :3].T @ n, float(n @ P[:3, 3])
    if s.kind == "box":
        return c + float(np.abs(d) @ (np.asarray(s.size) / 2))
    if s.kind == "cylinder":
        return c + s.size[0] * math.hypot(d[0], d[1]) + s.size[1] / 2 * abs(d[2])
    return c + s.size[0]


def surface_points(s: LinkShape, P: np.ndarray, count: int, vertices: int | None = None) -> np.ndarray:
    """(N, 3) points over the surface of a shape placed by ``P`` (4, 4): its mesh's vertices (a
    primitive's: a fine triangulation's; at most ``vertices`` of them, evenly strided, where given)
    and up to ``count`` more spread evenly over it (the same points on every call), in the frame
    ``P`` maps into (m)."""
    points = _POINTS.setdefault(s, {}).get((count, vertices))
    if points is None:
        mesh = s.mesh if s.kind == "mesh" else primitive_mesh(s.kind, s.size, fine=True)
        corners = np.asarray(mesh.vertices, dtype=np.float64)
        if vertices is not None and len(corners) > vertices:
            corners = corners[:: math.ceil(len(corners) / vertices)]
        points = np.concatenate([corners, sample_even(mesh, count)])
        points.flags.writeable = False
        _POINTS[s][(count, vertices)] = points
    return points @ P[:3, :3].T + P[:3, 3]


def palm_shapes(model: UrdfModel, palm: str) -> list[tuple[LinkShape, np.ndarray]]:
    """The palm's collision shapes, each with its placement (4, 4) in the palm link's frame: the
    palm link's and those of the links fixed to it (a hand's base under a wrist frame)."""
    fixed = {palm}
    grew = True
    while grew:
        grew = False
        for child, joint in model.parent_joint.items():
            if joint.parent in fixed and joint.type == "fixed" and child not in fixed:
                fixed.add(child)
                grew = True
    return [(s, model.fixed_transform(palm, s.link) @ s.origin) for s in link_shapes(model) if s.link in fixed]
