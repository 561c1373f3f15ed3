"""Generate the shipped URDFs from one table of dimensions.

    python urdf/build.py           # (re)write urdf/{hand,arm_hand,manus}/*.urdf
    python urdf/build.py --check   # exit 1 if a committed URDF differs from what this script writes

The hand is defined once (``HAND``) and reused by ``arm_hand``: one source of truth for its
dimensions. Every number below is documented, with its source, in the README of the robot's folder.
Lengths in metres, angles in degrees (converted to radians in the URDF).

Frames (see urdf/hand/README.md): the palm frame has its origin at the wrist, x radial (towards the
thumb), y palmar (out of the palm), z proximal (towards the forearm), so the extended fingers point
along -z. Each finger base frame sits at the knuckle (MCP; CMC for the thumb) with x distal, y
palmar (the direction the finger flexes to) and z = x cross y; its joints, in chain order, are
abduction (about -y: positive moves the finger radially / away from the palm for the thumb), then
MCP flexion, PIP flexion and DIP flexion (about +z: positive flexes).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent

# --------------------------------------------------------------------------------------------
# Hand dimensions
# --------------------------------------------------------------------------------------------
HAND_LENGTH = 0.19  # wrist crease to middle fingertip, ~50th percentile adult male

# Segment length / hand length (Buchholz, Armstrong & Goldstein 1992, Ergonomics 35(3)).
# Thumb: metacarpal, proximal, distal; fingers: proximal, middle, distal phalanx (joint to joint,
# distal = DIP to fingertip).
SEGMENT_RATIOS = {
    "thumb": (0.251, 0.196, 0.158),
    "index": (0.245, 0.143, 0.097),
    "middle": (0.266, 0.170, 0.108),
    "ring": (0.244, 0.165, 0.107),
    "pinky": (0.204, 0.117, 0.093),
}

# Knuckle positions in the palm frame (x radial, y palmar, z proximal), metres. Axial positions are
# placed so that the extended fingertips end 0 / 10.7 / 10.8 / 36.4 mm proximal to the middle
# fingertip for middle / index / ring / pinky (finger length differences of Chatzioglou, Pinar &
# Govsa 2024, Anat Cell Biol 57(2)); radio-ulnar spacing ~19 mm between MCP centres (hand breadth
# ~85 mm). The thumb CMC is radial, palmar and just distal to the wrist crease.
FINGER_TIP_SHORTFALL = {"index": 0.0107, "middle": 0.0, "ring": 0.0108, "pinky": 0.0108 + 0.0256}
KNUCKLE_XY = {"index": (0.022, 0.0), "middle": (0.0, 0.0), "ring": (-0.019, 0.0), "pinky": (-0.036, 0.002)}
FINGER_SPLAY_DEG = {"index": 4.0, "middle": 0.0, "ring": -4.0, "pinky": -9.0}  # + = radial

THUMB_CMC = (0.025, 0.012, -0.022)
# Thumb base orientation: the metacarpal points distally and radially (THUMB_RADIAL_DEG from the
# palm's long axis, in the palm plane), is lifted palmar by THUMB_PALMAR_DEG, and its flexion plane
# is pronated by THUMB_PRONATION_DEG about the metacarpal so that flexion sweeps the thumb across the
# palm towards the fingers (opposition).
THUMB_RADIAL_DEG = 25.0
THUMB_PALMAR_DEG = 20.0
THUMB_PRONATION_DEG = 60.0

# Joint limits, degrees: (abduction, MCP flexion, PIP flexion, DIP flexion); thumb: (CMC abduction,
# CMC flexion, MCP flexion, IP flexion). Active ranges of motion, see urdf/hand/README.md.
JOINT_LIMITS_DEG = {
    "thumb": ((-20.0, 45.0), (-20.0, 50.0), (-10.0, 60.0), (-15.0, 80.0)),
    "index": ((-20.0, 20.0), (-20.0, 90.0), (0.0, 110.0), (-10.0, 80.0)),
    "middle": ((-15.0, 15.0), (-20.0, 90.0), (0.0, 110.0), (-10.0, 80.0)),
    "ring": ((-15.0, 15.0), (-20.0, 90.0), (0.0, 110.0), (-10.0, 80.0)),
    "pinky": ((-20.0, 20.0), (-20.0, 90.0), (0.0, 110.0), (-10.0, 80.0)),
}
JOINT_SUFFIXES = ("abd", "mcp", "pip", "dip")
THUMB_JOINT_SUFFIXES = ("cmc_abd", "cmc_flex", "mcp", "ip")

FINGER_RADIUS = {"thumb": 0.0095, "index": 0.0085, "middle": 0.0085, "ring": 0.008, "pinky": 0.007}
PALM_BOX = {"x": (-0.044, 0.032), "y": (-0.014, 0.014), "z": (-0.080, 0.0)}

# --------------------------------------------------------------------------------------------
# Arm dimensions (segment lengths as fractions of body height, Winter 2009, "Biomechanics and Motor
# Control of Human Movement", table 4.1; body height 1.75 m). Right arm, world frame x forward,
# y left, z up, origin at the gleno-humeral joint centre; at zero the arm hangs down with the palm
# facing the thigh (palm frame = world axes).
# --------------------------------------------------------------------------------------------
BODY_HEIGHT = 1.75
UPPER_ARM = 0.186 * BODY_HEIGHT  # shoulder to elbow joint centre
FOREARM = 0.146 * BODY_HEIGHT  # elbow to wrist joint centre
ARM_JOINTS = (  # name, axis in the (zero-posture) world frame, limits in degrees
    ("shoulder_flexion", (0, -1, 0), (-60.0, 180.0)),
    ("shoulder_abduction", (-1, 0, 0), (-30.0, 180.0)),
    ("shoulder_rotation", (0, 0, 1), (-90.0, 90.0)),
    ("elbow_flexion", (0, -1, 0), (0.0, 145.0)),
    ("wrist_pronation", (0, 0, 1), (-90.0, 90.0)),
    ("wrist_flexion", (1, 0, 0), (-70.0, 80.0)),
    ("wrist_deviation", (0, -1, 0), (-30.0, 20.0)),
)

# --------------------------------------------------------------------------------------------
# MANUS on a mobile base (approximate published geometry of the MANUS ARM, Exact Dynamics:
# 6 DOF + gripper, reach ~0.8 m; see urdf/manus/README.md).
# --------------------------------------------------------------------------------------------
MANUS = {
    "platform_size": (0.60, 0.45, 0.30),  # x, y, z box, on the floor
    "arm_mount": (0.20, -0.20, 0.65),  # shoulder yaw axis foot on the platform frame
    "shoulder_height": 0.10,  # yaw axis to shoulder pitch axis
    "upper_arm": 0.43,
    "forearm": 0.40,
    "wrist_to_flange": 0.06,
    "flange_to_jaw_tip": 0.12,
    "jaw_opening": 0.07,  # distance between the two marked points
    "base_limits": ((-0.5, 0.5), (-0.5, 0.5), (-45.0, 45.0)),  # x, y (m), yaw (deg)
    "arm_limits_deg": ((-180.0, 180.0), (-90.0, 90.0), (-150.0, 150.0), (-180.0, 180.0),
                       (-110.0, 110.0), (-180.0, 180.0)),
}


# --------------------------------------------------------------------------------------------
# A minimal URDF writer
# --------------------------------------------------------------------------------------------
def _fmt(v: float) -> str:
    s = f"{v:.9f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _vec(v) -> str:
    return " ".join(_fmt(float(x)) for x in v)


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """URDF rpy (fixed axes x, y, z: R = Rz(y) Ry(p) Rx(r)) of a rotation matrix."""
    sy = -R[2, 0]
    pitch = math.asin(max(-1.0, min(1.0, sy)))
    if abs(abs(sy) - 1.0) < 1e-12:  # gimbal lock: put everything in yaw
        roll = 0.0
        yaw = math.atan2(-R[0, 1], R[1, 1])
    else:
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    return roll, pitch, yaw


def _rot_axis(axis, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


@dataclass
class Geom:
    kind: str  # box | cylinder | sphere
    size: tuple  # box (x, y, z); cylinder (radius, length); sphere (radius,)
    xyz: tuple = (0.0, 0.0, 0.0)
    rpy: tuple = (0.0, 0.0, 0.0)
    color: str = "skin"
    collision: bool = True  # False: drawn only (a marker such as the MANUS gripper points)

    def xml(self, tag: str) -> str:
        if self.kind == "box":
            g = f'<box size="{_vec(self.size)}"/>'
        elif self.kind == "cylinder":
            g = f'<cylinder radius="{_fmt(self.size[0])}" length="{_fmt(self.size[1])}"/>'
        else:
            g = f'<sphere radius="{_fmt(self.size[0])}"/>'
        mat = f'<material name="{self.color}"/>' if tag == "visual" else ""
        return (f'    <{tag}><origin xyz="{_vec(self.xyz)}" rpy="{_vec(self.rpy)}"/>'
                f"<geometry>{g}</geometry>{mat}</{tag}>")


@dataclass
class Link:
    name: str
    geoms: list[Geom] = field(default_factory=list)

    def xml(self) -> str:
        if not self.geoms:
            return f'  <link name="{self.name}"/>'
        body = "\n".join(g.xml("visual") + ("\n" + g.xml("collision") if g.collision else "") for g in self.geoms)
        return f'  <link name="{self.name}">\n{body}\n  </link>'


@dataclass
class Joint:
    name: str
    kind: str  # fixed | revolute | prismatic
    parent: str
    child: str
    xyz: tuple = (0.0, 0.0, 0.0)
    rpy: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)
    limits: tuple | None = None  # (lower, upper) in URDF units (rad or m)

    def xml(self) -> str:
        s = (f'  <joint name="{self.name}" type="{self.kind}">\n'
             f'    <parent link="{self.parent}"/>\n    <child link="{self.child}"/>\n'
             f'    <origin xyz="{_vec(self.xyz)}" rpy="{_vec(self.rpy)}"/>\n')
        if self.kind != "fixed":
            lo, hi = self.limits
            s += (f'    <axis xyz="{_vec(self.axis)}"/>\n'
                  f'    <limit lower="{_fmt(lo)}" upper="{_fmt(hi)}" effort="10" velocity="2"/>\n')
        return s + "  </joint>"


MATERIALS = {"skin": "0.93 0.75 0.62 1", "bone": "0.85 0.82 0.75 1", "metal": "0.6 0.62 0.66 1",
             "dark": "0.25 0.27 0.3 1", "blue": "0.3 0.45 0.75 1", "red": "0.85 0.2 0.2 1"}


def to_urdf(name: str, links: list[Link], joints: list[Joint], comment: str) -> str:
    used = sorted({g.color for link in links for g in link.geoms})
    mats = "\n".join(f'  <material name="{m}"><color rgba="{MATERIALS[m]}"/></material>' for m in used)
    body = "\n".join([link.xml() for link in links] + [j.xml() for j in joints])
    return (f'<?xml version="1.0"?>\n<!-- {comment}\n     Generated by urdf/build.py: edit that file, '
            f'not this one. -->\n<robot name="{name}">\n{mats}\n{body}\n</robot>\n')


def _capsule_x(length: float, radius: float, color: str = "skin") -> list[Geom]:
    """A segment along +x from the joint: a cylinder plus a sphere at its distal end."""
    return [Geom("cylinder", (radius, length), (length / 2, 0, 0), (0, math.pi / 2, 0), color),
            Geom("sphere", (radius,), (length, 0, 0), (0, 0, 0), color)]


# --------------------------------------------------------------------------------------------
# Models
# --------------------------------------------------------------------------------------------
def finger_lengths(finger: str) -> tuple[float, float, float]:
    return tuple(HAND_LENGTH * r for r in SEGMENT_RATIOS[finger])


def finger_base_pose(finger: str) -> tuple[tuple, tuple]:
    """(xyz, rpy) of a finger's base frame in the palm frame."""
    if finger == "thumb":
        rad, pal, pro = (math.radians(a) for a in (THUMB_RADIAL_DEG, THUMB_PALMAR_DEG, THUMB_PRONATION_DEG))
        x = np.array([math.sin(rad) * math.cos(pal), math.sin(pal), -math.cos(rad) * math.cos(pal)])
        y0 = np.array([0.0, 1.0, 0.0]) - x[1] * x  # palmar, orthogonal to x
        y0 /= np.linalg.norm(y0)
        y = _rot_axis(x, -pro) @ y0  # pronate: turn the flexion direction towards the ulnar side
        z = np.cross(x, y)
        R = np.stack([x, y, z], axis=1)
        return THUMB_CMC, rpy_from_matrix(R)
    length = sum(finger_lengths(finger))
    z = -(HAND_LENGTH - FINGER_TIP_SHORTFALL[finger] - length)
    x, y = KNUCKLE_XY[finger]
    phi = math.radians(FINGER_SPLAY_DEG[finger])
    return (x, y, z), (0.0, math.pi / 2 - phi, 0.0)


