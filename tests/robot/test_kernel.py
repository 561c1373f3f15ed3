"""ChainKernel against pytorch-kinematics, finite differences and its own batched/looped forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from graspnet_torch.robot import ChainKernel, UrdfModel
from tests.conftest import ROBOTS, uniform

pk = pytest.importorskip("pytorch_kinematics")


def every_chain(robot):
    """(root, tip) of every serial chain a robot evaluates, plus the whole-tree chains to each
    fingertip / gripper point."""
    cfg = robot.cfg
    chains = [(c.base, c.tip) for c in cfg.fingers.values()]
    root = robot.urdf.root_link
    if cfg.arm is not None:
        chains.append((root, cfg.palm_link))
        chains += [(root, c.tip) for c in cfg.fingers.values()]
        chains += [(root, p) for p in cfg.gripper_points]
    else:
        chains += [(cfg.palm_link, c.tip) for c in cfg.fingers.values()]
    return chains


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.slow
def test_every_chain_matches_pytorch_kinematics(robots, name):
    """1,000 random configurations within limits per chain: tip pose and Jacobian agree to 1e-6."""
    robot = robots[name]
    gen = torch.Generator().manual_seed(7)
    for root, tip in every_chain(robot):
        spec = robot.urdf.chain_spec(root, tip)
        kernel = ChainKernel(spec)
        ref = robot.urdf.serial_chain(root, tip).to(dtype=torch.float64)
        q = uniform(spec.lower, spec.upper, 1000, gen)
        R, p, J = kernel.pose_jacobian(q)
        T = ref.forward_kinematics(q).get_matrix()
        assert (p - T[:, :3, 3]).abs().max() < 1e-6, (root, tip)
        assert (R - T[:, :3, :3]).abs().max() < 1e-6, (root, tip)
        assert (J - ref.jacobian(q)).abs().max() < 1e-6, (root, tip)


@pytest.mark.parametrize("name", ROBOTS)
@pytest.mark.slow
def test_fk_finite_at_joint_limits(robots, name):
    robot = robots[name]
    for root, tip in every_chain(robot):
        spec = robot.urdf.chain_spec(root, tip)
        corners = torch.tensor(np.stack([spec.lower, spec.upper,
                                         np.where(np.arange(spec.n_joints) % 2, spec.lower, spec.upper)]))
        R, p, J = ChainKernel(spec).pose_jacobian(corners)
        assert torch.isfinite(p).all() and torch.isfinite(R).all() and torch.isfinite(J).all()


def test_spec_reference_transform_matches_kernel(hand, gen):
    spec = hand.fingers["thumb"].chain.spec
    q = uniform(spec.lower, spec.upper, 20, gen)
    R, p = ChainKernel(spec).pose(q)
    for k in range(20):
        T = spec.transform(q[k].numpy())
        np.testing.assert_allclose(p[k].numpy(), T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(R[k].numpy(), T[:3, :3], atol=1e-12)


@pytest.mark.parametrize("finger", ["thumb", "index", "pinky"])
def test_jacobian_matches_central_differences(hand, gen, finger):
    spec = hand.fingers[finger].chain.spec
    kernel = ChainKernel(spec)
    q = uniform(spec.lower, spec.upper, 50, gen)
    _, J = kernel.position_jacobian(q)
    h = 1e-6
    fd = torch.stack([(kernel.position(q + h * e) - kernel.position(q - h * e)) / (2 * h)
                      for e in torch.eye(spec.n_joints, dtype=q.dtype)], dim=-1)
    assert (J - fd).abs().max() < 1e-8


def test_jacobian_matches_autograd(hand, gen):
    spec = hand.fingers["index"].chain.spec
    kernel = ChainKernel(spec)
    q = uniform(spec.lower, spec.upper, 1, gen)[0]
    auto = torch.autograd.functional.jacobian(kernel.position, q)
    _, J = kernel.position_jacobian(q)
    assert (auto - J).abs().max() < 1e-12


def test_stacked_equals_separate_and_batched_equals_looped(hand, gen):
    specs = [f.chain.spec for f in hand.fingers.values()]
    stacked = ChainKernel(specs)
    lo, hi = hand.finger_limits
    q = uniform(lo, hi, 64, gen)  # (64, F, 4)
    p, J = stacked.position_jacobian(q)
    for k, spec in enumerate(specs):
        pk_, Jk = ChainKernel(spec).position_jacobian(q[:, k])
        assert torch.equal(p[:, k], pk_) or (p[:, k] - pk_).abs().max() < 1e-15
        assert (J[:, k] - Jk).abs().max() < 1e-15
    for b in range(0, 64, 9):
        pb, Jb = stacked.position_jacobian(q[b])
        assert (pb - p[b]).abs().max() < 1e-15 and (Jb - J[b]).abs().max() < 1e-15


def test_leading_batch_dimensions_and_float32(hand, gen):
    kernel = hand.finger_kernel
    lo, hi = hand.finger_limits
    q = uniform(lo, hi, 24, gen).reshape(2, 3, 4, 5, 4)
    p = kernel.position(q)
    assert p.shape == (2, 3, 4, 5, 3)
    p32 = kernel.position(q.float())
    assert p32.dtype == torch.float32
    assert (p32.double() - p).abs().max() < 1e-6


def _planar_urdf(axis_xyz: str, prismatic: bool = False) -> str:
    j2 = ('<joint name="j2" type="prismatic"><parent link="l1"/><child link="l2"/>'
          '<origin xyz="0.1 0 0" rpy="0.3 -0.2 0.5"/><axis xyz="0.6 0 0.8"/>'
          '<limit lower="-0.2" upper="0.2" effort="1" velocity="1"/></joint>') if prismatic else \
         ('<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>'
          '<origin xyz="0.1 0 0" rpy="0.3 -0.2 0.5"/><axis xyz="0 1 0"/>'
          '<limit lower="-2" upper="2" effort="1" velocity="1"/></joint>')
    return f"""<robot name="t"><link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0.02 0" rpy="0 0 0.4"/>
