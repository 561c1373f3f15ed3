"""A robot's link shapes as spheres, for the loop's collision proxy.

Every collision primitive of the URDF becomes a few spheres fixed in its link:

- a sphere is itself;
- a cylinder (radius r, length L along z) becomes spheres of radius r whose centres run along
  the axis from -(L/2 - e) to (L/2 - e), e = min(r/4, L/2), at most r/2 apart: a capsule-like
  union whose waist is >= 0.97 r, which covers the rim (to within 3 % of r) and overshoots the
  flat ends by 3r/4 on the axis (the URDF's joint spheres sit there for most links);
- a box becomes spheres of radius rho (its smallest half-extent) on a grid over the box shrunk
  by rho, at most rho apart: a slab with rounded edges;
- a mesh becomes spheres that hug it, within a slack of it either way
  (:func:`~graspnet_torch.collision.mesh_spheres.mesh_spheres`; its grown oriented bounding box,
  :func:`mesh_box`, stays the self-collision model's primitive).

Each sphere hangs from one level frame of the robot's chains
(:func:`~graspnet_torch.robot.frames.link_attachments`); :func:`sphere_clusters` cuts each link's
spheres into clusters of at most ``CLUSTER`` neighbours with a bounding sphere each.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from graspnet_torch.collision.mesh_spheres import mesh_key, mesh_spheres
from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.frames import Attachment
from graspnet_torch.robot.geometry import LinkShape

__all__ = ["CLUSTER", "SphereClusters", "cylinder_axis_half", "mesh_box", "shape_spheres", "sphere_clusters"]

CLUSTER = 8  # spheres per cluster (a link's spheres are cut into clusters of at most this many)


def cylinder_axis_half(r: float, length: float) -> float:
    """How far along a cylinder's axis (r, length) its model reaches: L/2 - e, e = min(r/4, L/2)."""
    return length / 2 - min(r / 4, length / 2)


def mesh_box(shape: LinkShape) -> LinkShape:
    """A mesh link shape's conservative box, in the link frame: the mesh's oriented bounding box
    (trimesh; cached with the mesh), its half-extents h raised to at least max(h) / 8 (a thin
    plate would otherwise need thousands of spheres), then grown by rho / 2 on every side, rho =
    min(h): the box's sphere model (:func:`shape_spheres`) dimples its faces by up to 0.134 rho'
    and rounds its corners by up to 0.366 rho' / 2 along the diagonal (rho' = 1.5 rho, the grown
    box's), so the model of the grown box still covers the mesh. Other shapes are returned as
    they are."""
    if shape.kind != "mesh":
        return shape
    obb = shape.mesh.bounding_box_oriented
    half = np.asarray(obb.primitive.extents, dtype=np.float64) / 2
    half = np.maximum(half, half.max() / 8)
    half = half + half.min() / 2
    return LinkShape.placed(shape.link, "box", tuple(float(2 * h) for h in half),
                            shape.origin @ np.asarray(obb.primitive.transform, dtype=np.float64), shape.rgba)


def shape_spheres(shape: LinkShape) -> tuple[np.ndarray, np.ndarray]:
    """A link shape as spheres in its link's frame: centres (k, 3), radii (k,); a mesh by
    :func:`~graspnet_torch.collision.mesh_spheres.mesh_spheres` (once per file and scale)."""
    if shape.kind == "mesh":
        local, radii = mesh_spheres(shape.mesh, mesh_key(shape.shape.mesh, shape.shape.scale))
        return local @ shape.origin[:3, :3].T + shape.origin[:3, 3], radii
    if shape.kind == "sphere":
        local, radii = np.zeros((1, 3)), np.array([shape.size[0]])
    elif shape.kind == "cylinder":
        r, length = shape.size
        half = cylinder_axis_half(r, length)
        k = max(1, math.ceil(2 * half / (r / 2)) + 1)
        z = np.linspace(-half, half, k) if k > 1 else np.zeros(1)
        local, radii = np.stack([np.zeros(k), np.zeros(k), z], axis=1), np.full(k, r)
    elif shape.kind == "box":
        h = np.asarray(shape.size, dtype=np.float64) / 2
        rho = float(h.min())
        axes = []
        for hi in h - rho:
            k = max(1, math.ceil(2 * hi / rho) + 1)
            axes.append(np.linspace(-hi, hi, k) if k > 1 else np.zeros(1))
        local = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        radii = np.full(len(local), rho)
        # the slab's rounded rim misses the box's edges: spheres of radius rho/2 along the rim,
        # rho/2 inside both faces that meet there, at most rho/2 apart
        a = int(np.argmin(h))
        b, c = [i for i in range(3) if i != a]
        hb, hc, r2 = h[b] - rho / 2, h[c] - rho / 2, rho / 2
        rim = []
        for u0, u1, v0, v1 in ((-hb, hb, -hc, -hc), (hb, hb, -hc, hc), (hb, -hb, hc, hc), (-hb, -hb, hc, -hc)):
            k = max(2, math.ceil(max(abs(u1 - u0), abs(v1 - v0)) / r2) + 1)
            rim += [(u, v) for u, v in zip(np.linspace(u0, u1, k)[:-1], np.linspace(v0, v1, k)[:-1], strict=True)]
        for side in (-1, 1):
            for u, v in rim:
                point = np.zeros(3)
                point[a], point[b], point[c] = side * (h[a] - r2), u, v
                local = np.vstack([local, point])
                radii = np.append(radii, r2)
    else:  # pragma: no cover - link_shapes makes no other kinds
        raise ConfigError(f"link '{shape.link}': no sphere model for {shape.kind}")
    centres = local @ shape.origin[:3, :3].T + shape.origin[:3, 3]
    return centres, radii


