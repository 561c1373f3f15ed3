"""Batched frames of every joint level of a robot's serial chains, for the hot loops.

A chain's level-k frame is the pose of its k-th joint's child frame in the chain's root:

    P_k = F_0 M_0(q_0) F_1 M_1(q_1) ... F_{k-1} M_{k-1}(q_{k-1})    (chain.py's offsets F_i)
    M(q) = I + s(q) A + c(q) B:  revolute s = sin q, c = 1 - cos q, A = [a]x, B = [a]x^2 (Rodrigues);
                                 prismatic s = q, c = 0, A = the axis as a translation,

so that F_k M_k(q_k) = F_k + s(q_k) (F_k A_k) + c(q_k) (F_k B_k) costs two fused multiply-adds on
precomputed products (:class:`ChainLevels`). :class:`RobotLevels` holds the body chain's (its end
gives the palm) and every finger chain's (from the finger's base on the palm), and
:func:`link_attachments` says which level each link hangs from, and where: the collision proxy
places its spheres from these frames, the gripper environment its points and Jacobian.
:class:`~graspnet_torch.robot.kernel.ChainKernel` stays the fingertips' kernel; these are for
every level at once.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.kernel import motion_terms
from graspnet_torch.robot.robot import Posture, Robot

__all__ = ["Attachment", "ChainLevels", "RobotLevels", "frames_at_zero", "link_attachments", "motion_terms",
           "riding_base_links"]


class ChainLevels:
    """Torch constants of one (batch of) serial chain(s). With M(q) = I + s(q) A + c(q) B,

        F_k M_k(q_k) = F_k + s(q_k) (F_k A_k) + c(q_k) (F_k B_k),

    so each joint's transform costs two fused multiply-adds on precomputed products, no matmul."""

    def __init__(self, A: np.ndarray, B: np.ndarray, revolute: np.ndarray, offsets: np.ndarray, kw: dict):
        F = offsets[..., :-1, :, :]
        self.F = torch.as_tensor(F, **kw)  # (..., n, 4, 4)
        self.FA = torch.as_tensor(F @ A, **kw)
        self.FB = torch.as_tensor(F @ B, **kw)
        self.all_revolute = bool(np.all(revolute))
        self.revolute = torch.as_tensor(revolute, device=kw["device"])

    def levels(self, q: Tensor, upto: int) -> list[Tensor]:
        """q (T, ..., n) -> [P_1, ..., P_upto], each (T, ..., 4, 4) (P_0 = identity is left out)."""
        if upto == 0:
            return []
        if self.all_revolute:
            s, c = torch.sin(q), 1 - torch.cos(q)
        else:
            s = torch.where(self.revolute, torch.sin(q), q)
            c = torch.where(self.revolute, 1 - torch.cos(q), torch.zeros_like(q))
        FM = torch.addcmul(torch.addcmul(self.F, s[..., None, None], self.FA), c[..., None, None], self.FB)
        lead = FM.shape[:-3]
        flat = FM.reshape(-1, *FM.shape[-3:])  # (B, n, 4, 4): products as bmm, the cheapest small matmul
        P = [flat[:, 0]]
        for k in range(1, upto):
            P.append(torch.bmm(P[-1], flat[:, k]))
        return [p.view(*lead, 4, 4) for p in P]


def _finger_chains(robot: Robot) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple | None]:
    """Every finger's whole chain (mimic joints included) padded to the longest, m joints: A, B
    (F, m, 4, 4), revolute (F, m), offsets (F, m + 1, 4, 4), and the map from the free joints
    (F, n) to them, ``q_all = C q + c`` as (C (F, m, n), c (F, m)), or None when they are the same.
    A padding joint has no motion (A = B = 0) and an identity offset."""
    fingers = list(robot.fingers.values())
    m, n = max(f.chain.spec.n_joints for f in fingers), robot.joints_per_finger
    A, B = np.zeros((len(fingers), m, 4, 4)), np.zeros((len(fingers), m, 4, 4))
    rev = np.ones((len(fingers), m), dtype=bool)
    offsets = np.broadcast_to(np.eye(4), (len(fingers), m + 1, 4, 4)).copy()
    C, c = np.zeros((len(fingers), m, n)), np.zeros((len(fingers), m))
    for k, f in enumerate(fingers):
        spec, j = f.chain.spec, f.chain.spec.n_joints
        A[k, :j], B[k, :j], rev[k, :j] = motion_terms(spec.axes, spec.joint_types)
        offsets[k, :j] = spec.offsets[:j]
        offsets[k, m] = spec.offsets[j]
        C[k, :j, : f.n_joints], c[k, :j] = f.chain.coupling, f.chain.coupling_offset
    plain = m == n and all(f.chain.identity for f in fingers)
    return A, B, rev, offsets, None if plain else (C, c)


