"""Pictures of a result: the best trial's posture with the problem around it."""

from __future__ import annotations

from graspnet_torch.collision.scene import CollisionScene, has_environment
from graspnet_torch.robot.robot import Robot
from graspnet_torch.solver.environments import environment_class
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.solver.result import GraspResult
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.viz.robot import Panel

__all__ = ["posture_panels"]


def posture_panels(robot: Robot, problem: GraspProblem, result: GraspResult) -> list[Panel]:
    """Two views (:class:`~graspnet_torch.viz.Panel`) of the best trial's posture with the object,
    obstacles and contacts (a gripper: the object's two points and its own), colliding links red."""
    posture = trial_posture(robot, result.best)
    meshes = tuple(s.trimesh() for s in ((problem.object,) if problem.object else ()) + problem.obstacles)
    contacts = environment_class(robot).marks(problem, result.best)  # the contacts (a gripper: its points too)
    red: frozenset[str] = frozenset()
    if has_environment(robot, problem):
        report = CollisionScene(robot, problem).check(posture)
        red = frozenset({link for link, _ in report.obstacle_pairs} | set(report.object_links)
                        | {link for pair in report.self_pairs for link in pair})
    caption = (f"{problem.name or 'problem'}: best trial, error {result.best.error_mm:.2f} mm, "
               f"{result.best.collisions} collision(s){' (red)' if red else ''}")
    return [Panel(caption, posture, (12.0, -150.0), contacts, meshes, red),
            Panel("side view", posture, (12.0, -60.0), contacts, meshes, red)]
