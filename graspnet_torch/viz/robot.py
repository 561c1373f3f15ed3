"""Pictures of robots (PNG), drawn from their collision geometry with matplotlib.

A robot is drawn from its ``<collision>`` shapes (primitives; meshes decimated to at most
``PICTURE_FACES`` faces), or its ``<visual>`` shapes when it has no collision geometry at all. A
robot with nothing drawable, or whose meshes cannot be loaded (one warning on stderr per robot),
is drawn as a skeleton as well: a line from each link's frame to its child links' frames and a
marker per link frame. A picture never fails because of a robot's geometry.

matplotlib is imported here only, lazily, and always with the non-interactive Agg backend.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from graspnet_torch.errors import say
from graspnet_torch.io import atomic_path
from graspnet_torch.robot.geometry import LinkShape, link_shapes
from graspnet_torch.robot.meshes import decimate
from graspnet_torch.robot.robot import Posture, Robot

__all__ = ["Panel", "draw_mesh", "draw_shapes", "draw_skeleton", "drawable_shapes", "new_figure", "render_robot",
           "save_figure"]


def new_figure(n_views: int, size: float = 4.2):
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(size * n_views, size + 0.4), dpi=110)
    axes = [fig.add_subplot(1, n_views, k + 1, projection="3d") for k in range(n_views)]
    return fig, axes


def save_figure(fig, path: str | Path) -> Path:
    """Save atomically (temporary file, then rename) and close the figure."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, bbox_inches="tight")
    finally:
        plt.close(fig)
    return Path(path)


def _sphere(radius: float, n: int = 10):
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 2 * n), np.linspace(0, np.pi, n))
    return radius * np.cos(u) * np.sin(v), radius * np.sin(u) * np.sin(v), radius * np.cos(v)


def _cylinder(radius: float, length: float, n: int = 14):
    u, h = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.array([-length / 2, length / 2]))
    return radius * np.cos(u), radius * np.sin(u), h


def _apply(T: np.ndarray, X, Y, Z):
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()])
    out = T[:3, :3] @ pts + T[:3, 3:4]
    return (out[0].reshape(X.shape), out[1].reshape(X.shape), out[2].reshape(X.shape))


COLLIDING = (0.85, 0.1, 0.1)


def draw_shapes(ax, shapes: Sequence[LinkShape], frames: dict[str, np.ndarray], alpha: float = 1.0,
                red: frozenset[str] = frozenset()) -> np.ndarray:
    """Draw shapes at their links' world frames, the links in ``red`` red (colliding); returns
    (N, 3) points spanning the drawing."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    extent = []
    for s in shapes:
        T = frames[s.link] @ s.origin
        color = COLLIDING if s.link in red else s.rgba[:3]
        if s.kind == "box":
            hx, hy, hz = (0.5 * d for d in s.size)
            corners = np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)])
            w = corners @ T[:3, :3].T + T[:3, 3]
            faces = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
            ax.add_collection3d(Poly3DCollection([w[f] for f in faces], facecolor=color, edgecolor=(0, 0, 0, 0.25),
                                                 linewidth=0.3, alpha=alpha))
            extent.append(w)
        elif s.kind == "mesh":
            mesh = decimate(s.mesh)
            w = np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3]
            ax.add_collection3d(Poly3DCollection(w[np.asarray(mesh.faces)], facecolors=color, shade=True,
                                                 edgecolor=(0, 0, 0, 0.08), linewidth=0.1, alpha=alpha))
            extent.append(w)
        else:
            X, Y, Z = _sphere(s.size[0]) if s.kind == "sphere" else _cylinder(*s.size)
            X, Y, Z = _apply(T, X, Y, Z)
            ax.plot_surface(X, Y, Z, color=color, shade=True, linewidth=0, antialiased=False, alpha=alpha)
            extent.append(np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1))
    return np.concatenate(extent) if extent else np.zeros((0, 3))


def _frame_axes(ax, points: np.ndarray, elev: float, azim: float, title: str) -> None:
    points = points if len(points) else np.zeros((1, 3))
    lo, hi = points.min(0), points.max(0)
    center, half = (lo + hi) / 2, max((hi - lo).max() / 2, 1e-3) * 1.05
    ax.set_xlim(center[0] - half, center[0] + half)
    ax.set_ylim(center[1] - half, center[1] + half)
    ax.set_zlim(center[2] - half, center[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    ax.set_xlabel("x (m)", fontsize=7)
    ax.set_ylabel("y (m)", fontsize=7)
    ax.set_zlabel("z (m)", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.set_title(title, fontsize=9)


@dataclass(frozen=True)
class Panel:
    """One picture panel: a posture seen from (elevation, azimuth) degrees, with optional red
    markers (N, 3) in the world (e.g. contact points), green arrows (pad normals), trimesh meshes
    (objects, obstacles), the links to draw red (colliding) and the links to draw (``focus``;
    empty: all), e.g. the hand at the end of an arm."""

    caption: str
    posture: Posture
    view: tuple[float, float] = (15.0, -60.0)
    markers: np.ndarray | None = None
    meshes: tuple = ()
    red_links: frozenset[str] = frozenset()
    focus: frozenset[str] = frozenset()
    arrows: np.ndarray | None = None  # (N, 2, 3) green segments from [:, 0] to [:, 1] in the world (pad normals)


def draw_mesh(ax, mesh, color=(0.45, 0.65, 0.9), alpha: float = 0.35) -> np.ndarray:
    """Draw a trimesh.Trimesh (world coordinates); returns its vertices."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    ax.add_collection3d(Poly3DCollection(mesh.vertices[mesh.faces], facecolor=color, edgecolor=(0, 0, 0, 0.05),
                                         linewidth=0.2, alpha=alpha))
    return np.asarray(mesh.vertices)


