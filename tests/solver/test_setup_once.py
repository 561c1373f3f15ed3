"""A solver's set-up paid once per robot: the finger kernels and the FCNN's stacked weights are
built once for all of a robot's fingers, a problem's subset of fingers selects rows of them, the
answers are those of the fingers alone, and nothing is shared between two robots."""

from __future__ import annotations

import itertools

import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.fcnn import FingerIK
from graspnet_torch.paths import repo_root
from graspnet_torch.robot import load_robot_cfg
from graspnet_torch.robot.fingers import FingerKernel
from tests.conftest import uniform

pk = pytest.importorskip("pytorch_kinematics")


@pytest.fixture(scope="module")
def shipped_ik() -> FingerIK:
    return gt.Solver("hand").finger_ik


def test_bank_built_once_per_robot_across_finger_subsets(shipped_ik):
    """Solves of problems with different contact fingers stack the experts' weights once (float32:
    the search; the polish's float64 kernel needs no stack), derive one bank per subset, and take
    each subset's kernel from the robot's, the same object every time."""
    robot = gt.load_robot("hand")
    ik = FingerIK(robot, shipped_ik.experts)
    solver = gt.Solver(robot, finger_ik=ik, trials=2, max_iterations=5)
    problems = [gt.random_reachable_problem(robot, 900 + k, (2, 5)) for k in range(8)]
    subsets = {p.fingers for p in problems}
    assert len(subsets) >= 4  # the problems use different fingers
    for p in problems:
        solver.solve(p)
    assert ik.cache_info() == {"stacked": 1, "subsets": len(subsets)}
    for fingers in subsets:
        kernel = ik.kernel(fingers)
        assert kernel is robot.finger_kernel.select([robot.finger_index(f) for f in fingers])
        assert kernel is ik.kernel(list(fingers)) and kernel.num_chains == len(fingers)
    solver.solve(problems[0])
    assert ik.cache_info() == {"stacked": 1, "subsets": len(subsets)}


def _pk_tips(robot: gt.Robot, fingers, q: torch.Tensor) -> torch.Tensor:
    """Fingertips in each finger's base frame by pytorch-kinematics on the URDF. q: (B, F, n)."""
    text = robot.urdf.path.read_bytes()
    out = []
    for k, f in enumerate(fingers):
        chain = robot.fingers[f].chain
        serial = pk.build_serial_chain_from_urdf(text, chain.tip, chain.root).to(dtype=torch.float64)
        out.append(serial.forward_kinematics(q[:, k, : chain.n_joints]).get_matrix()[:, :3, 3])
    return torch.stack(out, dim=1)


@pytest.mark.parametrize("fingers", [("thumb", "index"), ("pinky", "middle", "thumb"), ("ring",),
                                     ("thumb", "index", "middle", "ring", "pinky")])
def test_a_subset_answers_as_the_fingers_alone(hand, shipped_ik, fingers, gen):
    """A subset's answers (the winning experts' joints and their errors, refined) from rows of
    the robot's bank are those of a finger IK holding only those fingers' experts, bit for bit,
    and its fingertip errors are those of pytorch-kinematics at the returned joints."""
    idx = [hand.finger_index(f) for f in fingers]
    q_true = uniform(*hand.finger_limits, 64, gen)
    targets = hand.fingertips_base(q_true)[:, idx]  # reachable: fingertips of random postures
    q, err = shipped_ik.solve_fingers(targets, fingers, refine=2)
    alone = FingerIK(hand, {f: shipped_ik.experts[f] for f in fingers})
    q_alone, err_alone = alone.solve_fingers(targets, fingers, refine=2)
    assert torch.equal(q, q_alone) and torch.equal(err, err_alone)
    tips = _pk_tips(hand, fingers, q)  # pytorch-kinematics keeps joint origins in float32: ~1e-8 m
    torch.testing.assert_close(torch.linalg.vector_norm(tips - targets, dim=-1), err, rtol=0, atol=1e-7)
    assert float(err.median()) < 1e-3  # the trained experts reach them
    q32, err32 = shipped_ik.compete(targets.float(), fingers)
    q32_alone, err32_alone = alone.compete(targets.float(), fingers)
    assert torch.equal(q32, q32_alone) and torch.equal(err32, err32_alone)


