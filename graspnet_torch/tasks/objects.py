"""Objects as users have them: real object meshes, problems moved anywhere, grasps closed on a mesh.

- :func:`real_objects`: a few real object meshes from the ``pybullet`` package's ``pybullet_data``
  (installed by the ``dev`` extra; not copied into this repository), with the scale that makes
  each hand-sized;
- :func:`random_pose`: a rigid motion to anywhere within a radius of the origin, any orientation
  (uniform), to move a whole problem with :meth:`GraspProblem.moved`;
- :func:`as_mesh`: a problem's primitive object written as a mesh file (the same object);
- :func:`closure_problem`: a contact set on an object whose grasp is known to be reachable and
  collision-free: the hand is placed around the object, each finger closes along a straight line
  in joint space until its fingertip touches the surface (bisection on the mesh's winding number,
  which stays exact up to the surface), and the posture is kept only when FCL finds it
  collision-free (the touching fingertips excepted, as in every count); the contacts are the
  fingertips, the posture the problem's ``reference``;
- :func:`real_mesh_problems`: closure contact sets on real object meshes at random poses (the
  random problems of the mesh kind).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.tasks.problem import Contact, GraspProblem, ReferencePosture, Shape

__all__ = ["REAL_OBJECTS", "as_mesh", "closure_problem", "random_pose", "real_mesh_problems", "real_objects"]

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


def closure_problem(robot: Robot, obj: Shape, seed: int, fingers: int = 3, attempts: int = 500,
                    name: str | None = None) -> GraspProblem:
    """A contact set of ``fingers`` contacts (the thumb, the robot's first finger, and others) on
    ``obj``, from a collision-free posture whose fingertips touch its surface (module docstring).
    Deterministic in ``seed``; a free hand only. Raises ValueError after ``attempts`` draws
    without one."""
    from graspnet_torch.collision.mesh import MeshQuery, mesh_query
    from graspnet_torch.collision.scene import CollisionScene
    from graspnet_torch.robot.chain import rpy_matrix_np
    from graspnet_torch.robot.transforms import rt_to_pose

    if robot.has_body or robot.n_fingers < fingers:
        raise ValueError(f"robot '{robot.name}': closure problems need a free hand of at least {fingers} fingers")
    rng = np.random.default_rng(seed)
    if obj.kind == "mesh":
        local_query, T = mesh_query(obj)
    else:
        local_query, T = MeshQuery(replace(obj, pose=np.zeros(6)).trimesh()), np.eye(4)
        T[:3, :3], T[:3, 3] = rpy_matrix_np(obj.pose[3:]), obj.pose[:3]

    def inside(points: np.ndarray) -> np.ndarray:  # world points inside the object, up to its surface
        return local_query.winding((points - T[:3, 3]) @ T[:3, :3]) > 0.5

    centre = T[:3, :3] @ local_query.bounds.mean(0) + T[:3, 3]
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    span = hi - lo
    s = torch.linspace(0, 1, 41, dtype=torch.float64)
    for _ in range(attempts):
        chosen = [0, *sorted(rng.choice(np.arange(1, robot.n_fingers), fingers - 1, replace=False).tolist())]
        q_open = lo + span * torch.as_tensor(rng.uniform(0.0, 0.3, size=lo.shape))
        q_shut = lo + span * torch.as_tensor(rng.uniform(0.6, 1.0, size=lo.shape))
        mid = robot.fingertips_palm((q_open + q_shut) / 2)[chosen].mean(0).numpy()
        R = random_pose(rng)[:3, :3]
        t = centre + rng.normal(scale=0.01, size=3) - R @ mid
        pose = rt_to_pose(torch.as_tensor(R), torch.as_tensor(t))
        path = q_open + s.view(-1, 1, 1) * (q_shut - q_open)  # (S, F, n)
        tips = robot.fingertips_world(pose.expand(len(s), 6), path).numpy()  # (S, F, 3)
        q = q_open.clone()
        ok = True
        for f in chosen:
            inside_path = inside(tips[:, f])
            if inside_path[0] or not inside_path.any():  # starts inside, or never reaches the surface
                ok = False
                break
            k = int(np.argmax(inside_path))
            a, b = float(s[k - 1]), float(s[k])
            for _ in range(40):  # bisection: the fingertip on the surface
                m = (a + b) / 2
                qm = q_open[f] + m * (q_shut[f] - q_open[f])
                tip = robot.fingertips_world(pose, q_open.index_copy(0, torch.tensor([f]), qm.unsqueeze(0)))[f]
                a, b = (a, m) if inside(tip.numpy()[None])[0] else (m, b)
            q[f] = q_open[f] + b * (q_shut[f] - q_open[f])
        if not ok:
            continue
        problem = _problem(robot, obj, chosen, pose, q, name or f"closure {seed}")
        if CollisionScene(robot, problem).count(Posture(palm_pose=pose, fingers=q, body=torch.zeros(0))) == 0:
            return problem
    raise ValueError(f"no collision-free closure on this object in {attempts} attempts (seed {seed})")


def real_mesh_problems(robot: Robot, objects: Sequence[str], rng: np.random.Generator, sets: int = 1,
                       radius: float = 0.3, fingers: int = 3, seed: int = 0) -> list[GraspProblem]:
    """``sets`` closure contact sets (:func:`closure_problem`, set k with seed ``seed`` + k) on each
    of the real objects ``objects`` (:func:`real_objects`, in that order), each set with the object
    at its own random pose within ``radius`` of the origin (:func:`random_pose` from ``rng``)."""
    from graspnet_torch.robot.transforms import matrix_to_pose

    files = real_objects()
    problems = []
    for name in objects:
        path, scale = files[name]
        for k in range(sets):
            pose = matrix_to_pose(torch.as_tensor(random_pose(rng, radius))).numpy()
            obj = Shape("mesh", (), pose, path, scale)
            problems.append(closure_problem(robot, obj, seed=seed + k, fingers=fingers, name=f"{name} {k}"))
    return problems


def _problem(robot: Robot, obj: Shape, chosen: list[int], pose: torch.Tensor, q: torch.Tensor,
             name: str) -> GraspProblem:
    """The problem whose contacts are the chosen fingertips (object frame) at a posture."""
    from graspnet_torch.robot.chain import rpy_matrix_np

    tips = robot.fingertips_world(pose, q).numpy()
    R = rpy_matrix_np(obj.pose[3:])
    contacts = tuple(Contact(robot.finger_names[f], (tips[f] - obj.pose[:3]) @ R) for f in chosen)
    reference = ReferencePosture(pose.numpy().copy(), {robot.finger_names[f]: q[f].numpy().copy() for f in chosen})
    return GraspProblem(robot=robot.name, contacts=contacts, object=obj, name=name, reference=reference,
                        source=name, robot_cfg=robot.cfg)