def drawable_shapes(robot: Robot) -> tuple[list[LinkShape], list[str]]:
    """The shapes a picture draws (collision, else visual when there is no collision geometry)
    and the one-line errors of the meshes that could not be loaded (skipped)."""
    errors: list[str] = []
    shapes = link_shapes(robot.urdf, "collision", errors)
    if not shapes and not errors:
        shapes = link_shapes(robot.urdf, "visual", errors)
    return shapes, errors


def draw_skeleton(ax, robot: Robot, frames: dict[str, np.ndarray], links: frozenset[str] = frozenset()) -> np.ndarray:
    """Lines from each link's frame origin (its parent joint's) to its child links' origins and a
    marker per link frame, for the ``links`` given (empty: all); returns the (N, 3) origins."""
    origins = {link: T[:3, 3] for link, T in frames.items()
               if link in robot.urdf.links and (not links or link in links)}
    for joint in robot.urdf.robot.joints:
        if joint.parent in origins and joint.child in origins:
            a, b = origins[joint.parent], origins[joint.child]
            ax.plot([a[0], b[0]], [a[1], b[1]], [a[2], b[2]], color=(0.25, 0.25, 0.3), linewidth=1.4)
    pts = np.array(list(origins.values())) if origins else np.zeros((0, 3))
    if len(pts):
        ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], color=(0.2, 0.35, 0.7), s=6, depthshade=False)
    return pts


def render_robot(robot: Robot, panels: Sequence[Panel], path: str | Path, title: str | None = None) -> Path:
    """Draw a robot in one or more panels and save a PNG atomically. Meshes that cannot be loaded
    are one warning on stderr, and the robot is then drawn as a skeleton too (as one with
    nothing to draw)."""
    shapes, errors = drawable_shapes(robot)
    if errors:
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        say(f"warning: {errors[0]}{more}; drawn as a skeleton")
    skeleton = bool(errors) or not shapes
    fig, axes = new_figure(len(panels))
    for ax, panel in zip(axes, panels, strict=True):
        frames = robot.link_frames(panel.posture)
        drawn = [s for s in shapes if s.link in panel.focus] if panel.focus else shapes
        pts = draw_shapes(ax, drawn, frames, red=panel.red_links)
        if skeleton:
            pts = np.concatenate([pts, draw_skeleton(ax, robot, frames, panel.focus)])
        for mesh in panel.meshes:
            pts = np.concatenate([pts, draw_mesh(ax, mesh)])
        if panel.markers is not None and len(panel.markers):
            mk = np.asarray(panel.markers)
            ax.scatter(mk[:, 0], mk[:, 1], mk[:, 2], color="red", s=14, depthshade=False)
            pts = np.concatenate([pts, mk])
        if panel.arrows is not None and len(panel.arrows):
            for a, b in np.asarray(panel.arrows):
                ax.plot(*np.stack([a, b]).T, color="green", linewidth=1.6)
            pts = np.concatenate([pts, np.asarray(panel.arrows).reshape(-1, 3)])
        _frame_axes(ax, pts, *panel.view, panel.caption)
    if title:
        fig.suptitle(title, fontsize=11)
    return save_figure(fig, path)