@dataclass
class SphereClusters:
    """Every link's spheres, in clusters of at most ``CLUSTER``, in the frames they hang from.

    Attributes:
        links: the links with spheres, in shape order.
        link_spheres: each link's sphere centres (k, 3) in its link frame, one array per shape.
        frame: (C,) each cluster's frame (``frame_id`` of its link's attachment).
        link: (C,) each cluster's link (index into ``links``).
        local: (C, 4, CLUSTER) homogeneous sphere centres in the cluster's frame (padding: zeros).
        radii: (C, CLUSTER) sphere radii (padding: NaN).
        bound: (C, 4, 1) homogeneous bounding-sphere centres; ``bound_r`` (C,) their radii.
    """

    links: list[str]
    link_spheres: dict[str, list[np.ndarray]]
    frame: list[int]
    link: list[int]
    local: np.ndarray
    radii: np.ndarray
    bound: np.ndarray
    bound_r: np.ndarray

    @property
    def n_spheres(self) -> int:
        return int(np.sum(~np.isnan(self.radii)))


def sphere_clusters(shapes: list[LinkShape], attachments: dict[str, Attachment],
                    frame_id: Callable[[Attachment], int]) -> SphereClusters:
    """The shapes' spheres (:func:`shape_spheres`) placed in their links' level frames
    (``attachments``: link -> :class:`~graspnet_torch.robot.frames.Attachment`), each link's cut
    into clusters of at most ``CLUSTER`` in order, ``frame_id`` numbering the frames."""
    by_link: dict[str, list] = {}
    link_spheres: dict[str, list[np.ndarray]] = {}
    for shape in shapes:
        G = attachments[shape.link].pose
        centres, radii_ = shape_spheres(shape)
        link_spheres.setdefault(shape.link, []).append(centres)  # in the link frame
        for c, r in zip(centres, radii_, strict=True):
            by_link.setdefault(shape.link, []).append((G[:3, :3] @ c + G[:3, 3], float(r)))
    clusters = []  # (frame id, link index, centres (k, 3), radii (k,))
    for li, (link, spheres) in enumerate(by_link.items()):
        for start in range(0, len(spheres), CLUSTER):
            chunk = spheres[start:start + CLUSTER]
            clusters.append((frame_id(attachments[link]), li, np.stack([c for c, _ in chunk]),
                             np.array([r for _, r in chunk])))
    C = len(clusters)
    local = np.zeros((C, 4, CLUSTER))
    radii = np.full((C, CLUSTER), np.nan)
    bound = np.zeros((C, 4, 1))
    bound_r = np.zeros(C)
    for k, (_f, _l, c, r) in enumerate(clusters):
        local[k, :3, :len(r)], local[k, 3, :len(r)], radii[k, :len(r)] = c.T, 1.0, r
        centre = (c.min(0) + c.max(0)) / 2
        bound[k, :3, 0], bound[k, 3, 0] = centre, 1.0
        bound_r[k] = float(np.max(np.linalg.norm(c - centre, axis=1) + r))
    return SphereClusters(list(by_link), link_spheres, [f for f, *_ in clusters], [li for _, li, *_ in clusters],
                          local, radii, bound, bound_r)