def hand_model(parent: str | None = None, mount_xyz=(0, 0, 0), mount_rpy=(0, 0, 0)):
    """Links and joints of the right hand; palm link 'palm'. If ``parent`` is given, the palm is
    attached to it by a fixed joint (used by arm_hand)."""
    bx, by, bz = PALM_BOX["x"], PALM_BOX["y"], PALM_BOX["z"]
    palm = Link("palm", [Geom("box", (bx[1] - bx[0], by[1] - by[0], bz[1] - bz[0]),
                              ((bx[0] + bx[1]) / 2, (by[0] + by[1]) / 2, (bz[0] + bz[1]) / 2))])
    links, joints = [palm], []
    if parent is not None:
        joints.append(Joint("palm_mount", "fixed", parent, "palm", mount_xyz, mount_rpy))
    for finger in ("thumb", "index", "middle", "ring", "pinky"):
        xyz, rpy = finger_base_pose(finger)
        base = f"{finger}_base"
        links.append(Link(base))
        joints.append(Joint(f"{base}_fixed", "fixed", "palm", base, xyz, rpy))
        l1, l2, l3 = finger_lengths(finger)
        r = FINGER_RADIUS[finger]
        suffixes = THUMB_JOINT_SUFFIXES if finger == "thumb" else JOINT_SUFFIXES
        seg_names = ([f"{finger}_{s}" for s in ("cmc", "metacarpal", "proximal", "distal")] if finger == "thumb"
                     else [f"{finger}_{s}" for s in ("knuckle", "proximal", "middle", "distal")])
        seg_geoms = [[Geom("sphere", (r * 1.05,))], _capsule_x(l1, r), _capsule_x(l2, r * 0.92),
                     _capsule_x(l3, r * 0.85)]
        offsets = [(0, 0, 0), (0, 0, 0), (l1, 0, 0), (l2, 0, 0)]
        axes = [(0, -1, 0), (0, 0, 1), (0, 0, 1), (0, 0, 1)]
        prev = base
        for k in range(4):
            links.append(Link(seg_names[k], seg_geoms[k]))
            lo, hi = (math.radians(a) for a in JOINT_LIMITS_DEG[finger][k])
            joints.append(Joint(f"{finger}_{suffixes[k]}", "revolute", prev, seg_names[k],
                                offsets[k], (0, 0, 0), axes[k], (lo, hi)))
            prev = seg_names[k]
        tip = f"{finger}_tip"
        links.append(Link(tip))
        joints.append(Joint(f"{tip}_fixed", "fixed", prev, tip, (l3, 0, 0)))
    return links, joints