<axis xyz="{axis_xyz}"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>{j2}
<joint name="jt" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.05 0.01 -0.02"/></joint></robot>"""


@pytest.mark.parametrize("axis", ["0 0 1", "0 0 -1", "1 0 0", "-1 0 0", "0 1 0", "0.267 0.535 0.802"])
@pytest.mark.parametrize("prismatic", [False, True])
def test_arbitrary_axes_and_prismatic_joints(tmp_path, gen, axis, prismatic):
    """The kernel is generic: any axis, revolute or prismatic, arbitrary fixed offsets."""
    path = tmp_path / "t.urdf"
    path.write_text(_planar_urdf(axis, prismatic))
    model = UrdfModel(path)
    spec = model.chain_spec("base", "tip")
    assert spec.joint_types == ("revolute", "prismatic" if prismatic else "revolute")
    q = uniform(spec.lower, spec.upper, 200, gen)
    R, p, J = ChainKernel(spec).pose_jacobian(q)
    ref = model.serial_chain("base", "tip").to(dtype=torch.float64)
    T = ref.forward_kinematics(q).get_matrix()
    assert (p - T[:, :3, 3]).abs().max() < 1e-6
    assert (R - T[:, :3, :3]).abs().max() < 1e-6
    assert (J - ref.jacobian(q)).abs().max() < 1e-6


def test_constant_folding_removes_work(hand):
    """An axis-aligned finger needs far fewer ops than a dense 4x4 product would (sanity of the
    compiler, and a guard against regressions that would silently slow the hot path)."""
    kernel = ChainKernel(hand.fingers["index"].chain.spec)
    assert kernel.num_ops(("p",)) < kernel.num_ops(("p", "Jv")) < 80
    dense_fk_ops = 4 * (12 + 27 + 9)  # mixing + R C + R t per joint, without folding
    assert kernel.num_ops(("p",)) < dense_fk_ops / 3


@pytest.mark.parametrize("bad", [(10, 3), (10, 5), (3,), (2, 5, 3)])
def test_wrong_joint_shape_is_a_clear_error(hand, bad):
    kernel = ChainKernel(hand.fingers["index"].chain.spec)
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 4\).*index_tip"):
        kernel.position(torch.zeros(bad))


