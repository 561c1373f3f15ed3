"""A hand on an arm chooses contacts too: sets drawn with the free hand its config names, reached by
the arm's full-pose IK, solved for the whole robot, checked independently (the URDF's link
frames, FCL, MuJoCo)."""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.collision.scene import CollisionScene
from graspnet_torch.paths import repo_root
from graspnet_torch.robot.ik import frame_ik
from graspnet_torch.robot.shape import Shape
from graspnet_torch.solver.contact import surface_fields
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.synthesis.reach import carried_hand
from graspnet_torch.synthesis.synthesize import no_grasp_reason

FINGERS = ("thumb", "index", "middle")
GLASS = Shape("cylinder", (0.0325, 0.12), np.array([0.4, -0.15, -0.25, 0.0, 0.0, np.pi]))  # env1's, no obstacle


@pytest.fixture(scope="module")
def arm() -> gt.Robot:
    return gt.load_robot("arm_hand")


def test_frame_ik_reaches_the_palm_poses_of_random_arm_postures(arm: gt.Robot) -> None:
    """Goals made by forward kinematics of random arm postures: the IK's joints put the palm there
    again, as the URDF's link frames place it (not the kernel the IK ran on)."""
    lo, hi = (torch.as_tensor(a) for a in arm.body_limits)
    gen = torch.Generator().manual_seed(1)
    goal = lo + (hi - lo) * torch.rand(40, lo.shape[0], generator=gen, dtype=torch.float64)
    R, t = arm.palm_frame(goal)
    starts = lo + (hi - lo) * torch.rand(40, 8, lo.shape[0], generator=gen, dtype=torch.float64)
    body, pos, rot = frame_ik(arm.palm_frame_jacobian, R, t, starts, lo, hi)
    reached = (pos < 1e-4) & (rot < 1e-4)  # the IK stops within 1e-5 of the goal
    assert reached.float().mean() >= 0.8
    assert bool(((body >= lo - 1e-12) & (body <= hi + 1e-12)).all())
    home = arm.home_posture()
    for k in np.flatnonzero(reached.numpy())[:5]:
        T = arm.link_frames(gt.Posture(home.palm_pose, home.fingers, body[k]))[arm.cfg.palm_link]
        np.testing.assert_allclose(T[:3, 3], t[k].numpy(), atol=1e-4)
        np.testing.assert_allclose(T[:3, :3], R[k].numpy(), atol=2e-4)


def test_the_carried_hand_has_the_arms_fingers(arm: gt.Robot) -> None:
    hand = carried_hand(arm)
    assert not hand.has_body and list(hand.fingers) == list(arm.fingers)
    assert carried_hand(hand) is hand
    trifinger = str(repo_root() / "examples" / "trifinger" / "trifinger.yaml")
    other = gt.load_robot(dataclasses.replace(arm.cfg, hand=trifinger))
    with pytest.raises(gt.ProblemError, match=r"robot arm_hand: its hand '.*trifinger.yaml' must be a free hand "
                                              r"with the robot's fingers"):
        carried_hand(other)
    with pytest.raises(gt.ProblemError, match=r"robot manus: contacts are chosen for a free hand, or a hand on an arm"):
        carried_hand(gt.load_robot("manus"))


def test_arm_and_hand_synthesis_puts_the_pads_on_the_contacts(arm: gt.Robot) -> None:
    """Every grasp: the arm within its limits, each pad sphere on its contact by the URDF's link frames,
    nothing inside the object (FCL, arm included), and, with MuJoCo, the best holds 6/6."""
    physics = gt.simulate_grasp if importlib.util.find_spec("mujoco") is not None else None
    stats: dict = {}
    grasps = gt.synthesize_grasps(arm, GLASS, n_grasps=2, fingers=FINGERS, candidates=16, seed=0, physics=physics,
                                  stats=stats)
    assert grasps, stats
    lo, hi = arm.body_limits
    problem = grasps[0].problem
    scene = CollisionScene(arm, problem, object_tolerance=0.001, touching=False)
    for g in grasps:
        assert g.success and g.problem.robot == "arm_hand"
        posture = trial_posture(arm, g.result.best)
        body = posture.body.numpy()
        assert np.all(body >= np.asarray(lo) - 1e-9) and np.all(body <= np.asarray(hi) + 1e-9)
        frames = arm.link_frames(posture)
        for k, f in enumerate(FINGERS):
            T = frames[arm.cfg.fingers[f].tip].copy()  # the tip frame (the pad's), tip offset applied
            offset = arm.cfg.fingers[f].tip_offset
            if offset is not None:
                T[:3, 3] += T[:3, :3] @ np.asarray(offset)
            gap = np.linalg.norm(g.contacts[k] - T[:3, 3]) - arm.pads[f].depth
            assert abs(gap) < 1e-3, f  # the pad sphere (the tip, radius the pad's depth) touches its contact
        fields = surface_fields(arm, g.problem, [posture])[0]
        assert fields["penetration_mm"] <= 1.0 + 1e-6
        assert scene.check(posture).count == 0
        np.testing.assert_allclose(g.problem.contacts_world(), g.contacts, atol=1e-9)
    if physics is not None:
        assert grasps[0].holds == 6


def test_an_object_out_of_the_arms_reach_gets_no_grasp(arm: gt.Robot) -> None:
    far = Shape("sphere", (0.04,), np.array([3.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    stats: dict = {}
    assert gt.synthesize_grasps(arm, far, n_grasps=1, candidates=4, seed=0, stats=stats) == []
    assert stats["tried"] > 0 and stats["reached"] == 0 and stats["touching"] == 0
    assert no_grasp_reason(stats) == (f"no grasp found: the arm reached none of {stats['tried']} palm poses around "
                                      f"the object (out of its reach?)")

