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
from dataclasses import replace
from functools import cached_property
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.chain import ChainSpec, UrdfModel
from graspnet_torch.robot.config import ChainCfg, PoseBounds, RobotCfg, load_robot_cfg
from graspnet_torch.robot.fingers import FingerChain, FingerKernel
from graspnet_torch.robot.joint_files import JointValues
from graspnet_torch.robot.kernel import ChainKernel
from graspnet_torch.robot.kinematics import Kinematics
from graspnet_torch.robot.link_frames import LinkFrames
from graspnet_torch.robot.opposition import facing_pads
from graspnet_torch.robot.pads import Pad, centred_config, finger_pads
from graspnet_torch.robot.shared import SharedJoints, find_shared_joints
from graspnet_torch.robot.structure import Finger, Posture
from graspnet_torch.robot.transforms import pose_to_matrix_np, rt_to_pose

__all__ = ["Finger", "Posture", "Robot", "load_robot"]


class Robot(Kinematics, JointValues, LinkFrames):
    """Kinematics of a robot described by a :class:`RobotCfg`.

    Build with :meth:`from_config` or :func:`load_robot`. Here: its structure (fingers, body,
    limits, home posture); its kinematics entry points, joint values in file units and link
    frames are its parts :class:`~graspnet_torch.robot.kinematics.Kinematics`,
    :class:`~graspnet_torch.robot.joint_files.JointValues` and
    :class:`~graspnet_torch.robot.link_frames.LinkFrames`.
    """

    def __init__(self, cfg: RobotCfg):
        self.cfg = cfg
        self.name = cfg.name
        self.urdf = UrdfModel(cfg.urdf, cfg.mesh_roots, cfg.allow_outside_paths)  # checked: robot/urdf_checks.py
        src = cfg.source
        self.urdf.check_link(cfg.palm_link, f"{src}: palm_link")
        self.wrist: dict[str, float] = self._wrist_values()  # a free hand's wrist joints -> held value (rad or m)

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
        if self.fingers:  # each tip on its pad's normal line (robot/pads.py, centred_config)
            try:
                pads = facing_pads(self, finger_pads(self))
            except ConfigError:  # a pad that cannot be derived (a distal link's mesh missing): said where pads
                return  # are used (the property below), as a robot without pads works for the point model
            centred = centred_config(self, pads)
            if centred is not None:
                self.__init__(centred)
                return
            self.__dict__["pads"] = pads  # the cached property's value

    def _shared_joints(self) -> SharedJoints:
        """The joints that move more than one finger (:mod:`graspnet_torch.robot.shared`), among
        the fingers whose chains start at the palm (the default base) and whose tips lie below it
        (any other finger's config errors are :meth:`_finger`'s to report)."""
        cfg = self.cfg
        below_palm = self.urdf.subtree(cfg.palm_link) - {cfg.palm_link}
        tips = {f: c.tip for f, c in cfg.fingers.items() if c.base == cfg.palm_link and c.tip in below_palm}
        return find_shared_joints(self.urdf, cfg.palm_link, tips, cfg.source)

    def _wrist_values(self) -> dict[str, float]:
        """A free hand's wrist: every movable joint between the URDF root and ``palm_link`` -> the
        value it is held at (rad or m): the config's ``wrist`` (degrees or metres), else 0; a mimic
        joint at its leader's coupled value. {} for a robot with an arm. Raises ConfigError for a
        ``wrist`` joint not on that path or a mimic one, and for a value (given, or the default 0)
        outside the joint's limits."""
        cfg, urdf = self.cfg, self.urdf
        if cfg.arm is not None:
            return {}
        src, root, palm, mimic = cfg.source, urdf.root_link, cfg.palm_link, urdf.mimic_joints
        path = [j for j in urdf.path_joints(root, palm, f"{src}: palm_link") if j.type != "fixed"]
        names = [j.name for j in path]
        for name in cfg.wrist:
            if name not in names:
                raise ConfigError(f"{src}: wrist.{name}: not a movable joint between the URDF root '{root}' and "
                                  f"palm_link '{palm}' (those are: {', '.join(names) or 'none'})")
            if name in mimic:
                raise ConfigError(f"{src}: wrist.{name}: a mimic joint of '{mimic[name][0]}', which it follows; "
                                  f"set wrist.{mimic[name][0]}")
        out = {}
        for j in path:
            if j.name in mimic:
                continue
            given = cfg.wrist.get(j.name, 0.0)
            unit = 1.0 if j.type == "prismatic" else math.pi / 180  # file units -> m or rad
            lo, hi = urdf.joint_limits(j.name)
            if j.type != "continuous" and not lo - 1e-9 <= given * unit <= hi + 1e-9:
                limits = f"[{lo / unit:g}, {hi / unit:g}] {'m' if j.type == 'prismatic' else 'degrees'}"
                raise ConfigError(f"{src}: wrist.{j.name}: {given:g} is outside the joint's limits {limits}"
                                  if j.name in cfg.wrist else
                                  f"{src}: wrist joint '{j.name}' (between '{root}' and palm_link '{palm}') is held "
                                  f"at 0 by default, outside its limits {limits}; set wrist.{j.name}")
            out[j.name] = min(max(given * unit, lo), hi) if j.type != "continuous" else given * unit
        todo = [name for name in names if name in mimic]
        while todo:  # mimic joints, each once its leader has a value
            ready = [name for name in todo if mimic[name][0] in out]
            if not ready:
                raise ConfigError(f"{src}: wrist joint '{todo[0]}' mimics '{mimic[todo[0]][0]}', which is not "
                                  f"between the URDF root '{root}' and palm_link '{palm}'")
            for name in ready:
                leader, m, b = mimic[name]
                out[name] = m * out[leader] + b
                todo.remove(name)
        return {name: out[name] for name in names}

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
            offsets[-1] = offsets[-1] @ pose_to_matrix_np([*chain.tip_offset, 0.0, 0.0, 0.0])
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
        mask = np.zeros((self.n_fingers, self.joints_per_finger), dtype=bool)  # (0, 0) without fingers
        for k, f in enumerate(self.fingers.values()):
            mask[k, :f.n_joints] = True
        return mask

    @property
    def body_joint_names(self) -> tuple[str, ...]:
        return self.body.joint_names if self.body is not None else ()

    @property
    def body_joint_types(self) -> tuple[str, ...]:
        """The body joints' types (``revolute``, ``prismatic``), URDF order; () without a body."""
        return tuple(self.body.joint_types) if self.body is not None else ()

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

    @cached_property
    def pads(self) -> dict[str, Pad]:
        """Finger name -> its :class:`~graspnet_torch.robot.pads.Pad` (a point and outward normal in
        the finger's tip frame: the config's ``pad``, else derived from the URDF, the opposing
        finger's facing the others: :func:`~graspnet_torch.robot.opposition.facing_pads`); {} without
        fingers."""
        return facing_pads(self, finger_pads(self))

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

    # ------------------------------------------------------------------ postures
    def home_posture(self, dtype: torch.dtype = torch.float64) -> Posture:
        """The config's ``home`` joints (degrees/metres in the file), clipped to the joint limits;
        a free hand's palm sits at the world origin. Built once per dtype; each call a fresh copy."""
        cached = self.__dict__.setdefault("_homes", {}).get(dtype)
        if cached is None:
            cached = self._homes[dtype] = self._build_home_posture(dtype)
        return Posture(cached.palm_pose.clone(), cached.fingers.clone(), cached.body.clone())

    def _build_home_posture(self, dtype: torch.dtype) -> Posture:
        """The config's ``home`` joints (degrees/metres in the file), clipped to the joint limits; a
        free hand's palm at the world origin (:meth:`home_posture` keeps one per dtype)."""
        home = self.cfg.home
        unknown = sorted(set(home) - set(self.urdf.movable_joint_names))
        if unknown:
            raise ConfigError(f"{self.cfg.source}: home names unknown joint(s) {', '.join(unknown)}")

        def values(spec_names, lower, upper, types):
            out = []
            for name, lo, hi, kind in zip(spec_names, lower, upper, types, strict=True):
                v = home.get(name, 0.0)
                out.append(min(max(math.radians(v) if kind == "revolute" else v, lo), hi))
            return out

        finger_q = torch.zeros(self.n_fingers, self.joints_per_finger, dtype=dtype)
        for k, f in enumerate(self.fingers.values()):
            finger_q[k, : f.n_joints] = torch.tensor(values(f.joint_names, f.chain.lower, f.chain.upper,
                                                            f.chain.joint_types), dtype=dtype)
        if self.body is not None:
            body_q = torch.tensor(values(self.body.joint_names, self.body.lower, self.body.upper,
                                         self.body.joint_types), dtype=dtype)
            palm = rt_to_pose(*self.palm_frame(body_q))
        else:
            body_q = torch.zeros(0, dtype=dtype)
            palm = torch.zeros(6, dtype=dtype)
        return Posture(palm_pose=palm, fingers=finger_q, body=body_q)

    def __repr__(self) -> str:
        return (f"Robot('{self.name}': {len(self.urdf.links)} links, {len(self.urdf.movable_joint_names)} "
                f"movable joints, {self.n_chains} chains, {self.dof} DOF)")


def load_robot(name: str | Path | RobotCfg) -> Robot:
    """A robot by name (``configs/robot/<name>.yaml``), YAML path or config."""
    return Robot.from_config(name)
