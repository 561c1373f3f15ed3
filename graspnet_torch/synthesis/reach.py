"""Contact sets for a hand on an arm: chosen with the free hand the arm carries, then reached.

A robot whose config names its ``hand`` (``configs/robot/arm_hand.yaml``: ``hand: hand``) has its
contact sets drawn with that free hand (:func:`~graspnet_torch.synthesis.candidates.iter_contact_sets`:
the palm anywhere around the object); each set's palm pose is then solved for the arm's joints
(:func:`~graspnet_torch.robot.ik.frame_ik`: full-pose IK within the joint limits, from the arm's
home and random postures, ``STARTS`` in all) and kept where the arm reaches it (within ``REACH_MM`` and
``REACH_DEG``): the set's posture becomes the whole robot's (the arm's joints, the set's fingers,
the fingers not chosen at the robot's home), the warm start of its solve.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
import torch

from graspnet_torch.errors import ProblemError
from graspnet_torch.quality import GraspQuality
from graspnet_torch.robot.ik import frame_ik
from graspnet_torch.robot.robot import Posture, Robot, load_robot
from graspnet_torch.robot.transforms import pose_to_matrix_np, rt_to_pose
from graspnet_torch.synthesis.candidates import ContactSet

__all__ = ["REACH_DEG", "REACH_MM", "STARTS", "arm_palms", "carried_hand", "reach_sets"]

STARTS = 8  # IK starts per palm pose: the arm's home and random postures within its limits
REACH_MM, REACH_DEG = 1.0, 1.0  # a palm pose the arm's IK ends farther from is out of reach
IK_ITERATIONS, IK_MIN_GAIN = 40, 1e-3  # steps at most; a start gaining less than this share has settled
CHUNK = 32  # sets solved for the arm at once
_HANDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def carried_hand(robot: Robot) -> Robot:
    """The free hand a robot chooses its contact sets with: the robot itself (a free hand), or the
    hand its config names (``hand``), checked to be the robot's fingers (the same names, joint
    limits and pads, and the same fingertips in the palm frame at the home and 8 random postures,
    within 1e-9 m); :class:`ProblemError` otherwise (a gripper, an arm without ``hand``)."""
    if not robot.has_body:
        return robot
    if robot in _HANDS:
        return _HANDS[robot]
    if robot.cfg.hand is None or not robot.cfg.fingers:
        raise ProblemError(f"robot {robot.cfg.name}: contacts are chosen for a free hand, or a hand on an arm whose "
                           f"config names it ('hand: <robot>'); the shipped ones are robot=hand and robot=arm_hand")
    hand = load_robot(robot.cfg.hand)
    where = f"robot {robot.cfg.name}: its hand '{robot.cfg.hand}'"
    if hand.has_body or list(hand.fingers) != list(robot.fingers) or set(hand.pads) != set(robot.pads):
        raise ProblemError(f"{where} must be a free hand with the robot's fingers ({', '.join(robot.fingers)}), pads")
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.finger_limits)
    if any(not np.allclose(a, b) for a, b in zip((lo, hi), hand.finger_limits, strict=True)):
        raise ProblemError(f"{where}: its fingers' joint limits differ from the robot's")
    rng = np.random.default_rng(0)
    q = torch.as_tensor(np.concatenate([robot.home_posture().fingers.numpy()[None],
                                        lo + rng.random((8, *lo.shape)) * (hi - lo)]))
    if not torch.allclose(robot.fingertips_palm(q), hand.fingertips_palm(q), atol=1e-9, rtol=0.0):
        raise ProblemError(f"{where}: its fingertips differ from the robot's in the palm frame")
    _HANDS[robot] = hand
    return hand


def arm_palms(robot: Robot, seed: int) -> tuple[Callable[[np.random.Generator, int], np.ndarray] | None,
                                                 Callable[[np.ndarray], np.ndarray] | None]:
    """What :func:`~graspnet_torch.synthesis.candidates.iter_contact_sets` draws palm poses with for
    ``robot``: (orientations, reachable), both None for a free hand. A hand on an arm: the palm
    orientations of uniformly random arm postures (rng, B -> (B, 3, 3)), and a palm pose kept where
    the arm's IK reaches it (T (B, 4, 4) -> (B,) bool; as :func:`reach_sets`, with the arm posture
    each orientation came from among the starts)."""
    if not robot.has_body:
        return None, None
    lo, hi = (np.asarray(a, dtype=np.float64) for a in robot.body_limits)
    drawn: list[torch.Tensor] = []  # the last batch's arm postures

    def orientations(rng: np.random.Generator, B: int) -> np.ndarray:
        drawn[:] = [torch.as_tensor(lo + rng.random((B, lo.shape[0])) * (hi - lo))]
        return robot.palm_frame(drawn[0])[0].numpy()

    def reachable(T: np.ndarray) -> np.ndarray:
        return _ik(robot, T, seed, drawn[0] if drawn and len(drawn[0]) == len(T) else None)[1].numpy()

    return orientations, reachable


def _ik(robot: Robot, T: np.ndarray, seed: int, first: torch.Tensor | None = None
        ) -> tuple[torch.Tensor, torch.Tensor]:
    """The arm's joints (B, m) that put the palm at T (B, 4, 4), and whether they do (B,) bool:
    from the home posture, ``first`` (B, m) where given, and random postures."""
    lo, hi = (torch.as_tensor(np.asarray(a, dtype=np.float64)) for a in robot.body_limits)
    gen = torch.Generator().manual_seed(seed)
    starts = lo + (hi - lo) * torch.rand(len(T), STARTS, lo.shape[0], generator=gen, dtype=torch.float64)
    starts[:, 0] = robot.home_posture().body
    if first is not None:
        starts[:, 1] = first
    R, t = torch.as_tensor(T[:, :3, :3]), torch.as_tensor(T[:, :3, 3])
    body, pos, rot = frame_ik(robot.palm_frame_jacobian, R, t, starts, lo, hi, IK_ITERATIONS, min_gain=IK_MIN_GAIN)
    return body, (pos <= REACH_MM / 1000.0) & (rot <= math.radians(REACH_DEG))


def reach_sets(robot: Robot, ranked: Sequence[tuple[ContactSet, GraspQuality]], fingers: Sequence[str], seed: int,
               need: int | None = None) -> list[tuple[ContactSet, GraspQuality]]:
    """The ranked sets (drawn with :func:`carried_hand`) whose palm pose ``robot``'s arm reaches,
    in order, each with the whole robot's posture (module docstring), the first ``need`` of them
    (None: all; solved ``CHUNK`` at a time, in rank order, until there are enough); ``robot`` a
    free hand: the sets as they are."""
    if not robot.has_body:
        return list(ranked)[:need]
    out: list[tuple[ContactSet, GraspQuality]] = []
    for k in range(0, len(ranked), CHUNK):
        out.extend(_reached(robot, ranked[k: k + CHUNK], fingers, seed + k))
        if need is not None and len(out) >= need:
            return out[:need]
    return out


def _reached(robot: Robot, ranked: Sequence[tuple[ContactSet, GraspQuality]], fingers: Sequence[str], seed: int
             ) -> list[tuple[ContactSet, GraspQuality]]:
    """:func:`reach_sets` of one chunk."""
    body, ok = _ik(robot, np.stack([pose_to_matrix_np(s.posture.palm_pose.numpy()) for s, _ in ranked]), seed)
    home = robot.home_posture()
    palm = rt_to_pose(*robot.palm_frame(body))
    rows = [robot.finger_index(f) for f in fingers]
    out = []
    for k in np.flatnonzero(ok.numpy()):
        s, q = ranked[k]
        q_fingers = home.fingers.clone()
        q_fingers[rows] = s.posture.fingers[rows].to(q_fingers.dtype)
        out.append((replace(s, posture=Posture(palm[k], q_fingers, body[k])), q))
    return out