class RobotLevels:
    """The level frames of a robot's body chain and finger chains, batched, in torch.

    Attributes:
        body: the body chain's :class:`ChainLevels` (robots with an arm), else None.
        palm_offset: (4, 4) the body chain's last offset F_m (its last level -> the palm), else None.
        fingers: every finger's whole chain, padded to the longest (robots with fingers), else None.
        n_fingers: F, the robot's fingers.
    """

    def __init__(self, robot: Robot, dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu"):
        kw = {"dtype": dtype, "device": device}
        self.n_body = len(robot.body_joint_names)
        self.body: ChainLevels | None = None
        self.palm_offset: Tensor | None = None
        if robot.body is not None:
            A, B, rev = motion_terms(robot.body.axes, robot.body.joint_types)
            self.body = ChainLevels(A, B, rev, robot.body.offsets, kw)
            self.palm_offset = torch.as_tensor(robot.body.offsets[-1], **kw)  # (4, 4) F_m: the last level -> palm
        self.fingers: ChainLevels | None = None
        self.n_fingers = robot.n_fingers
        self._finger_map: tuple[Tensor, Tensor] | None = None
        if robot.n_fingers:
            A, B, rev, offsets, coupling = _finger_chains(robot)
            self.fingers = ChainLevels(A, B, rev, offsets, kw)
            if coupling is not None:
                self._finger_map = (torch.as_tensor(coupling[0], **kw), torch.as_tensor(coupling[1], **kw))
            base = np.stack([f.base_in_palm for f in robot.fingers.values()])  # (F, 4, 4)
            self._base_cols = torch.as_tensor(base.transpose(1, 0, 2).reshape(4, -1), **kw)  # (4, 4F): W4 @ it
            self._bottom = torch.tensor([0.0, 0.0, 0.0, 1.0], **kw)

    def body_levels(self, body: Tensor, upto: int) -> list[Tensor]:
        """body: (T, m) body joints -> the body chain's frames [P_1, ..., P_upto], each (T, 4, 4)."""
        return self.body.levels(body, upto)

    def body_levels_and_palm(self, body: Tensor) -> tuple[list[Tensor], tuple[Tensor, Tensor]]:
        """The body chain's frames P_1..P_m (T, 4, 4) and the palm frame R (T, 3, 3), t (T, 3) that
        its end gives (P_m F_m): the arm's forward kinematics as m small batched products, cheaper
        than the general kernel for a few trials."""
        levels = self.body.levels(body, self.n_body)
        end = torch.matmul(levels[-1], self.palm_offset) if levels else self.palm_offset.expand(body.shape[0], 4, 4)
        return levels, (end[:, :3, :3], end[:, :3, 3])

    def finger_levels(self, palm: Tensor, fingers: Tensor, upto: int, bases: tuple[Tensor, Tensor] | None = None
                      ) -> list[Tensor]:
        """palm: W (T, 3, 4) the palm in the world; fingers: (T, F, n) every finger's free joints;
        bases: every finger's base in the palm, R (T, F, 3, 3), t (T, F, 3), where the joints the
        fingers share move them (None: the fixed ones) -> [every finger's base in the world, its
        level 1, ..., level ``upto``], each (T, F, 3, 4)."""
        T = palm.shape[0]
        if self._finger_map is not None:  # free joints (padded) -> every joint (mimic, padded)
            fingers = torch.einsum("fan,tfn->tfa", self._finger_map[0], fingers) + self._finger_map[1]
        if bases is None:  # base_f = W B_f for every finger at once: (T, 3, 4) @ (4, 4F)
            base = (palm @ self._base_cols).view(T, 3, self.n_fingers, 4).transpose(1, 2)  # (T, F, 3, 4)
        else:
            R, t = bases
            Wr = palm[:, None, :, :3]
            base = torch.cat([Wr @ R, (Wr @ t.unsqueeze(-1)) + palm[:, None, :, 3:]], -1)  # (T, F, 3, 4)
        levels = [base]
        if upto:
            base4 = torch.cat([base, self._bottom.expand(T, self.n_fingers, 1, 4)], -2).reshape(-1, 4, 4)
            for P in self.fingers.levels(fingers, upto):
                levels.append(torch.bmm(base4, P.reshape(-1, 4, 4))[:, :3].view(T, self.n_fingers, 3, 4))
        return levels


@dataclass(frozen=True, eq=False)
class Attachment:
    """The level frame a link hangs from, and its pose in it.

    Attributes:
        kind: 'body' (level ``level`` of the body chain; 0: the world), 'palm', or 'finger' (level
            ``level`` of finger ``finger``'s chain, 0: its base).
        level: the chain level (0 for the palm).
        finger: the finger's index (0 unless ``kind`` is 'finger').
        pose: (4, 4) the link's pose in that frame, float64 (the same at every configuration).
    """

    kind: str
    level: int
    finger: int = 0
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))


def frames_at_zero(robot: Robot) -> dict[str, np.ndarray]:
    """(4, 4) float64 world pose of every link with every joint at zero (a free hand's palm at the origin)."""
    zero = Posture(palm_pose=torch.zeros(6, dtype=torch.float64),
                   fingers=torch.zeros(robot.n_fingers, robot.joints_per_finger, dtype=torch.float64),
                   body=torch.zeros(len(robot.body_joint_names), dtype=torch.float64))
    return robot.link_frames(zero)


