"""Random problems whose posture is known to be collision-free (FCL:
:class:`~graspnet_torch.collision.scene.CollisionScene`).

- :func:`closure_problem`: a contact set on an object whose grasp is known to be reachable and
  collision-free: the hand is placed around the object, each finger closes along a straight line
  in joint space until its fingertip touches the surface (bisection on the mesh's winding number,
  which stays exact up to the surface), and the posture is kept only when FCL finds it
  collision-free (the touching fingertips excepted, as in every count); the contacts are the
  fingertips, the posture the problem's ``reference``;
- :func:`real_mesh_problems`: closure contact sets on real object meshes at random poses (the
  random problems of the mesh kind; the objects: :mod:`graspnet_torch.tasks.objects`);
- :func:`random_obstacle_problems`: a hand on an arm among random obstacles that clear the posture.

Each is deterministic in its seed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import torch

from graspnet_torch.collision.mesh import MeshQuery, mesh_query
from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.kinds import robot_kind
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.shape import Shape
from graspnet_torch.robot.transforms import matrix_to_pose, pose_to_matrix_np, rpy_to_matrix_np, rt_to_pose
from graspnet_torch.tasks.objects import random_pose, real_objects
from graspnet_torch.tasks.problem import Contact, GraspProblem, ReferencePosture

__all__ = ["closure_problem", "random_obstacle_problems", "real_mesh_problems"]


def closure_problem(robot: Robot, obj: Shape, seed: int, fingers: int = 3, attempts: int = 500,
                    name: str | None = None) -> GraspProblem:
    """A contact set of ``fingers`` contacts (the thumb, the robot's first finger, and others) on
    ``obj``, from a collision-free posture whose fingertips touch its surface (module docstring).
    Deterministic in ``seed``; a free hand only. Raises ValueError after ``attempts`` draws
    without one."""
    if not robot_kind(robot).closure or robot.n_fingers < fingers:
        raise ValueError(f"robot '{robot.name}': closure problems need a free hand of at least {fingers} fingers")
    rng = np.random.default_rng(seed)
    if obj.kind == "mesh":
        local_query, T = mesh_query(obj)
    else:
        local_query, T = MeshQuery(replace(obj, pose=np.zeros(6)).trimesh()), pose_to_matrix_np(obj.pose)

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
    of the real objects ``objects`` (:func:`~graspnet_torch.tasks.objects.real_objects`, in that
    order), each set with the object at its own random pose within ``radius`` of the origin
    (:func:`~graspnet_torch.tasks.objects.random_pose` from ``rng``)."""
    files = real_objects()
    problems = []
    for name in objects:
        path, scale = files[name]
        for k in range(sets):
            pose = matrix_to_pose(torch.as_tensor(random_pose(rng, radius))).numpy()
            obj = Shape("mesh", (), pose, path, scale)
            problems.append(closure_problem(robot, obj, seed=seed + k, fingers=fingers, name=f"{name} {k}"))
    return problems


def random_obstacle_problems(robot: Robot, n: int, seed: int = 7,
                             fingers: Sequence[str] = ("thumb", "index", "middle"),
                             anchors: Sequence[str] = ("shoulder_rotation_link", "elbow_flexion_link", "palm"),
                             clear_of: Sequence[Posture] = ()) -> list[GraspProblem]:
    """``n`` problems of a hand on an arm among obstacles: a random arm posture (the middle 60 % of
    every joint range) and ``fingers`` (the middle 60 % of their ranges) give the contacts; two or
    three obstacles (boxes, cylinders, spheres of 3-15 cm) are centred 12-20 cm from a point near
    one of the links ``anchors``, kept only if they clear that posture (FCL) and swallow no contact;
    the search space is +-30 deg about the posture, shifted by up to 10 deg. ``clear_of``: other
    postures the obstacles must clear too (a reach motion's start: the robot's home)."""
    rng = np.random.default_rng(seed)
    lo, hi = (np.degrees(a) for a in robot.body_limits)
    flo, fhi = robot.finger_limits
    problems: list[GraspProblem] = []
    while len(problems) < n:
        qa = lo + (hi - lo) * rng.uniform(0.2, 0.8, lo.size)
        q = robot.home_posture().fingers.clone()
        for f in fingers:
            i = robot.finger_index(f)
            q[i] = torch.as_tensor(flo[i] + (fhi[i] - flo[i]) * rng.uniform(0.2, 0.8, flo[i].size))
        body = torch.as_tensor(np.radians(qa))
        tips = robot.fingertips_world_from_body(body, q)
        posture = Posture(palm_pose=torch.zeros(6), fingers=q, body=body)
        frames = robot.link_frames(posture)
        points = [frames[link][:3, 3] for link in anchors]
        obstacles = []
        for _ in range(rng.integers(2, 4)):
            a = points[rng.integers(len(points))] + rng.normal(0, 0.05, 3)
            direction = rng.normal(size=3)
            centre = a + direction / np.linalg.norm(direction) * rng.uniform(0.12, 0.2)
            kind = ("box", "cylinder", "sphere")[rng.integers(3)]
            size = {"box": rng.uniform(0.05, 0.15, 3).tolist(), "cylinder": [float(rng.uniform(0.02, 0.05)), 0.3],
                    "sphere": [float(rng.uniform(0.03, 0.07))]}[kind]
            obstacles.append({"shape": kind, "size": size, "pose": [*centre.tolist(), 0, 0, float(rng.uniform(0, 90))]})
        shift = rng.uniform(-10, 10, lo.size)
        data = {"robot": robot.name, "obstacles": obstacles,
                "contacts": [{"finger": f, "position": tips[robot.finger_index(f)].tolist()} for f in fingers],
                "bounds": {"min": np.maximum(qa + shift - 30, lo).tolist(),
                           "max": np.minimum(qa + shift + 30, hi).tolist()}}
        try:
            problem = GraspProblem.from_mapping(data, source=f"random-{len(problems)}", robot_cfg=robot.cfg)
        except ProblemError:  # an obstacle swallows a contact: draw again
            continue
        scene = CollisionScene(robot, problem)
        if scene.count(posture) > 0 or any(scene.count(p) > 0 for p in clear_of):
            continue  # an obstacle hits the posture that made the contacts (or one to clear): draw again
        problems.append(problem)
    return problems


def _problem(robot: Robot, obj: Shape, chosen: list[int], pose: torch.Tensor, q: torch.Tensor,
             name: str) -> GraspProblem:
    """The problem whose contacts are the chosen fingertips (object frame) at a posture."""
    tips = robot.fingertips_world(pose, q).numpy()
    R = rpy_to_matrix_np(obj.pose[3:])
    contacts = tuple(Contact(robot.finger_names[f], (tips[f] - obj.pose[:3]) @ R) for f in chosen)
    reference = ReferencePosture(pose.numpy().copy(), {robot.finger_names[f]: q[f].numpy().copy() for f in chosen})
    return GraspProblem(robot=robot.name, contacts=contacts, object=obj, name=name, reference=reference,
                        source=name, robot_cfg=robot.cfg)
