"""Objects as users have them: real object meshes, problems moved anywhere, grasps closed on a mesh.

- :func:`real_objects`: a few real object meshes from the ``pybullet`` package's ``pybullet_data``
  (installed by the ``dev`` extra; not copied into this repository), with the scale that makes
  each hand-sized;
- :func:`random_pose`: a rigid motion to anywhere within a radius of the origin, any orientation
  (uniform), to move a whole problem with :meth:`GraspProblem.moved`;
- :func:`as_mesh`: a problem's primitive object written as a mesh file (the same object);
- the grasps closed on a mesh (contact sets whose posture FCL finds clear) are made where
  collisions are known: :func:`graspnet_torch.collision.problems.closure_problem` and
  :func:`~graspnet_torch.collision.problems.real_mesh_problems`.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from graspnet_torch.errors import ConfigError
from graspnet_torch.meshes import load_mesh
from graspnet_torch.robot.shape import Shape
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["OBJECT_CENTRE", "REAL_OBJECTS", "as_mesh", "centred_mesh", "random_pose", "real_objects"]

OBJECT_CENTRE = (0.0, 0.0, 0.2)  # m, world: where an object given alone is centred (the hand's tasks' place)

# name -> (file under pybullet_data, scale to metres): hand-sized, closed surfaces but the mug's
REAL_OBJECTS = {
    "duck": ("duck.obj", 0.07),               # 116 x 108 x 81 mm
    "bunny": ("bunny.obj", 0.07),             # the Stanford bunny, 65 x 101 x 138 mm
    "mug": ("objects/mug_col.obj", 1.0),      # 82 x 122 x 100 mm, open: its convex pieces hold its inside
    "cylinder": ("toys/cylinder.obj", 1.0),   # a toy cylinder, 77 x 116 x 58 mm
    "torus": ("torus/torus_textured.obj", 0.06),  # a ring, 90 x 30 x 90 mm
    "soccerball": ("soccerball.obj", 0.08),   # 80 mm across, 9048 triangles
    "blob000": ("random_urdfs/000/000.obj", 0.015),  # random objects (pybullet's grasping data), ~100 mm
    "blob001": ("random_urdfs/001/001.obj", 0.015),
    "blob002": ("random_urdfs/002/002.obj", 0.015),
    "blob003": ("random_urdfs/003/003.obj", 0.015),
}


def real_objects() -> dict[str, tuple[Path, float]]:
    """The real object meshes: name -> (file, scale). Needs the ``pybullet`` package (its
    ``pybullet_data``: ``pip install -e '.[dev]'``)."""
    try:
        import pybullet_data
    except ImportError:
        raise ConfigError("the real object meshes come from the pybullet package's pybullet_data: "
                          "pip install pybullet (or pip install -e '.[dev]')") from None
    root = Path(pybullet_data.getDataPath())
    return {name: (root / rel, scale) for name, (rel, scale) in REAL_OBJECTS.items()}


def centred_mesh(path: Path, scale: float = 1.0, centre: tuple[float, float, float] = OBJECT_CENTRE) -> Shape:
    """A mesh file as an object whose bounding box is centred at ``centre`` (world, unturned): how
    an object given without a pose is placed (the synthesis job, the synthesis experiment)."""
    lo, hi = load_mesh(Path(path).resolve(), scale).bounds
    pose = np.concatenate([np.asarray(centre) - (np.asarray(lo) + np.asarray(hi)) / 2, np.zeros(3)])
    return Shape("mesh", (), pose, Path(path).resolve(), scale)


def random_pose(rng: np.random.Generator, radius: float = 0.3) -> np.ndarray:
    """(4, 4) a rigid motion: a rotation uniform over SO(3), a translation uniform in the ball of
    ``radius`` metres."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    direction = rng.normal(size=3)
    T[:3, 3] = direction / np.linalg.norm(direction) * radius * rng.uniform() ** (1 / 3)
    return T


def as_mesh(problem: GraspProblem, folder: Path, sections: int = 64) -> GraspProblem:
    """The problem with its primitive object as a mesh (STL written into ``folder``), same pose."""
    obj = problem.object
    if obj is None or obj.kind == "mesh":
        return problem
    import trimesh

    if obj.kind == "box":
        mesh = trimesh.creation.box(extents=obj.size)
    elif obj.kind == "cylinder":
        mesh = trimesh.creation.cylinder(radius=obj.size[0], height=obj.size[1], sections=sections)
    else:
        mesh = trimesh.creation.icosphere(subdivisions=4, radius=obj.size[0])
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{obj.kind}_{'_'.join(f'{s:.4f}' for s in obj.size)}.stl"
    if not path.is_file():
        mesh.export(path)
    return replace(problem, object=Shape("mesh", (), obj.pose.copy(), path.resolve()))
