"""Joints that move more than one finger, found from the URDF: the configuration's business, not
any one finger's.

Real hands couple fingers: the Schunk SVH's ring and little fingers hang from one joint (``j5``,
which mimics the thumb's opposition), and one actuator (``Finger_Spread``) spreads three
fingers through mimic joints. In the paper's architecture such a joint belongs with the palm
pose (HCNN) or the arm's joints (ACNN): the configuration network chooses it, and each finger's
FCNN solves its own free joints from a base frame the shared joints have moved.

A free joint L (not a mimic joint) is **shared** when the joints it drives, itself and its mimic
followers (transitively), lie on the chains (palm to fingertip) of two or more fingers, or on the
chain of a finger whose chain does not hold L itself. Each finger's **base** is the child link of
the last joint on its chain that a shared joint drives; its own chain, base to tip, holds only
its own joints (free joints and their mimic followers), which the FCNN learns as for any finger.
A finger whose own joint comes before a joint a shared joint drives is refused: its base would
move with its own joints.

Every finger's base frame in the palm is a function of the shared joints s (S,):

    T_palm_base_k(s) = F_0 M_1(q_1) F_1 ... M_m(q_m) F_m,   q_i = a_i s_{l(i)} + b_i

(the chain palm -> base_k, each of its movable joints a shared joint or a follower of one, with
multiplier a_i and offset b_i).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.chain import ChainSpec, UrdfModel

__all__ = ["SharedJoints", "find_shared_joints"]


@dataclass(frozen=True)
class SharedJoints:
    """The shared joints of a hand and the base each finger's own chain starts from.

    Attributes:
        names: (S,) the shared joints (free URDF joints), in URDF order: search variables of the
            configuration.
        lower, upper: (S,) their limits (rad or m), narrowed so that every follower stays
            within its own.
        followers: mimic joint -> (shared joint, multiplier, offset), every joint a shared joint
            drives other than itself (mimics of mimics resolved).
        bases: finger -> the link its own chain starts from.
        paths: finger -> the chain from the palm to its base (its movable joints: shared joints
            and their followers), for each finger the shared joints move.
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    followers: dict[str, tuple[str, float, float]]
    bases: dict[str, str]
    paths: dict[str, ChainSpec] = field(repr=False)

    @property
    def n(self) -> int:
        return len(self.names)

    def joint_values(self, s: np.ndarray) -> dict[str, float]:
        """Every joint the shared joints drive, at s (S,): name -> value (rad or m)."""
        s = np.asarray(s, dtype=np.float64)
        out = {name: float(s[k]) for k, name in enumerate(self.names)}
        for joint, (leader, m, b) in self.followers.items():
            out[joint] = m * out[leader] + b
        return out

    def base_frames(self, s: Tensor) -> dict[str, Tensor]:
        """The base in the palm frame of each finger the shared joints move: s (..., S) ->
        finger -> (..., 4, 4) (the equation in the module docstring)."""
        index = {name: k for k, name in enumerate(self.names)}
        frames = {}
        for finger, spec in self.paths.items():
            T = torch.as_tensor(spec.offsets[0], dtype=s.dtype, device=s.device).expand(*s.shape[:-1], 4, 4)
            for i, (joint, kind) in enumerate(zip(spec.joint_names, spec.joint_types, strict=True)):
                leader, m, b = self.followers.get(joint, (joint, 1.0, 0.0))
                q = m * s[..., index[leader]] + b
                offset = torch.as_tensor(spec.offsets[i + 1], dtype=s.dtype, device=s.device)
                T = T @ _joint_motion(kind, spec.axes[i], q) @ offset
            frames[finger] = T
        return frames


