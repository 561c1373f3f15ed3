"""``random_sequence``: a smooth random walk of a reachable posture, within the search space, with
bounded steps, deterministic in its seed."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.robot.transforms import pose_to_rt
from graspnet_torch.tasks import random_sequence


def _contacts(problems: list[gt.GraspProblem]) -> np.ndarray:
    """(T, K, 3) contact positions of every frame."""
    return np.stack([[c.position for c in p.contacts] for p in problems])


def _reference(robot: gt.Robot, problem: gt.GraspProblem) -> tuple[torch.Tensor, torch.Tensor]:
    """The frame's reference posture: palm pose (6,) or arm joints (m,), and free finger joints (F, n)."""
    ref = problem.reference
    q = robot.free_finger_joints({f: ref.joints[f].tolist() for f in robot.finger_names})
    if ref.arm_joints is not None:
        return torch.tensor([ref.arm_joints[n] for n in robot.body_joint_names], dtype=torch.float64), q
    return torch.as_tensor(ref.palm_pose, dtype=torch.float64), q


def test_a_sequence_is_deterministic_with_the_same_fingers_in_every_frame(hand):
    a = random_sequence(hand, 3, 20, n_fingers=(4, 5))
    assert [p.to_mapping() for p in a] == [p.to_mapping() for p in random_sequence(hand, 3, 20, n_fingers=(4, 5))]
    assert [p.to_mapping() for p in a] != [p.to_mapping() for p in random_sequence(hand, 4, 20, n_fingers=(4, 5))]
    assert len(a) == 20 and len({p.fingers for p in a}) == 1 and len(a[0].fingers) in (4, 5)
    assert all(len(random_sequence(hand, s, 2, n_fingers=3)[1].contacts) == 3 for s in range(3))
    assert np.linalg.norm(_contacts(a)[-1] - _contacts(a)[0], axis=-1).max() > 0.01  # it moves


@pytest.mark.parametrize(("step_m", "step_deg"), [(0.01, 5.0), (0.002, 1.0)])
def test_every_step_keeps_within_its_limits(hand, step_m, step_deg):
    problems = random_sequence(hand, 1, 40, n_fingers=5, step_m=step_m, step_deg=step_deg)
    moves = np.linalg.norm(np.diff(_contacts(problems), axis=0), axis=-1).max(axis=-1)
    assert moves.max() <= step_m + 1e-12 and np.median(moves) > step_m / 4  # scaled down, not to nothing
    R = [pose_to_rt(_reference(hand, p)[0])[0] for p in problems]
    turns = [math.degrees(math.acos(min(1.0, (float(torch.trace(a.T @ b)) - 1) / 2))) for a, b in itertools.pairwise(R)]
    assert max(turns) <= step_deg + 1e-9


def test_each_frame_is_reachable_by_its_reference_within_the_bounds(hand):
    lo, hi = hand.finger_limits
    b = hand.palm_bounds
    for seed in (0, 7):
        for p in random_sequence(hand, seed, 60, n_fingers=(2, 5), step_m=0.02, step_deg=10.0):
            pose, q = _reference(hand, p)
            assert np.all(b.lower - 1e-9 <= pose.numpy()) and np.all(pose.numpy() <= b.upper + 1e-9)
            assert np.all(lo - 1e-9 <= q.numpy()) and np.all(q.numpy() <= hi + 1e-9)
            tips = hand.fingertips_world(pose, q)[[hand.finger_index(f) for f in p.fingers]]
            np.testing.assert_allclose(tips.numpy(), _contacts([p])[0], atol=1e-9)


def test_a_hand_on_an_arm_walks_its_arm_joints(robots):
    arm = robots["arm_hand"]
    problems = random_sequence(arm, 2, 15, n_fingers=3, step_m=0.01)
    assert np.linalg.norm(np.diff(_contacts(problems), axis=0), axis=-1).max() <= 0.01 + 1e-12
    blo, bhi = arm.body_limits
    for p in problems:
        body, q = _reference(arm, p)
        assert np.all(blo - 1e-9 <= body.numpy()) and np.all(body.numpy() <= bhi + 1e-9)
        tips = arm.fingertips_world_from_body(body, q)[[arm.finger_index(f) for f in p.fingers]]
        np.testing.assert_allclose(tips.numpy(), _contacts([p])[0], atol=1e-9)
    with pytest.raises(ValueError, match="at least two fingers"):
        random_sequence(robots["manus"], 0, 3)
    with pytest.raises(ValueError, match="frames >= 1"):
        random_sequence(arm, 0, 0)
