"""One random-problem generator per robot kind: deterministic in the seed, refused for the other kind,
and reachable by construction."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision.problems import random_obstacle_problems
from graspnet_torch.tasks import (
    random_arm_problem,
    random_gripper_problems,
    random_hand_problem,
    random_reachable_problem,
)


def test_random_reachable_problem_is_the_generator_of_the_robots_kind():
    hand, arm = gt.load_robot("hand"), gt.load_robot("arm_hand")
    for seed in (0, 5):
        assert random_reachable_problem(hand, seed).to_mapping() == random_hand_problem(hand, seed).to_mapping()
        assert random_reachable_problem(arm, seed, 2).to_mapping() == random_arm_problem(arm, seed, 2).to_mapping()
    assert random_hand_problem(hand, 3).to_mapping() != random_hand_problem(hand, 4).to_mapping()
    with pytest.raises(ValueError, match=r"'arm_hand' \(arm_hand\): its random problems come from random_reachable"):
        random_hand_problem(arm, 0)
    with pytest.raises(ValueError, match=r"'hand' \(hand\): its random problems come from random_reachable"):
        random_arm_problem(hand, 0)
    with pytest.raises(ValueError, match="at least two fingers"):
        random_reachable_problem(gt.load_robot("manus"), 0)


def test_a_hand_problem_has_two_to_all_fingers_inside_the_palm_box():
    hand = gt.load_robot("hand")
    counts = {len(random_hand_problem(hand, s).contacts) for s in range(30)}
    assert counts <= set(range(2, hand.n_fingers + 1)) and len(counts) > 1
    assert all(len(random_hand_problem(hand, s, n_fingers=3).contacts) == 3 for s in range(5))


def test_gripper_problems_are_the_gripper_points_of_a_configuration():
    manus = gt.load_robot("manus")
    problems = random_gripper_problems(manus, 4, seed=3)
    again = random_gripper_problems(manus, 4, seed=3)
    assert [p.points.tolist() for p in problems] == [p.points.tolist() for p in again]
    lo, hi = (torch.as_tensor(a) for a in manus.body_limits)
    gen = torch.Generator().manual_seed(3)
    q = [lo + (hi - lo) * torch.rand(1, len(lo), generator=gen, dtype=torch.float64) for _ in range(2)]
    np.testing.assert_allclose(problems[0].points, manus.gripper_points(q[0])[0].numpy())
    np.testing.assert_allclose(problems[1].points[::-1], manus.gripper_points(q[1])[0].numpy())  # listed reversed
    assert all(p.robot == "manus" and not p.contacts for p in problems)


def test_obstacle_problems_keep_their_obstacles_clear_of_the_contacts():
    arm = gt.load_robot("arm_hand")
    problems = random_obstacle_problems(arm, 2, seed=1)
    assert [p.to_mapping() for p in problems] == [p.to_mapping() for p in random_obstacle_problems(arm, 2, seed=1)]
    for p in problems:
        assert 2 <= len(p.obstacles) <= 3 and p.fingers == ("thumb", "index", "middle")
        assert p.joint_bounds is not None and np.all(p.joint_bounds[0] <= p.joint_bounds[1])
