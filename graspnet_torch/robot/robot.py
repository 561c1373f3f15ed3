"""The robot: URDF + robot config -> chains, limits, frames and batched kinematics.

Frames. *World* is the URDF's root link frame (for the ``hand``, whose palm floats, world is the
frame the palm pose is given in). The *palm* frame is ``palm_link``. Each finger has a fixed
*base* frame on the palm; the FCNN learns each finger's inverse kinematics in its base frame.

Joint tensors. Finger joints are ``(..., F, n)``: F fingers in ``robot.finger_names`` order
(thumb first), each finger's *free* joints in chain order (abduction, MCP, PIP, DIP for the shipped
hand). Mimic joints are not free: they follow their leaders (:mod:`graspnet_torch.robot.fingers`).
Fingers with fewer free joints than the largest, n, are padded: slots ``n_k..n-1`` of finger k
have limits [0, 0] and do not move anything (``robot.finger_mask``).
Body joints (the arm, or the mobile base then the arm) are ``(..., m)`` in
``robot.body_joint_names`` order. Angles in radians, lengths in metres. Every method follows the
dtype and device of its inputs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.chain import ChainSpec, UrdfModel
from graspnet_torch.robot.config import ChainCfg, PoseBounds, RobotCfg, load_robot_cfg
from graspnet_torch.robot.fingers import FingerChain, FingerKernel
from graspnet_torch.robot.kernel import ChainKernel
from graspnet_torch.robot.shared import SharedJoints, find_shared_joints
from graspnet_torch.robot.transforms import pose_to_rt, transform_points, untransform_points

__all__ = ["Finger", "Posture", "Robot", "load_robot"]


@dataclass(frozen=True)
class Finger:
    """One finger: its serial chain (base -> tip) and where its base sits on the palm.

    Attributes:
        name: finger name.
        chain: the chain from the base link to the fingertip (tip offset folded in), seen through
            its free joints (``chain.spec``: every movable joint, mimic joints included).
        base_in_palm: (4, 4) float64 pose of the base frame in the palm frame.
    """

    name: str
    chain: FingerChain
    base_in_palm: np.ndarray

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.chain.joint_names

    @property
    def n_joints(self) -> int:
        return self.chain.n_joints


@dataclass(frozen=True)
class Posture:
    """A whole-robot configuration.

    Attributes:
        palm_pose: (6,) palm pose in the world (x, y, z, rx, ry, rz); for robots with a body it is
            the pose the body's forward kinematics gives.
        fingers: (F, n) finger joints.
        body: (m,) body joints (empty for the hand).
        shared: (S,) the joints several fingers share (:attr:`Robot.shared`); None: where the robot
            holds them (:attr:`Robot.shared_reference`).
    """

    palm_pose: Tensor
    fingers: Tensor
    body: Tensor
    shared: Tensor | None = None


class Robot:
    """Kinematics of a robot described by a :class:`RobotCfg`.

    Build with :meth:`from_config` or :func:`load_robot`.
    """

    def __init__(self, cfg: RobotCfg):
        self.cfg = cfg
        self.name = cfg.name
        self.urdf = UrdfModel(cfg.urdf, cfg.mesh_roots, cfg.allow_outside_paths)  # checked: robot/urdf_checks.py
        src = cfg.source
        self.urdf.check_link(cfg.palm_link, f"{src}: palm_link")

        self.shared = self._shared_joints()
        fingers = [self._finger(fname, chain) for fname, chain in cfg.fingers.items()]
        self.fingers: dict[str, Finger] = {f.name: f for f in fingers}
        self.finger_names: tuple[str, ...] = tuple(self.fingers)
        self.finger_kernel: FingerKernel | None = FingerKernel([f.chain for f in fingers]) if fingers else None
        for f in fingers:
            self._check_tip_moves(f)

        self.body: ChainSpec | None = None
        self.body_kernel: ChainKernel | None = None
        self.gripper_kernel: ChainKernel | None = None
        if cfg.arm is not None:
            root = self.urdf.root_link
            self.urdf.check_link(cfg.arm.base, f"{src}: arm base")
            if cfg.arm.tip != cfg.palm_link:
                raise ConfigError(f"{src}: arm tip '{cfg.arm.tip}' must be the palm_link '{cfg.palm_link}'")
            self.body = self.urdf.chain_spec(root, cfg.palm_link, f"{src}: arm")
            arm_joints = self.urdf.chain_spec(cfg.arm.base, cfg.arm.tip, f"{src}: arm").joint_names
            base_joints = ()
            if cfg.mobile_base is not None:
                base_joints = self.urdf.chain_spec(cfg.mobile_base.base, cfg.mobile_base.tip,
                                                   f"{src}: mobile_base").joint_names
            if self.body.joint_names != base_joints + arm_joints:
                raise ConfigError(f"{src}: the joints from '{root}' to '{cfg.palm_link}' "
                                  f"{self.body.joint_names} are not mobile_base + arm joints")
            self.body_kernel = ChainKernel(self.body)
            if cfg.gripper_points:
                specs = [self.urdf.chain_spec(root, pt, f"{src}: gripper_points") for pt in cfg.gripper_points]
                for spec in specs:
                    if spec.joint_names != self.body.joint_names:
                        raise ConfigError(f"{src}: gripper point '{spec.tip}' must hang rigidly from "
                                          f"'{cfg.palm_link}'")
                self.gripper_kernel = ChainKernel(specs)
        elif cfg.gripper_points:
            raise ConfigError(f"{src}: gripper_points need an arm")
        self._consts: dict[tuple, dict[str, Tensor]] = {}

    def _shared_joints(self) -> SharedJoints:
        """The joints that move more than one finger (:mod:`graspnet_torch.robot.shared`), among
        the fingers whose chains start at the palm (the default base) and whose tips lie below it
        (any other finger's config errors are :meth:`_finger`'s to report)."""
        cfg, links = self.cfg, self.urdf.links

        def below_palm(link: str) -> bool:
            while link in self.urdf.parent_joint:
                link = self.urdf.parent_joint[link].parent
                if link == cfg.palm_link:
                    return True
            return False

        tips = {f: c.tip for f, c in cfg.fingers.items()
                if c.base == cfg.palm_link and c.tip in links and below_palm(c.tip)}
        return find_shared_joints(self.urdf, cfg.palm_link, tips, cfg.source)

    @cached_property
    def shared_reference(self) -> np.ndarray:
        """(S,) the values the shared joints are held at (the config's ``home``, else 0, within
        their limits): they are not yet search variables of the solvers."""
        sh, home = self.shared, self.cfg.home
        out = []
        for name, lo, hi in zip(sh.names, sh.lower, sh.upper, strict=True):
            v = home.get(name, 0.0)
            out.append(min(max(math.radians(v) if self.urdf.joints[name].type != "prismatic" else v, lo), hi))
        return np.asarray(out, dtype=np.float64)

    def _finger(self, fname: str, chain: ChainCfg) -> Finger:
        """A finger from its config: the chain from its base (on the palm; after the joints it
        shares with other fingers) to its tip (offset folded in), its mimic joints and free
        joints."""
        cfg, what = self.cfg, f"{self.cfg.source}: finger '{fname}'"
        self.urdf.check_link(chain.base, f"{what} base")
        self.urdf.check_link(chain.tip, f"{what} tip")
        if fname in self.shared.paths:  # its own chain starts after the shared joints
            chain = replace(chain, base=self.shared.bases[fname])
            s = torch.as_tensor(self.shared_reference, dtype=torch.float64)
            base_in_palm = self.shared.base_frames(s)[fname].numpy()
            return self._finger_chain(fname, chain, base_in_palm)
        for joint in self.urdf.path_joints(cfg.palm_link, chain.base, f"{what} base") if chain.base != cfg.palm_link \
                else []:
            if joint.type != "fixed":
                raise ConfigError(f"{what}: its chain must start at the palm, but joint '{joint.name}' between "
                                  f"palm_link '{cfg.palm_link}' and base '{chain.base}' is {joint.type}; set base "
                                  f"to '{cfg.palm_link}' (or leave it out) so that joint belongs to the finger")
        return self._finger_chain(fname, chain, self.urdf.fixed_transform(cfg.palm_link, chain.base, f"{what} base"))

    def _finger_chain(self, fname: str, chain: ChainCfg, base_in_palm: np.ndarray) -> Finger:
        what = f"{self.cfg.source}: finger '{fname}'"
        spec = self.urdf.chain_spec(chain.base, chain.tip, what)
        if chain.tip_offset is not None:
            offsets = spec.offsets.copy()
            offsets[-1] = offsets[-1] @ _translation(chain.tip_offset)
            spec = replace(spec, offsets=offsets)
        if spec.n_joints == 0:
            raise ConfigError(f"{what}: no movable joint between '{chain.base}' and '{chain.tip}'")
        try:
            finger_chain = FingerChain.from_spec(spec, self.urdf.mimic_joints, what)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        if finger_chain.n_joints == 0:
            raise ConfigError(f"{what}: every joint between '{chain.base}' and '{chain.tip}' is a mimic joint of a "
                              f"joint outside the finger")
        return Finger(fname, finger_chain, base_in_palm)

    def _check_tip_moves(self, finger: Finger, samples: int = 64) -> None:
        """Refuse a finger with a free joint that never moves its tip (the tip on that joint's axis,
        e.g. a fingertip link at the distal joint): its inverse kinematics would be singular everywhere."""
        chain = finger.chain
        gen = np.random.default_rng(0)
        q = chain.lower + (chain.upper - chain.lower) * gen.random((samples, chain.n_joints))
        _, J = FingerKernel(chain).position_jacobian(torch.as_tensor(q, dtype=torch.float64))
        reach = torch.linalg.vector_norm(J, dim=-2).amax(dim=0)  # (n_f,) m/rad, the most over samples
        dead = [chain.joint_names[i] for i in torch.nonzero(reach < 1e-6).flatten().tolist()]
        if dead:
            raise ConfigError(f"{self.cfg.source}: finger '{finger.name}': joint(s) {', '.join(dead)} never move its "
                              f"tip '{chain.tip}' (the tip lies on the joint axis); give the tip an offset: "
                              f"tip: {{link: {chain.tip}, offset: [x, y, z]}} (m, in that link's frame)")

    @classmethod
    def from_config(cls, cfg: RobotCfg | str | Path) -> Robot:
        """From a :class:`RobotCfg`, a robot name (``configs/robot/<name>.yaml``) or a YAML path."""
        return cls(cfg if isinstance(cfg, RobotCfg) else load_robot_cfg(cfg))

    # ------------------------------------------------------------------ structure
    @property
    def n_fingers(self) -> int:
        return len(self.fingers)

    @property
    def joints_per_finger(self) -> int:
        return self.finger_kernel.n_joints if self.finger_kernel is not None else 0

    @property
    def n_finger_joints(self) -> int:
        """Free finger joints, all fingers together (padding not counted)."""
        return sum(f.n_joints for f in self.fingers.values())

    @cached_property
    def finger_mask(self) -> np.ndarray:
        """(F, n) bool: True for a finger's free joints, False for padding."""
        n = self.joints_per_finger
        return np.array([[i < f.n_joints for i in range(n)] for f in self.fingers.values()], dtype=bool).reshape(-1, n)

    @property
    def body_joint_names(self) -> tuple[str, ...]:
        return self.body.joint_names if self.body is not None else ()

    @property
    def has_body(self) -> bool:
        return self.body is not None

    @property
    def kind(self) -> str:
        """'hand' (a free palm with fingers), 'arm_hand' (fingers on a body chain) or 'gripper' (a
        body chain with two marked gripper points, no fingers): which environment solves it
        (:attr:`RobotCfg.kind <graspnet_torch.robot.config.RobotCfg.kind>`)."""
        return self.cfg.kind

    @property
    def dof(self) -> int:
        """Degrees of freedom: finger joints + body joints, or + 6 palm-pose DOF for a
        free-floating hand, + the joints the fingers share."""
        return self.n_finger_joints + (len(self.body_joint_names) if self.has_body else 6) + self.shared.n

    @property
    def n_chains(self) -> int:
        """Serial chains this robot evaluates: one per finger, plus the body chain, plus one per
        gripper point."""
        return self.n_fingers + (1 if self.has_body else 0) + len(self.cfg.gripper_points)

    @property
    def palm_bounds(self) -> PoseBounds | None:
        return self.cfg.palm_bounds

    @cached_property
    def finger_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(F, n) lower and upper limits of the free finger joints (rad or m); padding: [0, 0]."""
        n = self.joints_per_finger
        lower, upper = np.zeros((self.n_fingers, n)), np.zeros((self.n_fingers, n))
        for k, f in enumerate(self.fingers.values()):
            lower[k, : f.n_joints], upper[k, : f.n_joints] = f.chain.lower, f.chain.upper
        return lower, upper

    @cached_property
    def body_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(m,) lower and upper body joint limits (radians or metres)."""
        if self.body is None:
            return np.zeros(0), np.zeros(0)
        return self.body.lower.copy(), self.body.upper.copy()

    def finger_index(self, name: str) -> int:
        try:
            return self.finger_names.index(name)
        except ValueError:
            raise ConfigError(f"robot '{self.name}' has no finger '{name}' (fingers: "
                              f"{', '.join(self.finger_names)})") from None

    def _const(self, dtype: torch.dtype, device: torch.device) -> dict[str, Tensor]:
        key = (dtype, device)
        c = self._consts.get(key)
        if c is None:
            base = np.stack([f.base_in_palm for f in self.fingers.values()]) if self.fingers else np.zeros((0, 4, 4))
            c = {"base_R": torch.as_tensor(base[:, :3, :3], dtype=dtype, device=device),
                 "base_t": torch.as_tensor(base[:, :3, 3], dtype=dtype, device=device)}
            self._consts[key] = c
        return c

    # ------------------------------------------------------------------ checks
    def _check_fingers(self, q: Tensor) -> None:
        if self.finger_kernel is None:
            raise ValueError(f"robot '{self.name}' has no fingers")
        F, n = self.n_fingers, self.joints_per_finger
        if not isinstance(q, Tensor) or q.dim() < 2 or tuple(q.shape[-2:]) != (F, n):
            shape = tuple(q.shape) if isinstance(q, Tensor) else type(q).__name__
            raise ValueError(f"finger joints must have shape (..., {F}, {n}) ({F} fingers "
                             f"{', '.join(self.finger_names)} x {n} joints); got {shape}")

    def _check_body(self, q: Tensor) -> None:
        if self.body_kernel is None:
            raise ValueError(f"robot '{self.name}' has no arm")
        m = len(self.body_joint_names)
        if not isinstance(q, Tensor) or q.dim() < 1 or q.shape[-1] != m:
            shape = tuple(q.shape) if isinstance(q, Tensor) else type(q).__name__
            raise ValueError(f"body joints must have shape (..., {m}) ({', '.join(self.body_joint_names)}); "
                             f"got {shape}")

    @staticmethod
    def _check_pose(pose: Tensor, what: str = "palm pose") -> None:
        if not isinstance(pose, Tensor) or pose.dim() < 1 or pose.shape[-1] != 6:
            shape = tuple(pose.shape) if isinstance(pose, Tensor) else type(pose).__name__
            raise ValueError(f"{what} must have shape (..., 6) (x, y, z, rx, ry, rz); got {shape}")

    # ------------------------------------------------------------------ finger kinematics
    def fingertips_base(self, q: Tensor) -> Tensor:
        """Fingertips, each in its finger's base frame. q: (..., F, n) -> (..., F, 3)."""
        self._check_fingers(q)
        return self.finger_kernel.position(q)

    def fingertips_base_jacobian(self, q: Tensor) -> tuple[Tensor, Tensor]:
        """Fingertips and d tip / d q in each finger's base frame.

        q: (..., F, n) -> p: (..., F, 3), J: (..., F, 3, n).
        """
        self._check_fingers(q)
        return self.finger_kernel.position_jacobian(q)

    def base_to_palm(self, points: Tensor) -> Tensor:
        """Points given in each finger's base frame -> palm frame. (..., F, 3) -> (..., F, 3)."""
        c = self._const(points.dtype, points.device)
        return transform_points(c["base_R"], c["base_t"], points)

    def palm_to_base(self, points: Tensor) -> Tensor:
        """Points given in the palm frame -> each finger's base frame. (..., F, 3) -> (..., F, 3)."""
        c = self._const(points.dtype, points.device)
        return untransform_points(c["base_R"], c["base_t"], points)

    def base_frames(self, shared: Tensor) -> tuple[Tensor, Tensor]:
        """Every finger's base in the palm frame with the shared joints at ``shared`` (..., S):
        R (..., F, 3, 3), t (..., F, 3) (the fingers they do not move: their fixed base)."""
        c = self._const(shared.dtype, shared.device)
        lead = shared.shape[:-1]
        R = c["base_R"].expand(*lead, -1, -1, -1).clone()
        t = c["base_t"].expand(*lead, -1, -1).clone()
        for name, T in self.shared.base_frames(shared).items():
            k = self.finger_index(name)
            R[..., k, :, :], t[..., k, :] = T[..., :3, :3], T[..., :3, 3]
        return R, t

    def fingertips_palm(self, q: Tensor, shared: Tensor | None = None) -> Tensor:
        """Fingertips in the palm frame. q: (..., F, n) -> (..., F, 3); shared: (..., S) the joints
        the fingers share (None: where they are held)."""
        if shared is None or not self.shared.n:
            return self.base_to_palm(self.fingertips_base(q))
        R, t = self.base_frames(shared)
        return transform_points(R, t, self.fingertips_base(q))

    def fingertips_world(self, palm_pose: Tensor, q: Tensor, shared: Tensor | None = None) -> Tensor:
        """Fingertips in the world for a palm pose.

        palm_pose: (..., 6); q: (..., F, n); shared: (..., S) (None: where they are held) -> (..., F, 3).
        """
        self._check_pose(palm_pose)
        R, t = pose_to_rt(palm_pose)
        return transform_points(R.unsqueeze(-3), t.unsqueeze(-2), self.fingertips_palm(q, shared))

    def world_to_bases(self, points: Tensor, palm_pose: Tensor) -> Tensor:
        """Points in the world, one per finger, -> each in its finger's base frame.

        points: (..., F, 3); palm_pose: (..., 6) -> (..., F, 3).
        """
        self._check_pose(palm_pose)
        R, t = pose_to_rt(palm_pose)
        return self.palm_to_base(untransform_points(R.unsqueeze(-3), t.unsqueeze(-2), points))

    # ------------------------------------------------------------------ body kinematics
    def palm_frame(self, q_body: Tensor) -> tuple[Tensor, Tensor]:
        """Palm frame in the world from the body joints (arm FK).

        q_body: (..., m) -> R: (..., 3, 3), t: (..., 3).
        """
        self._check_body(q_body)
        return self.body_kernel.pose(q_body)

    def palm_frame_jacobian(self, q_body: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Palm frame and its geometric Jacobian (rows d t, then w; see ``transforms.frame_point_jacobian``).
        q_body: (..., m) -> R: (..., 3, 3), t: (..., 3), J: (..., 6, m)."""
        self._check_body(q_body)
        return self.body_kernel.pose_jacobian(q_body)

    def fingertips_world_from_body(self, q_body: Tensor, q: Tensor) -> Tensor:
        """Fingertips in the world from body and finger joints. (..., m), (..., F, n) -> (..., F, 3)."""
        R, t = self.palm_frame(q_body)
        return transform_points(R.unsqueeze(-3), t.unsqueeze(-2), self.fingertips_palm(q))

    def world_to_bases_from_body(self, points: Tensor, q_body: Tensor) -> Tensor:
        """World points, one per finger -> finger base frames, palm placed by the body joints."""
        R, t = self.palm_frame(q_body)
        return self.palm_to_base(untransform_points(R.unsqueeze(-3), t.unsqueeze(-2), points))

    def gripper_points(self, q_body: Tensor) -> Tensor:
        """The gripper's marked points in the world. q_body: (..., m) -> (..., 2, 3)."""
        q = self._gripper_joints(q_body)
        return self.gripper_kernel.position(q)

    def _gripper_joints(self, q_body: Tensor) -> Tensor:
        """The body joints, checked, once per gripper point's chain: (..., m) -> (..., 2, m)."""
        self._check_body(q_body)
        if self.gripper_kernel is None:
            raise ValueError(f"robot '{self.name}' has no gripper points")
        return q_body.unsqueeze(-2).expand(*q_body.shape[:-1], self.gripper_kernel.num_chains, q_body.shape[-1])

    def gripper_points_jacobian(self, q_body: Tensor) -> tuple[Tensor, Tensor]:
        """The gripper's marked points and d point / d q_body. q_body: (..., m) -> (..., 2, 3), (..., 2, 3, m)."""
        q = self._gripper_joints(q_body)
        return self.gripper_kernel.position_jacobian(q)

    # ------------------------------------------------------------------ postures
    def home_posture(self, dtype: torch.dtype = torch.float64) -> Posture:
        """The config's ``home`` joints (degrees/metres in the file), clipped to the joint limits;
        a free hand's palm sits at the world origin. Built once per dtype; each call a fresh copy."""
        cached = self.__dict__.setdefault("_homes", {}).get(dtype)
        if cached is None:
            from graspnet_torch.robot.postures import build_home_posture

            cached = self._homes[dtype] = build_home_posture(self, dtype)
        return Posture(cached.palm_pose.clone(), cached.fingers.clone(), cached.body.clone())

    def finger_all_joint_names(self, name: str) -> tuple[str, ...]:
        """Every movable joint on a finger's URDF chain from the palm to its tip, in chain order:
        the joints it shares with other fingers (:attr:`shared`), then its own (mimic joints
        included)."""
        path = self.shared.paths.get(name)
        return (path.joint_names if path is not None else ()) + self.fingers[name].chain.all_joint_names

    def _shared_rows(self, shared: Tensor | np.ndarray | None, T: int) -> np.ndarray:
        """(T, S) shared joint values: as given ((S,) or (T, S)), else where they are held."""
        if shared is None:
            return np.broadcast_to(self.shared_reference, (T, self.shared.n))
        s = np.asarray(shared.detach().cpu() if isinstance(shared, Tensor) else shared, dtype=np.float64)
        return np.broadcast_to(s.reshape(-1, self.shared.n), (T, self.shared.n))

    def _prefix(self, name: str, s: np.ndarray) -> np.ndarray:
        """(T, P) the values of the joints finger ``name`` shares, at shared values s (T, S)."""
        path = self.shared.paths.get(name)
        if path is None:
            return np.zeros((s.shape[0], 0))
        index = {n: k for k, n in enumerate(self.shared.names)}
        columns = []
        for joint in path.joint_names:
            leader, m, b = self.shared.followers.get(joint, (joint, 1.0, 0.0))
            columns.append(m * s[:, index[leader]] + b)
        return np.stack(columns, axis=1)

    def finger_joint_values(self, q: Tensor | np.ndarray, shared: Tensor | np.ndarray | None = None
                            ) -> dict[str, list[float]]:
        """Every movable joint of each finger (:meth:`finger_all_joint_names`: the shared ones at
        ``shared`` (S,), default where they are held; mimic joints at their coupled values).

        q: (F, n) free joints (padded) -> finger name -> values (rad or m).
        """
        q = np.asarray(q.detach().cpu() if isinstance(q, Tensor) else q, dtype=np.float64)
        s = self._shared_rows(shared, 1)
        return {f.name: self._prefix(f.name, s)[0].tolist() + f.chain.expand(q[k, : f.n_joints]).tolist()
                for k, f in enumerate(self.fingers.values())}

    def free_finger_joints(self, values: dict[str, Sequence[float]], dtype: torch.dtype = torch.float64) -> Tensor:
        """The inverse of :meth:`finger_joint_values`: every finger's listed joints (palm to tip,
        shared and mimic joints included) -> (F, n) free joints, padded (the shared joints:
        :meth:`shared_joints_of`)."""
        q = torch.zeros(self.n_fingers, self.joints_per_finger, dtype=dtype)
        for k, f in enumerate(self.fingers.values()):
            row = list(values[f.name])
            names = self.finger_all_joint_names(f.name)
            if len(row) != len(names):
                raise ValueError(f"finger '{f.name}' has {len(names)} joints ({', '.join(names)}), got {len(row)} "
                                 f"values")
            own = row[len(names) - f.chain.spec.n_joints:]
            q[k, : f.n_joints] = torch.tensor([own[i] for i in f.chain.free], dtype=dtype)
        return q

    def shared_joints_of(self, values: dict[str, Sequence[float]]) -> Tensor:
        """The shared joints (S,) float64 (rad or m) from every finger's listed joints (as
        :meth:`free_finger_joints` takes them): each from the first finger whose chain holds it,
        else from a follower (q = m s + b); where no listed finger has either, where it is held."""
        out = torch.as_tensor(self.shared_reference.copy())
        found = set()
        for f in self.fingers:
            path = self.shared.paths.get(f)
            if path is None or f not in values:
                continue
            for joint, v in zip(path.joint_names, values[f], strict=False):
                leader, m, b = self.shared.followers.get(joint, (joint, 1.0, 0.0))
                k = self.shared.names.index(leader)
                if k in found and joint != leader:
                    continue
                out[k] = (v - b) / m
                found.add(k)
        return out

    def finger_joints_to_file(self, q: Tensor | np.ndarray, shared: Tensor | np.ndarray | None = None
                              ) -> dict[str, list[float]]:
        """:meth:`finger_joint_values` in file units: degrees (revolute), metres (prismatic)."""
        return self.finger_joints_to_file_many(q[None], None if shared is None else np.asarray(shared)[None])[0]

    def finger_joints_to_file_many(self, q: Tensor | np.ndarray, shared: Tensor | np.ndarray | None = None
                                   ) -> list[dict[str, list[float]]]:
        """:meth:`finger_joints_to_file` of T postures at once. q: (T, F, n) free joints (padded);
        shared: (T, S) (default: where they are held)."""
        q = np.asarray(q.detach().cpu() if isinstance(q, Tensor) else q, dtype=np.float64)
        s = self._shared_rows(shared, q.shape[0])
        columns = {}
        for k, f in enumerate(self.fingers.values()):
            types = self._joint_types(f.name)
            to_file = np.array([180.0 / math.pi if t == "revolute" else 1.0 for t in types])
            every = np.concatenate([self._prefix(f.name, s), f.chain.expand(q[:, k, : f.n_joints])], axis=1)
            columns[f.name] = (every * to_file).tolist()  # as math.degrees
        return [{name: rows[t] for name, rows in columns.items()} for t in range(q.shape[0])]

    def _joint_types(self, name: str) -> tuple[str, ...]:
        path = self.shared.paths.get(name)
        return (path.joint_types if path is not None else ()) + self.fingers[name].chain.spec.joint_types

    def finger_joints_from_file(self, values: dict[str, Sequence[float]], dtype: torch.dtype = torch.float64) -> Tensor:
        """The inverse of :meth:`finger_joints_to_file`: (F, n) free joints (rad or m), padded."""
        return self.free_finger_joints(self.finger_values_from_file(values), dtype)

    def finger_values_from_file(self, values: dict[str, Sequence[float]]) -> dict[str, list[float]]:
        """Every finger's listed joints in file units -> in radians / metres (as listed)."""
        si = {}
        for name in self.fingers:
            types = self._joint_types(name)
            row = list(values[name])
            si[name] = [math.radians(v) if t == "revolute" else v for v, t in zip(row, types, strict=False)] + \
                row[len(types):]
        return si

    def body_joints_to_file(self, q: Tensor) -> dict[str, float]:
        """(m,) body joints (rad or m) -> by URDF joint name in chain order, in file units: degrees
        (revolute), metres (prismatic)."""
        deg = 180.0 / math.pi
        return {n: v * (deg if t == "revolute" else 1.0)
                for n, v, t in zip(self.body_joint_names, q.tolist(), self.body.joint_types, strict=True)}

    def body_joints_from_file(self, values: dict[str, float]) -> Tensor:
        """The inverse of :meth:`body_joints_to_file`: (m,) float64 (rad or m)."""
        d = math.pi / 180
        return torch.tensor([values[n] * (d if t == "revolute" else 1.0)
                             for n, t in zip(self.body_joint_names, self.body.joint_types, strict=True)],
                            dtype=torch.float64)

    def joint_values(self, posture: Posture) -> dict[str, float]:
        """Every movable URDF joint's value in a posture (radians / metres), mimic joints at their
        coupled values, joints shared by several fingers where they are held
        (:attr:`shared_reference`)."""
        out = dict(zip(self.body_joint_names, posture.body.tolist(), strict=True))
        out.update(self.shared.joint_values(self._shared_rows(posture.shared, 1)[0]))
        for name, values in self.finger_joint_values(posture.fingers, posture.shared).items():
            out.update(zip(self.finger_all_joint_names(name), values, strict=True))
        return out

    def link_frames(self, posture: Posture) -> dict[str, np.ndarray]:
        """(4, 4) float64 world pose of every link (pytorch-kinematics; pictures, collision scenes)."""
        return self.link_frames_many([posture])[0]

    def link_frames_many(self, postures: Sequence[Posture]) -> list[dict[str, np.ndarray]]:
        """:meth:`link_frames` of several postures, in one pass of forward kinematics."""
        names, frames = self.link_frames_array(postures)
        return [dict(zip(names, frames[k], strict=True)) for k in range(len(postures))]

    def link_frames_array(self, postures: Sequence[Posture]) -> tuple[list[str], np.ndarray]:
        """The links' names and their world poses (B, L, 4, 4) float64 in B postures (one pass of
        forward kinematics: :meth:`link_frames_of`)."""
        fingers = torch.stack([p.fingers.to(torch.float64) for p in postures])
        shared = None
        if self.shared.n and any(p.shared is not None for p in postures):
            shared = np.stack([self._shared_rows(p.shared, 1)[0] for p in postures])
        if self.body is not None:
            return self.link_frames_of(torch.stack([p.body.to(torch.float64) for p in postures]), fingers,
                                       shared=shared)
        return self.link_frames_of(None, fingers, torch.stack([p.palm_pose.to(torch.float64) for p in postures]),
                                   shared)

    def link_frames_of(self, body: Tensor | None, fingers: Tensor, palm_pose: Tensor | None = None,
                       shared: Tensor | np.ndarray | None = None) -> tuple[list[str], np.ndarray]:
        """The links' names and world poses (B, L, 4, 4) float64 from joints: body (B, m) (a robot
        with a body; else None), fingers (B, F, n) free joints (padded), palm_pose (B, 6) (a free
        hand's), shared (B, S) (default: where they are held)."""
        chain = self.urdf.chain64
        names = chain.get_joint_parameter_names()
        if "_joint_columns" not in self.__dict__:  # where each URDF joint's value comes from, once
            body_names = list(self.body_joint_names) if self.body is not None else []
            sources = []
            for name in names:
                if name in body_names:
                    sources.append(("body", body_names.index(name), 0))
                    continue
                for k, f in enumerate(self.fingers.values()):
                    if name in f.chain.all_joint_names:
                        sources.append(("finger", k, f.chain.all_joint_names.index(name)))
                        break
                else:
                    sources.append(("shared", 0, 0) if name in self.shared.names or name in self.shared.followers
                                   else ("none", 0, 0))
            self._joint_columns = sources
        B = fingers.shape[0]
        s = self._shared_rows(shared, B)
        index = {n: k for k, n in enumerate(self.shared.names)}
        q = fingers.detach().to(torch.float64).cpu().numpy()
        expanded = [f.chain.expand(q[:, k, : f.n_joints]) for k, f in enumerate(self.fingers.values())]
        th = np.zeros((B, len(names)))
        for c, (kind, k, i) in enumerate(self._joint_columns):
            if kind == "body":
                th[:, c] = body[:, k].detach().cpu().numpy()
            elif kind == "finger":
                th[:, c] = expanded[k][:, i]
            elif kind == "shared":
                leader, m, b = self.shared.followers.get(names[c], (names[c], 1.0, 0.0))
                th[:, c] = m * s[:, index[leader]] + b
        fk = chain.forward_kinematics(torch.as_tensor(th))
        links = list(fk)
        frames = torch.stack([fk[name].get_matrix().expand(B, 4, 4) for name in links], dim=1).numpy()
        if self.body is None:
            from graspnet_torch.robot.transforms import pose_to_matrix

            root_to_palm = self.urdf.fixed_transform(self.urdf.root_link, self.cfg.palm_link)
            world = pose_to_matrix(palm_pose.detach().to(torch.float64).cpu()).numpy() @ np.linalg.inv(root_to_palm)
            frames = world[:, None] @ frames
        return links, frames

    def __repr__(self) -> str:
        return (f"Robot('{self.name}': {len(self.urdf.links)} links, {len(self.urdf.movable_joint_names)} "
                f"movable joints, {self.n_chains} chains, {self.dof} DOF)")


def _translation(xyz) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = xyz
    return T


def load_robot(name: str | Path | RobotCfg) -> Robot:
    """A robot by name (``configs/robot/<name>.yaml``), YAML path or config."""
    return Robot.from_config(name)