def _joint_motion(kind: str, axis: np.ndarray, q: Tensor) -> Tensor:
    """(..., 4, 4) the motion of a revolute (Rodrigues) or prismatic joint by q (...)."""
    a = torch.as_tensor(axis, dtype=q.dtype, device=q.device)
    M = torch.zeros(*q.shape, 4, 4, dtype=q.dtype, device=q.device)
    M[..., 3, 3] = 1.0
    if kind == "prismatic":
        M[..., :3, :3] = torch.eye(3, dtype=q.dtype, device=q.device)
        M[..., :3, 3] = a * q[..., None]
        return M
    K = torch.zeros(3, 3, dtype=q.dtype, device=q.device)
    K[0, 1], K[0, 2], K[1, 0], K[1, 2], K[2, 0], K[2, 1] = -a[2], a[1], a[2], -a[0], -a[1], a[0]
    sin, cos = torch.sin(q)[..., None, None], torch.cos(q)[..., None, None]
    M[..., :3, :3] = torch.eye(3, dtype=q.dtype, device=q.device) + sin * K + (1 - cos) * (K @ K)
    return M


def _root_leader(joint: str, mimic: dict[str, tuple[str, float, float]], where: str) -> tuple[str, float, float]:
    """The free joint a (possibly chained) mimic joint follows, with the composed multiplier and
    offset: q = m q_leader + b."""
    m, b, seen = 1.0, 0.0, [joint]
    while joint in mimic:
        leader, mj, bj = mimic[joint]
        m, b = m * mj, m * bj + b  # q = m q_joint + b and q_joint = mj q_leader + bj
        joint = leader
        if joint in seen:
            raise ConfigError(f"{where}: mimic joints {', '.join(seen)} form a cycle")
        seen.append(joint)
    return joint, m, b


def find_shared_joints(urdf: UrdfModel, palm: str, tips: dict[str, str], where: str = "robot") -> SharedJoints:
    """The shared joints of a hand whose fingers run from ``palm`` to ``tips`` (finger -> tip
    link), and each finger's base (module docstring). Raises :class:`ConfigError` for a finger
    whose own joint precedes a joint a shared joint drives, or a cycle of mimic joints."""
    mimic = urdf.mimic_joints
    chains = {f: [j.name for j in urdf.path_joints(palm, tip, f"{where}: finger '{f}'") if j.type != "fixed"]
              for f, tip in tips.items()}
    leaders: dict[str, tuple[str, float, float]] = {}  # every movable joint on a chain -> its free joint
    for joints in chains.values():
        for joint in joints:
            leaders[joint] = _root_leader(joint, mimic, where)
    reach: dict[str, set[str]] = {}  # free joint -> the fingers whose chains hold it or a follower
    for f, joints in chains.items():
        for joint in joints:
            reach.setdefault(leaders[joint][0], set()).add(f)
    shared = [name for name in urdf.movable_joint_names if name in reach and
              (len(reach[name]) > 1 or any(name not in chains[f] for f in reach[name]))]
    followers = {joint: lead for joint, lead in leaders.items() if lead[0] in shared and joint != lead[0]}
    bases, paths = {}, {}
    for f, joints in chains.items():
        driven = [i for i, joint in enumerate(joints) if leaders[joint][0] in shared]
        if not driven:
            bases[f] = palm
            continue
        last = driven[-1]
        own = [i for i in range(last) if i not in driven]
        if own:
            raise ConfigError(f"{where}: finger '{f}': its own joint '{joints[own[0]]}' comes before joint "
                              f"'{joints[last]}', which the shared joint '{leaders[joints[last]][0]}' drives; a "
                              f"finger's own joints must all follow the joints it shares with other fingers")
        bases[f] = urdf.joints[joints[last]].child
        paths[f] = urdf.chain_spec(palm, bases[f], f"{where}: finger '{f}' base")
    lower, upper = [], []
    for name in shared:
        limit = urdf.joints[name].limit
        lo, hi = (-np.pi, np.pi) if urdf.joints[name].type == "continuous" or limit is None else \
            (float(limit.lower), float(limit.upper))
        for joint, (leader, m, b) in followers.items():  # keep every follower within its own limits
            lim = urdf.joints[joint].limit
            if leader != name or lim is None or urdf.joints[joint].type == "continuous" or abs(m) < 1e-12:
                continue
            a, z = sorted(((float(lim.lower) - b) / m, (float(lim.upper) - b) / m))
            if max(lo, a) <= min(hi, z):
                lo, hi = max(lo, a), min(hi, z)
        lower.append(lo)
        upper.append(hi)
    return SharedJoints(tuple(shared), np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64),
                        followers, bases, paths)
