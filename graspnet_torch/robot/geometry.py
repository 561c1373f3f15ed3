"""Primitive shapes of a URDF's links (boxes, cylinders, spheres), for pictures and collisions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.chain import UrdfModel, rpy_matrix_np

__all__ = ["Shape", "link_shapes"]


@dataclass(frozen=True)
class Shape:
    """A primitive attached to a link.

    Attributes:
        link: link name.
        kind: 'box' | 'cylinder' | 'sphere'.
        size: box (x, y, z) full extents; cylinder (radius, length) along its z; sphere (radius,).
        origin: (4, 4) pose of the shape in the link frame.
        rgba: colour from the URDF material (grey if none).
    """

    link: str
    kind: str
    size: tuple[float, ...]
    origin: np.ndarray
    rgba: tuple[float, float, float, float] = (0.6, 0.6, 0.6, 1.0)


def _origin(origin) -> np.ndarray:
    T = np.eye(4)
    if origin is not None:
        T[:3, :3] = rpy_matrix_np(origin.rpy or (0, 0, 0))
        T[:3, 3] = origin.xyz or (0, 0, 0)
    return T


def link_shapes(model: UrdfModel, source: str = "collision") -> list[Shape]:
    """Every primitive of every link; ``source`` is 'collision' or 'visual'.

    Mesh geometry is refused: the shipped robots use primitives only (fast, exact collision checks).
    """
    from pytorch_kinematics.urdf_parser_py.urdf import Box, Cylinder, Sphere

    materials = {m.name: m for m in model.robot.materials}
    shapes = []
    for link in model.robot.links:
        visual_colors = []
        for v in link.visuals:
            mat = v.material
            color = getattr(mat, "color", None) if mat is not None else None
            if color is None and mat is not None and mat.name in materials:
                color = getattr(materials[mat.name], "color", None)
            visual_colors.append(tuple(color.rgba) if color is not None else (0.6, 0.6, 0.6, 1.0))
        elements = link.collisions if source == "collision" else link.visuals
        for k, el in enumerate(elements):
            g = el.geometry
            rgba = visual_colors[k] if k < len(visual_colors) else (0.6, 0.6, 0.6, 1.0)
            if isinstance(g, Box):
                kind, size = "box", tuple(float(s) for s in g.size)
            elif isinstance(g, Cylinder):
                kind, size = "cylinder", (float(g.radius), float(g.length))
            elif isinstance(g, Sphere):
                kind, size = "sphere", (float(g.radius),)
            else:
                raise ConfigError(f"{model.path.name}: link '{link.name}' has {type(g).__name__} "
                                  f"{source} geometry; only box, cylinder and sphere are supported")
            shapes.append(Shape(link.name, kind, size, _origin(el.origin), rgba))
    return shapes
