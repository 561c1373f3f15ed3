"""A hand unlike the shipped one, written into a test's tmp folder: what real URDFs do.

``oddhand`` (all lengths in metres):

- ``thumb``: 4 revolute joints with non-unit axes (``0 0 2``, ``1 1 0``...), base rotated on the palm,
  tip a link;
- ``index``: 4 joints, the last a ``<mimic>`` of the third (multiplier 0.7, offset 0.05): 3 free;
- ``middle``: 2 joints, its chain starts directly at the palm (no base link), and the URDF ends at
  the distal joint: the tip is an offset in the distal link (``tip: {link, offset}``);
- ``ring``: a revolute joint then a prismatic one (a sliding fingertip).

The file starts with an XML encoding declaration, as many exported URDFs do.

``coupled`` (:func:`write_coupled_hand`): fingers that share joints: a hub joint carrying fingers a
and b, a spread joint on finger c whose mimic turns finger d's base, and an independent finger e.
"""

from __future__ import annotations

from pathlib import Path

import torch
import yaml

MIMIC = {"index_dip": ("index_pip", 0.7, 0.05)}
MIDDLE_TIP_OFFSET = (0.0, 0.0, 0.022)


def _limit(lo: float, hi: float) -> str:
    return f'<limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/>'


def oddhand_urdf() -> str:
    box = '<collision><geometry><box size="0.07 0.02 0.08"/></geometry></collision>'
    cyl = ('<collision><origin xyz="0 0 0.015"/><geometry><cylinder radius="0.006" length="0.03"/></geometry>'
           '</collision>')
    links = ["palm", "thumb_base", "thumb_l1", "thumb_l2", "thumb_l3", "thumb_l4", "thumb_tip",
             "index_base", "index_l1", "index_l2", "index_l3", "index_l4", "index_tip",
             "middle_l1", "middle_distal", "ring_base", "ring_l1", "ring_slider", "ring_tip"]
    body = [f'<link name="palm">{box}</link>'] + [f'<link name="{n}">{cyl}</link>' for n in links[1:]]

    def joint(name, kind, parent, child, xyz="0 0 0", rpy="0 0 0", axis=None, lim=None, mimic=None):
        s = f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        s += f'<origin xyz="{xyz}" rpy="{rpy}"/>'
        if axis:
            s += f'<axis xyz="{axis}"/>'
        if lim:
            s += _limit(*lim)
        if mimic:
            s += f'<mimic joint="{mimic[0]}" multiplier="{mimic[1]}" offset="{mimic[2]}"/>'
        return s + "</joint>"

    j = [
        joint("thumb_mount", "fixed", "palm", "thumb_base", "0.03 0.015 0.02", "0.3 -0.4 0.6"),
        joint("thumb_abd", "revolute", "thumb_base", "thumb_l1", axis="0 0 2", lim=(-0.5, 0.8)),
        joint("thumb_flex", "revolute", "thumb_l1", "thumb_l2", "0 0 0.01", axis="1 1 0", lim=(-0.2, 1.2)),
        joint("thumb_mcp", "revolute", "thumb_l2", "thumb_l3", "0 0 0.04", axis="1 0 0", lim=(0.0, 1.2)),
        joint("thumb_ip", "revolute", "thumb_l3", "thumb_l4", "0 0 0.03", axis="1 0 0", lim=(0.0, 1.3)),
        joint("thumb_tip_joint", "fixed", "thumb_l4", "thumb_tip", "0 0 0.025"),
        joint("index_mount", "fixed", "palm", "index_base", "0.02 0 -0.05", "3.14159265 0 0"),
        joint("index_abd", "revolute", "index_base", "index_l1", axis="0 1 0", lim=(-0.3, 0.3)),
        joint("index_mcp", "revolute", "index_l1", "index_l2", axis="1 0 0", lim=(0.0, 1.5)),
        joint("index_pip", "revolute", "index_l2", "index_l3", "0 0 0.04", axis="1 0 0", lim=(0.0, 1.6)),
        joint("index_dip", "revolute", "index_l3", "index_l4", "0 0 0.025", axis="1 0 0", lim=(0.0, 1.3),
              mimic=MIMIC["index_dip"]),
        joint("index_tip_joint", "fixed", "index_l4", "index_tip", "0 0 0.02"),
        joint("middle_mcp", "revolute", "palm", "middle_l1", "0 0 -0.05", "3.14159265 0 0", "1 0 0", (0.0, 1.5)),
        joint("middle_pip", "revolute", "middle_l1", "middle_distal", "0 0 0.045", axis="1 0 0", lim=(0.0, 1.6)),
        joint("ring_mount", "fixed", "palm", "ring_base", "-0.02 0 -0.05", "3.14159265 0 0"),
        joint("ring_mcp", "revolute", "ring_base", "ring_l1", axis="1 0 0", lim=(0.0, 1.4)),
        joint("ring_slide", "prismatic", "ring_l1", "ring_slider", "0 0 0.03", axis="0 0 1", lim=(0.0, 0.02)),
        joint("ring_tip_joint", "fixed", "ring_slider", "ring_tip", "0 0 0.02"),
    ]
    return ('<?xml version="1.0" encoding="utf-8"?>\n<robot name="oddhand">\n' + "\n".join(body + j)
            + "\n</robot>\n")