def test_every_subset_kernel_equals_one_built_for_it(hand, gen):
    """The robot's kernel, subsets selected (in any order), gives what a kernel built for those
    fingers gives, bit for bit."""
    names = hand.finger_names
    lo, hi = (torch.as_tensor(a) for a in hand.finger_limits)
    for r in range(1, len(names) + 1):
        for rows in itertools.combinations(range(len(names)), r):
            rows = rows[::-1] if r % 2 else rows  # some in reverse order
            built = FingerKernel([hand.fingers[names[k]].chain for k in rows], width=hand.joints_per_finger)
            q = uniform(lo[list(rows)], hi[list(rows)], 40, gen)
            for dtype in (torch.float32, torch.float64):
                a = hand.finger_kernel.select(rows).position_jacobian(q.to(dtype))
                b = built.position_jacobian(q.to(dtype))
                assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1]), rows


def test_nothing_is_shared_between_two_robots(shipped_ik):
    """Two robots (two loads of the hand, and the trifinger by config) keep their own kernels and
    banks: a finger IK selects from its own robot's kernel, and each robot solves its problems."""
    first, second = gt.load_robot("hand"), gt.load_robot("hand")
    tri_cfg = load_robot_cfg(str(repo_root() / "examples" / "trifinger" / "trifinger.yaml"))
    tri_solver = gt.Solver(tri_cfg, trials=4)
    tri = tri_solver.robot
    a = FingerIK(first, shipped_ik.experts)
    b = FingerIK(second, shipped_ik.experts)
    pair = ("thumb", "index")
    assert a.kernel(pair) is first.finger_kernel.select((0, 1))
    assert b.kernel(pair) is second.finger_kernel.select((0, 1)) and b.kernel(pair) is not a.kernel(pair)
    assert tri.finger_kernel.select((0, 1)) is not first.finger_kernel.select((0, 1))
    assert [c.tip for c in tri.finger_kernel.select((0, 1)).chains] == \
        [tri.fingers[f].chain.tip for f in tri.finger_names[:2]]
    hand_solver = gt.Solver(first, finger_ik=a, trials=4)
    for k in range(3):  # alternate the robots
        for solver, robot in ((hand_solver, first), (tri_solver, tri)):
            result = solver.solve(gt.random_reachable_problem(robot, 700 + k, 2))
            assert result.robot == robot.name and result.best.total_error_mm < 1.0
    assert a.cache_info()["stacked"] == 1 and b.cache_info() == {"stacked": 0, "subsets": 0}


def test_chain_kernels_of_a_subset_equal_ones_built_for_it(hand, gen):
    """The robot's full-chain kernels of a subset of alike fingers (what the pad term turns its pads
    with) give the poses and Jacobians of a kernel traced for those chains, bit for bit, the same
    object each time; fingers of different joint types are refused."""
    from graspnet_torch.robot.kernel import ChainKernel

    names = hand.finger_names
    alike = [k for k in range(len(names)) if hand.fingers[names[k]].chain.spec.joint_types
             == hand.fingers[names[1]].chain.spec.joint_types]
    assert len(alike) >= 3
    for rows in (alike[:2], alike[::-1], alike[1:2]):
        kernel = hand.finger_kernel.chain_kernel(rows)
        assert kernel is hand.finger_kernel.chain_kernel(list(rows))
        built = ChainKernel([hand.fingers[names[k]].chain.spec for k in rows])
        n = built.n_joints
        q = torch.rand(30, len(rows), n, generator=gen, dtype=torch.float64)
        for a, b in zip(kernel.pose_jacobian(q), built.pose_jacobian(q), strict=True):
            assert torch.equal(a, b), rows
    kinds = {hand.fingers[f].chain.spec.joint_types for f in names}
    if len(kinds) > 1:
        other = next(k for k in range(len(names)) if k not in alike)
        with pytest.raises(ValueError, match="joint types"):
            hand.finger_kernel.chain_kernel([alike[0], other])