def build_hand() -> str:
    links, joints = hand_model()
    return to_urdf("hand", links, joints, "Right human-sized hand: palm + 5 fingers x 4 DOF.")


def build_arm_hand() -> str:
    r_upper, r_fore = 0.045, 0.035
    links = [Link("torso", [Geom("box", (0.22, 0.36, 0.55), (-0.02, 0.24, -0.20), color="blue")])]
    joints = []
    names = [j[0] for j in ARM_JOINTS]
    # chain: torso -> 3 shoulder links -> elbow link -> 3 wrist links -> palm
    geoms = {
        "shoulder_abduction": [Geom("sphere", (0.05,), color="skin")],
        "shoulder_rotation": [Geom("cylinder", (r_upper, UPPER_ARM - 0.05), (0, 0, -UPPER_ARM / 2))],
        "elbow_flexion": [Geom("sphere", (0.04,)),
                          Geom("cylinder", (r_fore, FOREARM - 0.04), (0, 0, -FOREARM / 2))],
    }
    offsets = {"shoulder_flexion": (0, 0, 0), "shoulder_abduction": (0, 0, 0), "shoulder_rotation": (0, 0, 0),
               "elbow_flexion": (0, 0, -UPPER_ARM), "wrist_pronation": (0, 0, -FOREARM),
               "wrist_flexion": (0, 0, 0), "wrist_deviation": (0, 0, 0)}
    prev = "torso"
    for name, axis, (lo, hi) in ARM_JOINTS:
        link = f"{name}_link"
        links.append(Link(link, geoms.get(name, [])))
        joints.append(Joint(name, "revolute", prev, link, offsets[name], (0, 0, 0), axis,
                            (math.radians(lo), math.radians(hi))))
        prev = link
    assert len(names) == 7
    hand_links, hand_joints = hand_model(parent=prev)
    return to_urdf("arm_hand", links + hand_links, joints + hand_joints,
                   "Right human arm (shoulder 3, elbow 1, wrist 3 DOF) carrying the hand of urdf/hand.")


