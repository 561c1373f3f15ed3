"""A hand unlike the shipped one (tests/odd_hands.py): mixed joint counts, a mimic joint, a tip
offset, a chain starting at the palm, non-unit axes, a prismatic joint, an encoding declaration.
Kinematics against pytorch-kinematics and finite differences in float64."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import yaml

import graspnet_torch as gt
from graspnet_torch.fcnn.checkpoint import chain_fingerprint
from graspnet_torch.robot.fingers import FingerKernel
from graspnet_torch.robot.kernel import ChainKernel
from tests.conftest import uniform
from tests.odd_hands import (
    MIDDLE_TIP_OFFSET,
    MIMIC,
    assert_jacobian_matches_fd,
    oddhand_config,
    pk_fingertips_palm,
    write_oddhand,
)


@pytest.fixture(scope="module")
def odd(tmp_path_factory) -> gt.Robot:
    return gt.load_robot(str(write_oddhand(tmp_path_factory.mktemp("odd"))))


def test_structure_free_joints_padding_and_mimic(odd):
    assert odd.finger_names == ("thumb", "index", "middle", "ring")
    assert [f.n_joints for f in odd.fingers.values()] == [4, 3, 2, 2]
    assert odd.joints_per_finger == 4 and odd.n_finger_joints == 11 and odd.dof == 17
    assert odd.finger_mask.tolist() == [[True] * 4, [True, True, True, False], [True, True, False, False],
                                        [True, True, False, False]]
    index = odd.fingers["index"].chain
    assert index.joint_names == ("index_abd", "index_mcp", "index_pip")
    assert index.all_joint_names[-1] == "index_dip" and index.mimic_joint_names == ("index_dip",)
    assert odd.fingers["middle"].chain.root == "palm"  # no base link: the chain starts at the palm
    lo, hi = odd.finger_limits
    assert np.all(lo[~odd.finger_mask] == 0) and np.all(hi[~odd.finger_mask] == 0)
    assert odd.cfg.checkpoint.name == "oddhand.fcnn.pt"  # beside the config given by path


def test_fingertips_match_pytorch_kinematics_with_mimic_and_offset(odd, gen):
    moved = np.subtract(odd.cfg.fingers["middle"].tip_offset, MIDDLE_TIP_OFFSET)  # onto its pad's normal line only
    assert abs(float(moved @ odd.pads["middle"].normal)) < 1e-12
    q = uniform(*odd.finger_limits, 64, gen)  # pytorch-kinematics keeps joint origins in float32: ~1e-8 m
    np.testing.assert_allclose(odd.fingertips_palm(q).numpy(), pk_fingertips_palm(odd, q).numpy(), atol=5e-8)
    q32 = q.float()
    np.testing.assert_allclose(odd.fingertips_palm(q32).double().numpy(), pk_fingertips_palm(odd, q).numpy(), atol=2e-6)


def test_jacobian_matches_finite_differences_and_padding_is_inert(odd, gen):
    q = uniform(*odd.finger_limits, 16, gen)
    p, J = odd.fingertips_base_jacobian(q)
    assert_jacobian_matches_fd(odd, q, atol=1e-8)
    assert torch.all(J.permute(0, 1, 3, 2)[:, torch.as_tensor(~odd.finger_mask)] == 0)  # padding moves nothing
    moved = q.clone()
    moved[:, torch.as_tensor(~odd.finger_mask)] = 0.7
    assert torch.equal(odd.fingertips_base(moved), odd.fingertips_base(q))
    torch.testing.assert_close(p, odd.fingertips_base(q), rtol=0, atol=1e-12)


def test_stacked_kernel_equals_each_finger_alone(odd, gen):
    q = uniform(*odd.finger_limits, 20, gen)
    p, J = odd.finger_kernel.position_jacobian(q)
    for k, f in enumerate(odd.fingers.values()):
        pk_, Jk = FingerKernel(f.chain).position_jacobian(q[:, k, : f.n_joints])
        torch.testing.assert_close(p[:, k], pk_, rtol=0, atol=1e-12)
        torch.testing.assert_close(J[:, k, :, : f.n_joints], Jk, rtol=0, atol=1e-12)
        ref = np.stack([f.chain.transform(row)[:3, 3] for row in q[:, k, : f.n_joints].numpy()])
        np.testing.assert_allclose(pk_.numpy(), ref, atol=1e-12)


def test_joint_values_list_mimic_joints_at_their_coupled_values(odd, gen):
    q = uniform(*odd.finger_limits, 1, gen)[0]
    values = odd.finger_joint_values(q)
    assert [len(v) for v in values.values()] == [4, 4, 2, 2]
    _leader, m, b = MIMIC["index_dip"]
    assert values["index"][3] == pytest.approx(m * values["index"][2] + b, abs=1e-12)
    assert torch.equal(odd.free_finger_joints(values), q)
    as_file = odd.finger_joints_to_file(q)
    assert as_file["ring"][1] == pytest.approx(float(q[3, 1]))  # prismatic: metres, not degrees
    assert as_file["thumb"][0] == pytest.approx(math.degrees(float(q[0, 0])))
    torch.testing.assert_close(odd.finger_joints_from_file(as_file), q, rtol=0, atol=1e-12)


def test_multilinear_route_handles_prismatic_joints(odd, gen):
    spec = odd.fingers["ring"].chain.spec  # revolute then prismatic
    kernel = ChainKernel(spec)
    q = uniform(spec.lower, spec.upper, 32, gen)
    p1, J1 = kernel.position_jacobian(q, strategy="multilinear")
    p2, J2 = kernel.position_jacobian(q, strategy="soa")
    torch.testing.assert_close(p1, p2, rtol=0, atol=1e-12)
    torch.testing.assert_close(J1, J2, rtol=0, atol=1e-12)


def test_fingerprint_sees_the_mimic_coupling(tmp_path, odd, hand):
    folder = tmp_path / "other"
    path = write_oddhand(folder)
    urdf = folder / "oddhand.urdf"
    urdf.write_text(urdf.read_text().replace('multiplier="0.7"', 'multiplier="0.8"'))
    other = gt.load_robot(str(path))
    assert chain_fingerprint(other.fingers["index"].chain) != chain_fingerprint(odd.fingers["index"].chain)
    assert chain_fingerprint(other.fingers["thumb"].chain) == chain_fingerprint(odd.fingers["thumb"].chain)
    # the hand has no mimic: the plain chain's fingerprint (shipped checkpoints stay valid)
    assert chain_fingerprint(hand.fingers["index"].chain) == chain_fingerprint(hand.fingers["index"].chain.spec)


def _config_with(tmp_path, **fingers):
    cfg = oddhand_config()
    cfg["fingers"].update(fingers)
    write_oddhand(tmp_path)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return str(path)


@pytest.mark.parametrize("finger, message", [
    ({"middle": {"tip": "middle_distal"}},
     r"finger 'middle': joint\(s\) middle_pip never move its tip 'middle_distal' .*give the tip an offset: "
     r"tip: \{link: middle_distal, offset: \[x, y, z\]\}"),
    ({"index": {"base": "index_base", "tip": "index_nail"}},
     r"finger 'index' tip: link 'index_nail' is not in oddhand"),
    ({"index": {"base": "index_l2", "tip": "index_tip"}},
     r"finger 'index': its chain must start at the palm, but joint 'index_abd' between palm_link 'palm'"),
    ({"ring": {"base": "ring_base", "tip": {"link": "ring_tip", "offset": [0, 0]}}}, r"fingers.ring.tip.offset"),
    ({"ring": {"bse": "ring_base", "tip": "ring_tip"}}, r"fingers.ring: expected \{base: <link>, tip: <link>\}"),
])
def test_bad_finger_configs_are_one_clear_line(tmp_path, finger, message):
    with pytest.raises(gt.ConfigError, match=message) as info:
        gt.load_robot(_config_with(tmp_path, **finger))
    assert "\n" not in str(info.value)


def test_a_mimic_leader_outside_the_finger_is_refused(tmp_path):
    path = write_oddhand(tmp_path)
    urdf = tmp_path / "oddhand.urdf"
    coupled = ('<limit lower="0.0" upper="1.4" effort="1" velocity="1"/>'
               '<mimic joint="index_mcp" multiplier="1" offset="0"/>')
    text = urdf.read_text()
    assert text.count('<limit lower="0.0" upper="1.4" effort="1" velocity="1"/>') == 1  # ring_mcp
    urdf.write_text(text.replace('<limit lower="0.0" upper="1.4" effort="1" velocity="1"/>', coupled))
    with pytest.raises(gt.ConfigError, match=r"finger 'ring': mimic joint 'ring_mcp' follows 'index_mcp', which is "
                                             r"not a joint of this finger's chain \(ring_mcp, ring_slide\)"):
        gt.load_robot(str(path))


def test_encoding_declaration_is_read(odd):
    assert odd.urdf.path.read_bytes().startswith(b'<?xml version="1.0" encoding="utf-8"?>')
    assert len(odd.urdf.movable_joint_names) == 12
