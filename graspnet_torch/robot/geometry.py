"""Shapes of a URDF's links (boxes, cylinders, spheres, meshes), for pictures and collisions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.chain import UrdfModel, origin_matrix
from graspnet_torch.robot.meshes import load_link_mesh

__all__ = ["Shape", "link_shapes"]

GREY = (0.6, 0.6, 0.6, 1.0)


@dataclass(frozen=True, eq=False)
class Shape:
    """A shape attached to a link.

    Attributes:
        link: link name.
        kind: 'box' | 'cylinder' | 'sphere' | 'mesh'.
        size: box (x, y, z) full extents; cylinder (radius, length) along its z; sphere (radius,);
            mesh: the URDF's scale (x, y, z), already applied to ``mesh``.
        origin: (4, 4) pose of the shape in the link frame.
        rgba: colour from the URDF material (grey if none).
        mesh: a mesh's ``trimesh.Trimesh`` (V vertices, M faces) in the shape's frame, scaled;
            shared with a cache: do not modify it. None for primitives.
    """

    link: str
    kind: str
    size: tuple[float, ...]
    origin: np.ndarray
    rgba: tuple[float, float, float, float] = GREY
    mesh: object = None


def link_shapes(model: UrdfModel, source: str = "collision", errors: list[str] | None = None) -> list[Shape]:
    """Every shape of every link; ``source`` is 'collision' or 'visual'.

    Meshes are loaded (``robot/meshes.py`` resolves their URIs, within the model's folders). A mesh
    that lies outside them, cannot be found or cannot be loaded is a one-line :class:`ConfigError`
    naming the link, the URI and where it looked; when ``errors`` (a list) is given, it is
    skipped instead and that line appended (pictures).
    """
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
            mesh = None
            if isinstance(g, Box):
                kind, size = "box", tuple(float(s) for s in g.size)
            elif isinstance(g, Cylinder):
                kind, size = "cylinder", (float(g.radius), float(g.length))
            elif isinstance(g, Sphere):
                kind, size = "sphere", (float(g.radius),)
            elif isinstance(g, Mesh) and g.filename:
                scale = np.broadcast_to(np.asarray(g.scale if g.scale is not None else 1.0, dtype=np.float64), (3,))
                try:
                    mesh = load_link_mesh(g.filename, model.path, scale,
                                          f"{model.path.name}: link '{link.name}' {source}", model.mesh_roots,
                                          model.allow_outside_paths)
                except ConfigError as exc:
                    if errors is None:
                        raise
                    errors.append(str(exc))
                    continue
                kind, size = "mesh", tuple(float(s) for s in scale)
            else:
                raise ConfigError(f"{model.path.name}: link '{link.name}' has {type(g).__name__} "
                                  f"{source} geometry; only box, cylinder, sphere and mesh are supported")
            shapes.append(Shape(link.name, kind, size, origin_matrix(el.origin), rgba, mesh))
    return shapes