def link_attachments(robot: Robot, links: Iterable[str]) -> dict[str, Attachment]:
    """Which level frame each link hangs from, and its pose there (at any configuration). Raises
    ConfigError for a link that moves with the palm on no finger chain, or moves on neither the
    body chain nor a finger chain."""
    frames = frames_at_zero(robot)
    return {link: _attachment(robot, link, frames) for link in dict.fromkeys(links)}


def _attachment(robot: Robot, link: str, frames: dict[str, np.ndarray]) -> Attachment:
    urdf = robot.urdf
    path = [link]  # link and its ancestors, up to the root
    while path[-1] in urdf.parent_joint:
        path.append(urdf.parent_joint[path[-1]].parent)

    def movable(upto: str) -> int:
        return sum(urdf.parent_joint[child].type != "fixed" for child in path[:path.index(upto)])

    palm = robot.cfg.palm_link
    for x in path:  # the nearest link up the tree that lies on a finger's chain (below its root)
        owner = next((f for f, finger in enumerate(robot.fingers.values()) if x in _chain_links(robot, finger)), None)
        if owner is None:
            continue
        if movable(x):  # moved by joints on no finger's own chain (the ones fingers share): see below
            break
        finger = list(robot.fingers.values())[owner]
        k = movable(finger.chain.root)
        spec = finger.chain.spec
        A, B, rev = motion_terms(spec.axes, spec.joint_types)
        q = finger.chain.coupling_offset  # every joint where ``frames`` has it: the free ones at 0, mimic ones at c
        P = np.eye(4)
        for i in range(k):  # level k: F_0 M_1(q_1) ... F_{k-1} M_k(q_k)
            s, c = (np.sin(q[i]), 1 - np.cos(q[i])) if rev[i] else (q[i], 0.0)
            P = P @ spec.offsets[i] @ (np.eye(4) + s * A[i] + c * B[i])
        frame = frames[palm] @ finger.base_in_palm @ P
        return Attachment("finger", k, owner, np.linalg.inv(frame) @ frames[link])
    if palm in path:
        moved = {urdf.parent_joint[c].name for c in path[:path.index(palm)] if urdf.parent_joint[c].type != "fixed"}
        if moved - set(robot.shared.names) - set(robot.shared.followers):
            raise ConfigError(f"{robot.cfg.source}: link '{link}' moves with the palm but is on no finger chain")
        # moved by joints the fingers share only: placed where the robot holds them
        return Attachment("palm", 0, 0, np.linalg.inv(frames[palm]) @ frames[link])
    if robot.body is None:  # above the palm of a free hand: rigid with it
        return Attachment("palm", 0, 0, np.linalg.inv(frames[palm]) @ frames[link])
    joints = tuple(urdf.parent_joint[c].name for c in reversed(path[:-1]) if urdf.parent_joint[c].type != "fixed")
    k = len(joints)
    if robot.body.joint_names[:k] != joints:
        raise ConfigError(f"{robot.cfg.source}: link '{link}' moves but is on neither the arm nor a finger")
    P = np.eye(4)
    for i in range(k):
        P = P @ robot.body.offsets[i]
    return Attachment("body", k, 0, np.linalg.inv(P) @ frames[link])


def _chain_links(robot: Robot, finger) -> set[str]:
    """The links on a finger's chain from its root (its base) down to its tip (the palm excluded:
    several fingers may start there)."""
    cached = robot.__dict__.setdefault("_finger_chain_links", {})
    if finger.name not in cached:
        links, link = set(), finger.chain.tip
        while link != finger.chain.root and link in robot.urdf.parent_joint:
            links.add(link)
            link = robot.urdf.parent_joint[link].parent
        if finger.chain.root != robot.cfg.palm_link:
            links.add(finger.chain.root)
        cached[finger.name] = links
    return cached[finger.name]


def riding_base_links(robot: Robot, attachments: dict[str, Attachment]) -> set[str]:
    """Links that only the mobile base's joints move, when those joints keep them at their
    height and upright (a planar base: x, y, yaw; checked at random base configurations): they
    stand on the floor. Empty for a robot without a mobile base or whose base tilts or lifts."""
    if robot.cfg.mobile_base is None or robot.body is None:
        return set()
    m = len(robot.urdf.chain_spec(robot.cfg.mobile_base.base, robot.cfg.mobile_base.tip, "mobile_base").joint_names)
    tip = robot.cfg.mobile_base.tip
    lo, hi = robot.body_limits
    rng = np.random.default_rng(0)
    rows = []
    for _ in range(4):
        q = np.zeros(len(lo))
        q[:m] = rng.uniform(lo[:m], hi[:m])
        posture = Posture(palm_pose=torch.zeros(6, dtype=torch.float64),
                          fingers=torch.zeros(robot.n_fingers, robot.joints_per_finger, dtype=torch.float64),
                          body=torch.as_tensor(q))
        rows.append(robot.link_frames(posture)[tip][2])  # the tip frame's z row: height and tilt
    if not np.allclose(rows, rows[0], atol=1e-9):
        return set()
    return {link for link, a in attachments.items() if a.kind == "body" and a.level <= m}