def test_non_tensor_and_integer_joints_are_refused(hand):
    kernel = ChainKernel(hand.fingers["index"].chain.spec)
    with pytest.raises(TypeError, match=r"torch.Tensor"):
        kernel.position([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(TypeError, match=r"floating point"):
        kernel.position(torch.zeros(4, dtype=torch.int64))


def test_stack_of_unlike_chains_is_refused(tmp_path):
    path = tmp_path / "t.urdf"
    path.write_text(_planar_urdf("0 0 1", prismatic=True))
    model = UrdfModel(path)
    rev = model.chain_spec("base", "l1")
    pri = model.chain_spec("l1", "tip")
    with pytest.raises(ValueError, match=r"differ in their joint types"):
        ChainKernel([rev, pri])


def test_closed_form_index_finger(hand, gen):
    """FK of the index finger in its base frame against a closed form derived by hand:
    abduction a about -y, then a planar 3R chain in the finger's x-y plane,

        p = Ry(-a) [l1 c1 + l2 c12 + l3 c123,  l1 s1 + l2 s12 + l3 s123,  0]^T.
    """
    # segment lengths of the index finger: hand length 0.19 m x Buchholz et al. (1992) ratios
    l1, l2, l3 = (0.19 * r for r in (0.245, 0.143, 0.097))
    spec = hand.fingers["index"].chain.spec
    q = uniform(spec.lower, spec.upper, 500, gen)
    a, t1, t2, t3 = q.unbind(-1)
    t12, t123 = t1 + t2, t1 + t2 + t3
    planar = torch.stack([l1 * torch.cos(t1) + l2 * torch.cos(t12) + l3 * torch.cos(t123),
                          l1 * torch.sin(t1) + l2 * torch.sin(t12) + l3 * torch.sin(t123),
                          torch.zeros_like(a)], dim=-1)
    ca, sa = torch.cos(-a), torch.sin(-a)
    Ry = torch.stack([torch.stack([ca, 0 * ca, sa], -1), torch.stack([0 * ca, 1 + 0 * ca, 0 * ca], -1),
                      torch.stack([-sa, 0 * ca, ca], -1)], -2)
    expected = (Ry @ planar.unsqueeze(-1)).squeeze(-1)
    assert (ChainKernel(spec).position(q) - expected).abs().max() < 1e-12
    assert math.isclose(float(torch.linalg.norm(ChainKernel(spec).position(torch.zeros(4, dtype=torch.float64)))),
                        l1 + l2 + l3, rel_tol=1e-12)


def _same(a, b) -> bool:
    a, b = (a,) if isinstance(a, torch.Tensor) else a, (b,) if isinstance(b, torch.Tensor) else b
    return all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


def test_rows_of_a_stack_equal_a_stack_of_those_chains_bit_for_bit(hand, gen):
    """A kernel of some chains of a stack (a problem's contact fingers among the hand's) is the
    stack's, rows selected: the same object for the same rows, and the results of a kernel built
    from those chains alone, bit for bit, on both routes (small and large batches), in float32
    and float64; single chains (which fold otherwise) included."""
    specs = [f.chain.spec for f in hand.fingers.values()]
    stack = ChainKernel(specs)
    for rows in [(0, 1), (1, 3, 4), (4, 2, 0), (0, 1, 2, 3, 4), (3,), (2,)]:
        view = stack.rows(rows)
        assert view is stack.rows(list(rows)) and view.num_chains == len(rows)
        alone = ChainKernel([specs[r] for r in rows])
        assert view.num_ops(("p", "Jv")) == alone.num_ops(("p", "Jv"))
        lo = torch.as_tensor(np.stack([specs[r].lower for r in rows]))
        hi = torch.as_tensor(np.stack([specs[r].upper for r in rows]))
        for batch in (3, 500):
            q = uniform(lo, hi, batch, gen)
            for dtype in (torch.float32, torch.float64):
                qq = q.to(dtype)
                for fn in ("position", "position_jacobian", "pose", "pose_jacobian"):
                    assert _same(getattr(view, fn)(qq), getattr(alone, fn)(qq)), (rows, batch, dtype, fn)
        ref = np.stack([np.stack([specs[r].transform(row)[:3, 3] for r, row in zip(rows, qk, strict=True)])
                        for qk in q[:20].numpy()])  # the chains' own float64 evaluation
        np.testing.assert_allclose(view.position(q[:20]).numpy(), ref, atol=1e-12)


def test_rows_that_fold_otherwise_are_traced_anew(tmp_path, gen):
    """Where the chosen rows alone fold otherwise than the stack (here: an offset that is zero
    for the first chain only), their program is their own, with fewer ops than the stack's, and
    their results are those of a kernel built from them alone."""
    straight = _planar_urdf("0 0 1")
    bent = straight.replace('<origin xyz="0.05 0.01 -0.02"/>', '<origin xyz="0.05 0.01 0.03"/>').replace(
        '<origin xyz="0 0.02 0" rpy="0 0 0.4"/>', '<origin xyz="0 0.02 0.01" rpy="0 0 0.4"/>')
    specs = []
    for k, text in enumerate((straight.replace("0.05 0.01 -0.02", "0.05 0.01 0"), bent)):
        path = tmp_path / f"c{k}.urdf"
        path.write_text(text)
        specs.append(UrdfModel(path).chain_spec("base", "tip"))
    stack = ChainKernel(specs)
    first = stack.rows([0])
    alone = ChainKernel([specs[0]])
    assert first.num_ops(("p", "Jv")) == alone.num_ops(("p", "Jv")) < stack.num_ops(("p", "Jv"))
    q = uniform(specs[0].lower, specs[0].upper, 300, gen).unsqueeze(1)
    for dtype in (torch.float32, torch.float64):
        assert _same(first.position_jacobian(q.to(dtype)), alone.position_jacobian(q.to(dtype)))
    with pytest.raises(ValueError, match=r"rows \[2\] of a stack of 2"):
        stack.rows([2])
