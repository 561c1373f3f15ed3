"""The pre-grasp opening of a reach motion: the fingers at the grasp with no link touching the
object, from which they close onto the grasp clear (:func:`openings`)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import torch

from graspnet_torch.motion.config import ReachCfg
from graspnet_torch.motion.validity import MotionChecker
from graspnet_torch.robot.heads import head_of
from graspnet_torch.robot.ik import refine
from graspnet_torch.robot.robot import Robot
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["OPENINGS_M", "OPEN_TOWARD_HOME", "finger_by_finger", "finger_links", "opening", "openings"]

OPENINGS_M = (0.04, 0.03, 0.02, 0.01)  # the pre-grasp: contact fingertips this far back from their contacts
OPEN_TOWARD_HOME = (1.0, 0.75, 0.5, 0.25)  # else: the fingers this far from the grasp's toward their home
OPENING_IK_STEPS = 40  # least-squares steps that put the fingertips on an opening's targets


def opening(checker: MotionChecker, problem: GraspProblem, goal: np.ndarray, cfg: ReachCfg,
            pregrasp: np.ndarray | None = None) -> np.ndarray | None:
    """The most open of :func:`openings`, or None."""
    return next(iter(openings(checker, problem, goal, cfg, pregrasp)), None)


def openings(checker: MotionChecker, problem: GraspProblem, goal: np.ndarray, cfg: ReachCfg,
             pregrasp: np.ndarray | None = None) -> Iterator[np.ndarray]:
    """The pre-grasp states at the grasp, clear of the object with no link touching it and whose
    closing onto the grasp is clear; the other fingers as in the grasp (a gripper: the grasp
    itself). First the result's own pre-grasp (``pregrasp``, a state: the surface contact model's
    pads backed off along the object's normals), where it is clear; then each contact finger at its
    own first clear candidate (:func:`finger_by_finger`), then every candidate for all fingers at
    once, in order: each contact fingertip backed off from its contact by each of :data:`OPENINGS_M`
    away from the object's centre (or the contacts' centroid; finger inverse kinematics), then by
    each toward the palm (curling), then the fingers straightened toward their home by
    :data:`OPEN_TOWARD_HOME`."""
    robot, m = checker.robot, checker.layout.body
    if not problem.fingers:  # a gripper's jaws: nothing to open
        yield goal
        return
    res = (cfg.resolution_deg, cfg.resolution_mm)
    if pregrasp is not None:
        pre = goal.copy()
        pre[m:] = pregrasp[m:]  # its fingers; the palm (or arm) is the grasp's
        if checker.strictly_clear(pre[None])[0] and checker.first_collision(pre, goal, *res) is None:
            yield pre
    posture = checker.posture(goal)
    contacts = np.asarray(problem.contacts_world(), dtype=np.float64)
    centre = np.asarray(problem.object.pose[:3], dtype=np.float64) if problem.object is not None else contacts.mean(0)
    out = contacts - centre
    norms = np.linalg.norm(out, axis=1, keepdims=True)
    palm = posture.palm_pose[:3].numpy()
    out = np.where(norms > 1e-6, out / np.maximum(norms, 1e-12), (palm - contacts) /
                   np.maximum(np.linalg.norm(palm - contacts, axis=1, keepdims=True), 1e-12))
    head = head_of(robot).values(posture)
    tips = head_of(robot).fingertips(head, posture.fingers)
    lo, hi = (torch.as_tensor(a) for a in robot.finger_limits)
    rows = [robot.finger_index(f) for f in problem.fingers]
    res = (cfg.resolution_deg, cfg.resolution_mm)
    mask = torch.as_tensor(robot.finger_mask)
    inward = palm - contacts  # curling back toward the palm, where backing off outward is blocked
    inward = inward / np.maximum(np.linalg.norm(inward, axis=1, keepdims=True), 1e-12)
    candidates = []
    for direction, distance in [(out, d) for d in OPENINGS_M] + [(inward, d) for d in OPENINGS_M]:
        targets = tips.clone()
        targets[rows] = torch.as_tensor(contacts + distance * direction)
        bases = head_of(robot).world_to_bases(targets, head)
        q, _err = refine(robot.fingertips_base_jacobian, posture.fingers, bases, lo, hi, OPENING_IK_STEPS)
        candidates.append(q[mask].numpy())
    home = robot.home_posture(torch.float64).fingers[mask].numpy()
    grasp = goal[m:]
    candidates += [grasp + f * (home - grasp) for f in OPEN_TOWARD_HOME]  # the fingers straightened
    mixed = finger_by_finger(checker, problem, goal, np.stack(candidates))
    for fingers in ([mixed] if mixed is not None else []) + candidates:
        pre = goal.copy()
        pre[m:] = fingers
        if checker.strictly_clear(pre[None])[0] and checker.first_collision(pre, goal, *res) is None:
            yield pre


def finger_by_finger(checker: MotionChecker, problem: GraspProblem, goal: np.ndarray, candidates: np.ndarray
                      ) -> np.ndarray | None:
    """Each contact finger at the first of the candidate openings (C, n_free) at which none of its
    own links collides (the other fingers as in the grasp); None where a finger has none."""
    robot, m = checker.robot, checker.layout.body
    owner = np.repeat(np.arange(robot.n_fingers)[:, None], robot.joints_per_finger, 1)[robot.finger_mask]
    out = goal[m:].copy()
    for name in problem.fingers:
        cols = np.nonzero(owner == robot.finger_index(name))[0]
        states = np.repeat(goal[None], len(candidates), 0)
        states[:, m + cols] = candidates[:, cols]
        links = finger_links(robot, name)
        for c, report in enumerate(checker.scene.check_many(checker.postures(states))):
            hit = {link for link, _ in report.obstacle_pairs} | set(report.object_links) | \
                {link for pair in report.self_pairs for link in pair}
            if not hit & links:
                out[cols] = candidates[c, cols]
                break
        else:
            return None
    return out


def finger_links(robot: Robot, name: str) -> set[str]:
    """The links a finger's joints move."""
    joints = set(robot.fingers[name].chain.all_joint_names)
    out = set()
    for link in robot.urdf.links:
        at = link
        while at in robot.urdf.parent_joint:
            joint = robot.urdf.parent_joint[at]
            if joint.name in joints:
                out.add(link)
                break
            at = joint.parent
    return out
