"""What the viewer shows of a result whose contacts were chosen on the object (a ``contacts: auto``
result of ``solve_grasp.py``, or one object's result of ``synthesize_grasps.py``): its grasps as
the trials to pick from, each with its contacts, the object's inward normals there and the
friction cones around them (the cone of forces a finger can apply without slipping, half-angle
atan(mu), mu the friction the grasps' quality was measured with)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from graspnet_torch.collision.surface import surface_normals
from graspnet_torch.errors import ConfigError, ProblemError
from graspnet_torch.robot.config import load_robot_cfg
from graspnet_torch.robot.robot import Robot
from graspnet_torch.synthesis.synthesize import FRICTION, SynthesizedGrasp
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.viz.result import posture_panels
from graspnet_torch.viz.robot import Panel, render_robot

__all__ = ["CONE_HEIGHT_M", "FRICTION", "SHOWN", "cone_mesh", "grasp_contacts", "grasp_panels", "grasp_problem",
           "render_grasps"]

CONE_HEIGHT_M = 0.015  # how far a drawn friction cone reaches out of the object
SHOWN = 4  # grasps side by side in a picture of an object's grasps


def grasp_problem(file: Path, result: dict[str, Any]) -> GraspProblem:
    """The problem of a result with chosen contacts: its problem file (``problem``, beside the
    result or as named; a ``contacts: auto`` problem), else its ``robot`` and ``object`` (the file,
    scale and pose a ``synthesize_grasps.py`` result records). Refused in one line otherwise."""
    source = result.get("problem")
    if isinstance(source, str) and source:
        candidate = file.parent / source
        return GraspProblem.from_file(candidate if not Path(source).is_absolute() and candidate.is_file() else source)
    obj, robot = result.get("object"), result.get("robot")
    if not isinstance(obj, dict) or not obj.get("file") or obj.get("pose") is None or not isinstance(robot, str):
        raise ProblemError(f"{file}: a result of grasps without its problem, robot or object (file, scale, pose)")
    mesh = Path(str(obj["file"]))  # looked up in its own folder, where the synthesis job read it
    try:
        targets = load_robot_cfg(robot).problem_schema.targets  # contacts, or a gripper's points
    except ConfigError as exc:
        raise ProblemError(f"{file}: robot: {exc}") from None
    return GraspProblem.from_mapping({"robot": robot, targets: "auto", "object": {
        "shape": "mesh", "size": [mesh.name], "scale": obj.get("scale", 1.0), "pose": obj["pose"]}}, str(file),
        folder=mesh.parent)


def grasp_contacts(file: Path, problem: GraspProblem, grasp: dict[str, Any], k: int) -> tuple[np.ndarray, np.ndarray]:
    """Grasp k's contacts (n, 3) in the world and the object's inward normals there (n, 3)."""
    try:
        contacts = np.asarray(grasp["contacts_world"], dtype=np.float64).reshape(-1, 3)
    except (KeyError, TypeError, ValueError):
        raise ProblemError(f"{file}: grasps[{k}] has no contacts_world (n x 3 numbers)") from None
    if not np.all(np.isfinite(contacts)):
        raise ProblemError(f"{file}: grasps[{k}].contacts_world: not finite numbers")
    return contacts, -surface_normals(problem.object, contacts)


def cone_mesh(contact: np.ndarray, inward: np.ndarray, friction: float = FRICTION,
              height: float = CONE_HEIGHT_M, sections: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """A friction cone drawn at a contact: apex on it, axis along the outward normal (out of the
    object, where it can be seen), half-angle atan(``friction``), ``height`` long -> vertices
    (V, 3) and faces (F, 3)."""
    out = -np.asarray(inward, dtype=np.float64) / np.linalg.norm(inward)
    helper = np.array([1.0, 0.0, 0.0]) if abs(out[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(out, helper)
    u /= np.linalg.norm(u)
    v = np.cross(out, u)
    angles = np.linspace(0.0, 2 * math.pi, sections, endpoint=False)
    rim = contact + height * out + height * friction * (np.outer(np.cos(angles), u) + np.outer(np.sin(angles), v))
    vertices = np.vstack([contact, rim, contact + height * out])  # apex, rim, the base's centre
    ring = np.arange(sections)
    sides = np.stack([np.zeros(sections, dtype=int), 1 + ring, 1 + (ring + 1) % sections], 1)
    base = np.stack([np.full(sections, sections + 1), 1 + (ring + 1) % sections, 1 + ring], 1)
    return vertices, np.vstack([sides, base])


def grasp_panels(robot: Robot, grasps: Sequence[SynthesizedGrasp], label: str = "", most: int = SHOWN) -> list[Panel]:
    """One panel per grasp (the first ``most``, best first): its posture with the object, its
    contacts red (a gripper: the points), colliding links red, captioned with its rank, epsilon (a
    gripper: its line's largest angle to the inward normals) and holds; a robot with a body drawn
    from its palm down (the hand and the object, not the arm)."""
    focus = robot.urdf.subtree(robot.cfg.palm_link) if robot.has_body else frozenset()
    panels = []
    for k, g in enumerate(grasps[:most]):
        panel = posture_panels(robot, g.problem, g.result)[0]
        holds = "" if g.physics is None else f", holds {g.holds}/{g.physics.of}" if len(g.physics.directions) == \
            g.physics.of else f", fails push {len(g.physics.directions)}"  # a check run until a push fails
        quality = f"epsilon {g.quality.epsilon:.4f}" if g.problem.points is None else \
            f"{float(np.max(g.candidate.angles_deg)):.1f} deg off the normals"  # a gripper's two points
        caption = f"{label + ' ' if label else ''}#{k + 1}: {quality}{holds}"
        panels.append(replace(panel, caption=caption, focus=focus))
    return panels


def render_grasps(robot: Robot, grasps: Sequence[SynthesizedGrasp], path: str | Path, label: str = "") -> Path:
    """The best grasps of an object side by side (:func:`grasp_panels`), a PNG written atomically."""
    return render_robot(robot, grasp_panels(robot, grasps, label), path)