def oddhand_config(urdf: str = "oddhand.urdf") -> dict:
    return {
        "name": "oddhand",
        "urdf": urdf,
        "palm_link": "palm",
        "fingers": {
            "thumb": {"base": "thumb_base", "tip": "thumb_tip"},
            "index": {"base": "index_base", "tip": "index_tip"},
            "middle": {"tip": {"link": "middle_distal", "offset": list(MIDDLE_TIP_OFFSET)}},
            "ring": {"base": "ring_base", "tip": "ring_tip"},
        },
        "palm_bounds": {"min": [-0.05, -0.05, 0.10, -30, -30, -30], "max": [0.05, 0.05, 0.20, 30, 30, 30]},
    }


def write_oddhand(folder: Path, **changes) -> Path:
    """Write ``oddhand.urdf`` and ``oddhand.yaml`` (config keys replaced by ``changes``) into
    ``folder``; returns the YAML path."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "oddhand.urdf").write_bytes(oddhand_urdf().encode("utf-8"))
    cfg = oddhand_config()
    cfg.update(changes)
    path = folder / "oddhand.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def pk_fingertips_palm(robot, q):
    """Fingertips in the palm frame by pytorch-kinematics on the whole URDF: every joint set,
    mimic joints computed here from the URDF's own numbers, the robot's tip offsets applied (the config's,
    moved onto the pads' normal lines: robot/pads.py). q: (B, F, n)."""
    import pytorch_kinematics as pk

    chain = pk.build_chain_from_urdf(robot.urdf.path.read_bytes()).to(dtype=torch.float64)
    names = chain.get_joint_parameter_names()
    B = q.shape[0]
    th = torch.zeros(B, len(names), dtype=torch.float64)
    for k, f in enumerate(robot.fingers.values()):
        for i, name in enumerate(f.chain.joint_names):
            th[:, names.index(name)] = q[:, k, i]
    for name, (leader, m, b) in MIMIC.items():
        th[:, names.index(name)] = m * th[:, names.index(leader)] + b
    frames = chain.forward_kinematics(th)
    palm = frames["palm"].get_matrix()
    out = []
    for f in robot.fingers.values():
        T = torch.linalg.solve(palm, frames[f.chain.tip].get_matrix())
        offset = torch.tensor([*(robot.cfg.fingers[f.name].tip_offset or (0, 0, 0)), 1.0], dtype=torch.float64)
        out.append((T @ offset)[:, :3])
    return torch.stack(out, dim=1)


def write_odd_arm(folder: Path, checkpoint: str | None = None) -> Path:
    """The odd hand on a 4-joint arm (shoulder yaw, pitch, elbow, wrist roll) in one URDF, and an
    ``arm_hand``-like config for it (``arm: {base: torso, tip: palm}``); returns the YAML path."""
    folder.mkdir(parents=True, exist_ok=True)
    hand = oddhand_urdf()
    body = hand[hand.index("<link"):hand.rindex("</robot>")]
    cyl = '<collision><origin xyz="0 0 -{h}"/><geometry><cylinder radius="0.03" length="{l}"/></geometry></collision>'
    arm = [
        '<link name="torso"/>',
        '<link name="upper_yaw"/>',
        f'<link name="upper_arm">{cyl.format(h=0.14, l=0.2)}</link>',
        f'<link name="forearm">{cyl.format(h=0.12, l=0.18)}</link>',
        '<joint name="shoulder_yaw" type="revolute"><parent link="torso"/><child link="upper_yaw"/>'
        f'<origin xyz="0 0 0.5"/><axis xyz="0 0 1"/>{_limit(-1.5, 1.5)}</joint>',
        '<joint name="shoulder_pitch" type="revolute"><parent link="upper_yaw"/><child link="upper_arm"/>'
        f'<axis xyz="0 1 0"/>{_limit(-0.5, 2.0)}</joint>',
        '<joint name="elbow" type="revolute"><parent link="upper_arm"/><child link="forearm"/>'
        f'<origin xyz="0 0 -0.3"/><axis xyz="0 1 0"/>{_limit(0.0, 2.2)}</joint>',
        '<joint name="wrist_roll" type="revolute"><parent link="forearm"/><child link="palm"/>'
        f'<origin xyz="0 0 -0.25" rpy="3.14159265 0 0"/><axis xyz="0 0 1"/>{_limit(-1.5, 1.5)}</joint>',
    ]
    (folder / "oddarm.urdf").write_text('<?xml version="1.0"?>\n<robot name="oddarm">\n' + "\n".join(arm) + body
                                        + "</robot>\n")
    cfg = oddhand_config("oddarm.urdf")
    cfg["name"] = "oddarm"
    del cfg["palm_bounds"]
    cfg["arm"] = {"base": "torso", "tip": "palm"}
    if checkpoint:
        cfg["checkpoint"] = checkpoint
    path = folder / "oddarm.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


# ---------------------------------------------------------------- a hand whose fingers share joints
COUPLED_TIPS = {"a": "a_tip", "b": "b_tip", "c": "c_tip", "d": "d_tip", "e": "e_tip"}


def urdf_joint(name, kind, parent, child, xyz="0 0 0", rpy="0 0 0", axis="1 0 0", lim=(-1.0, 1.0), mimic=None):
    s = f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
    s += f'<origin xyz="{xyz}" rpy="{rpy}"/>'
    if kind != "fixed":
        s += f'<axis xyz="{axis}"/><limit lower="{lim[0]}" upper="{lim[1]}" effort="1" velocity="1"/>'
    if mimic:
        s += f'<mimic joint="{mimic[0]}" multiplier="{mimic[1]}" offset="{mimic[2]}"/>'
    return s + "</joint>"


def coupled_hand_urdf(bad: bool = False) -> str:
    """palm; a hub joint carrying fingers a and b (a joint on two chains); a spread joint on finger
    c's chain whose mimic (x0.5) turns finger d's base (a leader driving another finger); finger e
    independent. ``bad``: finger f's own joint comes before a mimic of the spread."""
    cyl = '<collision><origin xyz="0 0 0.01"/><geometry><cylinder radius="0.005" length="0.02"/></geometry></collision>'
    links = ["palm", "hub", "a1", "a2", "a_tip", "b1", "b2", "b_tip", "c0", "c1", "c2", "c_tip",
             "d0", "d1", "d2", "d_tip", "e1", "e2", "e_tip"] + (["f1", "f2", "f_tip"] if bad else [])
    joints = [
        urdf_joint("hub", "revolute", "palm", "hub", "0.02 0 0.05", axis="0 1 0", lim=(-0.4, 0.6)),
        urdf_joint("a_mcp", "revolute", "hub", "a1", "0.01 0 0.01", lim=(0, 1.5)),
        urdf_joint("a_pip", "revolute", "a1", "a2", "0 0 0.04", lim=(0, 1.5)),
        urdf_joint("a_tip_joint", "fixed", "a2", "a_tip", "0 0 0.03"),
        urdf_joint("b_mcp", "revolute", "hub", "b1", "-0.01 0 0.01", lim=(0, 1.5)),
        urdf_joint("b_pip", "revolute", "b1", "b2", "0 0 0.04", lim=(0, 1.5)),
        urdf_joint("b_tip_joint", "fixed", "b2", "b_tip", "0 0 0.03"),
        urdf_joint("spread", "revolute", "palm", "c0", "-0.02 0 0.05", "0.2 0 0", axis="0 1 0", lim=(0, 0.6)),
        urdf_joint("c_mcp", "revolute", "c0", "c1", lim=(0, 1.5)),
        urdf_joint("c_pip", "revolute", "c1", "c2", "0 0 0.04", lim=(0, 1.5)),
        urdf_joint("c_tip_joint", "fixed", "c2", "c_tip", "0 0 0.03"),
        urdf_joint("d_spread", "revolute", "palm", "d0", "-0.04 0 0.05", axis="0 1 0", lim=(0, 0.3),
               mimic=("spread", 0.5, 0.0)),
        urdf_joint("d_mcp", "revolute", "d0", "d1", lim=(0, 1.5)),
        urdf_joint("d_pip", "revolute", "d1", "d2", "0 0 0.04", lim=(0, 1.5), mimic=("d_mcp", 1.2, 0.0)),
        urdf_joint("d_tip_joint", "fixed", "d2", "d_tip", "0 0 0.03"),
        urdf_joint("e_cmc", "revolute", "palm", "e1", "0.03 0.02 0.01", "0 0.5 0", axis="0 0 1", lim=(-0.5, 0.5)),
        urdf_joint("e_mcp", "revolute", "e1", "e2", "0 0 0.03", lim=(0, 1.2)),
        urdf_joint("e_tip_joint", "fixed", "e2", "e_tip", "0 0 0.03"),
    ]
    if bad:
        joints += [urdf_joint("f_own", "revolute", "palm", "f1", "0 0.03 0.05", lim=(0, 1)),
                   urdf_joint("f_spread", "revolute", "f1", "f2", "0 0 0.03", lim=(0, 0.6), mimic=("spread", 1.0, 0.0)),
                   urdf_joint("f_tip_joint", "fixed", "f2", "f_tip", "0 0 0.03")]
    body = [f'<link name="{n}">{cyl}</link>' for n in links]
    return '<robot name="coupled">\n' + "\n".join(body + joints) + "\n</robot>\n"


def write_coupled_hand(folder: Path, bad: bool = False) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "coupled.urdf").write_text(coupled_hand_urdf(bad))
    fingers = {f: {"tip": tip} for f, tip in COUPLED_TIPS.items()}
    if bad:
        fingers["f"] = {"tip": "f_tip"}
    cfg = {"name": "coupled", "urdf": "coupled.urdf", "palm_link": "palm", "fingers": fingers,
           "home": {"hub": 10.0, "spread": 20.0}}
    path = folder / "coupled.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def assert_jacobian_matches_fd(robot, q, atol: float, h: float = 1e-6) -> None:
    """The fingertips' Jacobian in the base frames against central differences of their positions."""
    _, J = robot.fingertips_base_jacobian(q)
    for i in range(robot.joints_per_finger):
        dq = torch.zeros_like(q)
        dq[..., i] = h
        fd = (robot.fingertips_base(q + dq) - robot.fingertips_base(q - dq)) / (2 * h)
        torch.testing.assert_close(J[..., i], fd, atol=atol, rtol=0)