def build_manus() -> str:
    m = MANUS
    px, py, pz = m["platform_size"]
    links = [Link("world"), Link("base_x"), Link("base_y"),
             Link("platform", [Geom("box", (px, py, pz), (0, 0, pz / 2), color="dark")])]
    (xlo, xhi), (ylo, yhi), (yawlo, yawhi) = m["base_limits"]
    joints = [Joint("base_x", "prismatic", "world", "base_x", axis=(1, 0, 0), limits=(xlo, xhi)),
              Joint("base_y", "prismatic", "base_x", "base_y", axis=(0, 1, 0), limits=(ylo, yhi)),
              Joint("base_yaw", "revolute", "base_y", "platform", axis=(0, 0, 1),
                    limits=(math.radians(yawlo), math.radians(yawhi)))]
    mx, my, mz = m["arm_mount"]
    links.append(Link("arm_mount", [Geom("cylinder", (0.05, mz - pz), (0, 0, -(mz - pz) / 2), color="metal")]))
    joints.append(Joint("arm_mount_fixed", "fixed", "platform", "arm_mount", (mx, my, mz)))
    ua, fa, wf = m["upper_arm"], m["forearm"], m["wrist_to_flange"]
    # zero posture: upper arm and forearm horizontal along +x, gripper pointing +x
    spec = [  # joint, parent offset, axis, link geometry
        ("shoulder_yaw", (0, 0, 0), (0, 0, 1),
         [Geom("cylinder", (0.06, m["shoulder_height"]), (0, 0, m["shoulder_height"] / 2), color="metal")]),
        ("shoulder_pitch", (0, 0, m["shoulder_height"]), (0, -1, 0),
         [Geom("cylinder", (0.045, ua), (ua / 2, 0, 0), (0, math.pi / 2, 0), color="metal")]),
        ("elbow_pitch", (ua, 0, 0), (0, -1, 0),
         [Geom("cylinder", (0.04, fa), (fa / 2, 0, 0), (0, math.pi / 2, 0), color="metal")]),
        ("wrist_yaw", (fa, 0, 0), (0, 0, 1), [Geom("sphere", (0.045,), color="dark")]),
        ("wrist_pitch", (0, 0, 0), (0, -1, 0), []),
        ("wrist_roll", (0, 0, 0), (1, 0, 0),
         [Geom("cylinder", (0.035, wf), (wf / 2, 0, 0), (0, math.pi / 2, 0), color="dark")]),
    ]
    prev = "arm_mount"
    for (name, xyz, axis, geoms), (lo, hi) in zip(spec, m["arm_limits_deg"], strict=True):
        link = f"{name}_link"
        links.append(Link(link, geoms))
        joints.append(Joint(name, "revolute", prev, link, xyz, (0, 0, 0), axis,
                            (math.radians(lo), math.radians(hi))))
        prev = link
    jl, w = m["flange_to_jaw_tip"], m["jaw_opening"]
    links.append(Link("gripper", [Geom("box", (0.04, w + 0.03, 0.05), (0.02, 0, 0), color="dark")]))
    joints.append(Joint("gripper_fixed", "fixed", prev, "gripper", (wf, 0, 0)))
    for k, side in ((1, 1.0), (2, -1.0)):
        jaw = f"jaw_{k}"
        links.append(Link(jaw, [Geom("box", (jl - 0.04, 0.012, 0.03), ((jl - 0.04) / 2, 0, 0), color="metal")]))
        joints.append(Joint(f"{jaw}_fixed", "fixed", "gripper", jaw, (0.04, side * (w / 2 + 0.006), 0)))
        pt = f"gripper_point_{k}"
        # a marker, not a body: the jaw carries the collision geometry (and may touch the object)
        links.append(Link(pt, [Geom("sphere", (0.006,), color="red", collision=False)]))
        joints.append(Joint(f"{pt}_fixed", "fixed", jaw, pt, (jl - 0.04 - 0.015, -side * 0.006, 0)))
    return to_urdf("manus", links, joints,
                   "MANUS-like assistive arm (6 DOF + two-jaw gripper) on a 3-DOF mobile base (x, y, yaw).")


BUILDERS = {"hand/hand.urdf": build_hand, "arm_hand/arm_hand.urdf": build_arm_hand,
            "manus/manus.urdf": build_manus}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only compare with the committed files")
    args = ap.parse_args(argv)
    stale = []
    for rel, build in BUILDERS.items():
        path = ROOT / rel
        text = build()
        if args.check:
            if not path.exists() or path.read_text() != text:
                stale.append(rel)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(".urdf.tmp")
            tmp.write_text(text)
            tmp.replace(path)
            print(f"wrote urdf/{rel}")
    if stale:
        print("out of date (run `python urdf/build.py`): " + ", ".join(stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
