"""URDF parsing and serial-chain constants.

pytorch-kinematics parses the URDF and builds each serial chain (which frames, which joints, their
types, axes and limits); :class:`ChainSpec` reads that chain into float64 constants,

    T(q) = F_0 M_0(q_0) F_1 M_1(q_1) ... M_{n-1}(q_{n-1}) F_n,

where each ``F_i`` is the product of the fixed transforms between two movable joints and ``M_i``
the motion of joint i about (revolute) or along (prismatic) its axis. Joint origins are taken from
the URDF in float64 (pytorch-kinematics stores them in float32), so the fast kernel built from a
``ChainSpec`` is exact to float64 rounding.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from graspnet_torch.errors import ConfigError
from graspnet_torch.robot.transforms import pose_to_matrix_np
from graspnet_torch.robot.urdf_checks import check_urdf
from graspnet_torch.settings import clip

if TYPE_CHECKING:  # pragma: no cover
    import pytorch_kinematics as pk

__all__ = ["ChainSpec", "UrdfModel", "joint_motion", "origin_matrix", "origin_pose"]


def origin_pose(origin) -> np.ndarray:
    """(6,) float64 (x, y, z, rx, ry, rz) of a URDF ``<origin>`` (None, or missing xyz / rpy: zeros)."""
    if origin is None:
        return np.zeros(6)
    xyz = origin.xyz if origin.xyz is not None else (0, 0, 0)
    rpy = origin.rpy if origin.rpy is not None else (0, 0, 0)
    return np.array([*xyz, *rpy], dtype=np.float64)


def origin_matrix(origin) -> np.ndarray:
    """(4, 4) float64 of a URDF ``<origin>`` (None, or missing xyz / rpy: zeros)."""
    return np.eye(4) if origin is None else pose_to_matrix_np(origin_pose(origin))


def joint_motion(kind: str, axis: np.ndarray, q: float) -> np.ndarray:
    """(4, 4) float64 motion of a joint of ``kind`` ('revolute' | 'prismatic') about / along its
    unit ``axis`` (3,) by ``q`` (rad or m): Rodrigues' formula, or a translation."""
    M = np.eye(4)
    if kind == "prismatic":
        M[:3, 3] = np.asarray(axis) * q
        return M
    a = axis
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    M[:3, :3] = np.eye(3) + math.sin(q) * K + (1 - math.cos(q)) * K @ K
    return M


@dataclass(frozen=True)
class ChainSpec:
    """float64 constants of one serial chain from ``root`` to ``tip``.

    Attributes:
        root, tip: link names.
        joint_names, joint_types: movable joints in chain order; types 'revolute' | 'prismatic'.
        axes: (n, 3) unit joint axes, each in its joint's frame.
        offsets: (n + 1, 4, 4) fixed transforms F_0..F_n (see module docstring).
        lower, upper: (n,) joint limits (rad or m); a continuous joint gets [-pi, pi].
    """

    root: str
    tip: str
    joint_names: tuple[str, ...]
    joint_types: tuple[str, ...]
    axes: np.ndarray
    offsets: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def transform(self, q: np.ndarray) -> np.ndarray:
        """Reference evaluation (float64, one configuration): q (n,) -> T (4, 4) of tip in root."""
        T = self.offsets[0].copy()
        for i, kind in enumerate(self.joint_types):
            T = T @ joint_motion(kind, self.axes[i], q[i]) @ self.offsets[i + 1]
        return T


MAX_URDF_BYTES = 32 << 20


@contextmanager
def _quiet_parser():
    """While pytorch-kinematics' URDF parser runs, drop its 'Unknown attribute' / 'Unknown tag'
    notes (non-standard extras such as the full inertia tensor some vendors write: harmless, and
    printed once per parse); other parser messages still reach stderr."""
    from pytorch_kinematics.urdf_parser_py.xml_reflection import core

    previous = core.on_error

    def on_error(message: str) -> None:
        if not str(message).startswith(("Unknown attribute", "Unknown tag")):
            sys.stderr.write(f"{message}\n")

    core.on_error = on_error
    try:
        yield
    finally:
        core.on_error = previous


class UrdfModel:
    """A URDF file parsed by pytorch-kinematics and checked (:func:`check_urdf`: a tree of finite
    joints), with its serial chains on demand.

    Args:
        path: the URDF file.
        roots: folders its meshes may also lie in, besides its own folder, the repository and the
            installed Python packages (the robot config's folder; :func:`~graspnet_torch.robot.meshes.resolve_mesh`).
        allow_outside_paths: its meshes may lie anywhere.
    """

    def __init__(self, path: str | Path, roots: tuple[Path, ...] = (), allow_outside_paths: bool = False):
        self.path = Path(path)
        self.mesh_roots = tuple(Path(r) for r in roots)
        self.allow_outside_paths = allow_outside_paths
        if not self.path.is_file():
            raise ConfigError(f"URDF file not found: {self.path}")
        if self.path.stat().st_size > MAX_URDF_BYTES:
            raise ConfigError(f"{self.path}: more than {MAX_URDF_BYTES} bytes; not a URDF this project reads")
        self.xml = self.path.read_bytes()  # bytes: the XML parser honours an encoding declaration
        from pytorch_kinematics.urdf_parser_py.urdf import URDF

        try:
            with _quiet_parser():
                self.robot = URDF.from_xml_string(self.xml)
        except Exception as exc:  # the parser raises assorted types on malformed XML
            raise ConfigError(f"{self.path}: not a valid URDF ({clip(' '.join(str(exc).split()), 160)})") from None
        check_urdf(self.robot, self.path)  # a tree of finite joints, before any walk or kinematics
        self.links: dict[str, object] = {link.name: link for link in self.robot.links}
        self.joints: dict[str, object] = {j.name: j for j in self.robot.joints}
        self.parent_joint: dict[str, object] = {j.child: j for j in self.robot.joints}

    @cached_property
    def mimic_joints(self) -> dict[str, tuple[str, float, float]]:
        """Mimic joint name -> (leader, multiplier, offset); URDF defaults 1 and 0."""
        out = {}
        for j in self.robot.joints:
            m = getattr(j, "mimic", None)
            if m is not None and j.type in ("revolute", "continuous", "prismatic"):
                out[j.name] = (m.joint, 1.0 if m.multiplier is None else float(m.multiplier),
                               0.0 if m.offset is None else float(m.offset))
        return out

    @property
    def link_names(self) -> list[str]:
        return list(self.links)

    @property
    def movable_joint_names(self) -> list[str]:
        return [j.name for j in self.robot.joints if j.type in ("revolute", "continuous", "prismatic")]

    @property
    def root_link(self) -> str:
        roots = [name for name in self.links if name not in self.parent_joint]
        if len(roots) != 1:
            raise ConfigError(f"{self.path}: expected one root link, found {roots}")
        return roots[0]

    @cached_property
    def chain(self) -> pk.Chain:
        """The whole kinematic tree as a pytorch-kinematics ``Chain``."""
        import pytorch_kinematics as pk

        with _quiet_parser():
            return pk.build_chain_from_urdf(self.xml)

    def check_link(self, link: str, what: str) -> None:
        if link not in self.links:
            raise ConfigError(f"{what}: link '{link}' is not in {self.path.name}")

    def subtree(self, link: str) -> frozenset[str]:
        """``link`` and every link below it."""
        children: dict[str, list[str]] = {}
        for j in self.robot.joints:
            children.setdefault(j.parent, []).append(j.child)
        out, todo = set(), [link]
        while todo:
            below = todo.pop()
            out.add(below)
            todo.extend(children.get(below, []))
        return frozenset(out)

    def path_joints(self, root: str, tip: str, what: str = "chain") -> list:
        """URDF joints from ``root`` down to ``tip``, in chain order."""
        self.check_link(root, what)
        self.check_link(tip, what)
        joints, link = [], tip
        while link != root:
            joint = self.parent_joint.get(link)
            if joint is None:
                raise ConfigError(f"{what}: link '{tip}' is not below '{root}' in {self.path.name}")
            joints.append(joint)
            link = joint.parent
        return joints[::-1]

    def fixed_transform(self, root: str, tip: str, what: str = "frame") -> np.ndarray:
        """(4, 4) float64 pose of ``tip`` in ``root``; every joint between them must be fixed."""
        return self.transform_at(root, tip, {}, what)

    def transform_at(self, root: str, tip: str, values: Mapping[str, float], what: str = "frame") -> np.ndarray:
        """(4, 4) float64 pose of ``tip`` in ``root`` with each movable joint between them at
        ``values[name]`` (rad or m); a movable joint ``values`` leaves out is refused."""
        T = np.eye(4)
        for joint in self.path_joints(root, tip, what):
            T = T @ self._link_offset(joint.child) @ origin_matrix(joint.origin)
            if joint.type == "fixed":
                continue
            if joint.name not in values:
                raise ConfigError(f"{what}: joint '{joint.name}' between '{root}' and '{tip}' is "
                                  f"{joint.type}, expected only fixed joints")
            T = T @ joint_motion("prismatic" if joint.type == "prismatic" else "revolute",
                                 self.joint_axis(joint.name), values[joint.name])
        return T

    def joint_axis(self, name: str) -> np.ndarray:
        """(3,) float64 unit axis of joint ``name`` in its own frame (no ``<axis>``: z)."""
        axis = self.joints[name].axis
        a = np.asarray(axis if axis is not None else (0.0, 0.0, 1.0), dtype=np.float64)
        return a / np.linalg.norm(a)

    def joint_limits(self, name: str) -> tuple[float, float]:
        """(lower, upper) of joint ``name`` (rad or m); a continuous joint or one without limits:
        (-pi, pi)."""
        joint = self.joints[name]
        if joint.type == "continuous" or joint.limit is None:
            return -math.pi, math.pi
        return float(joint.limit.lower), float(joint.limit.upper)

    def serial_chain(self, root: str, tip: str) -> pk.SerialChain:
        """The pytorch-kinematics ``SerialChain`` from ``root`` to ``tip`` (the reference in tests)."""
        import pytorch_kinematics as pk

        self.path_joints(root, tip)  # clear error first
        return pk.SerialChain(self.chain, tip, root)

    def _link_offset(self, link: str) -> np.ndarray:
        return origin_matrix(getattr(self.links[link], "origin", None))

    def chain_spec(self, root: str, tip: str, what: str = "chain") -> ChainSpec:
        """float64 constants of the serial chain from ``root`` to ``tip``.

        The frame sequence, joint types, axes and limits come from the pytorch-kinematics chain;
        joint origins are re-read from the URDF in float64.
        """
        self.path_joints(root, tip, what)
        sc = self.serial_chain(root, tip)
        frames = sc.get_frame_names(exclude_fixed=False)
        offsets, names, types, axes, lower, upper = [], [], [], [], [], []
        current = np.eye(4)
        for frame_name in frames[1:]:  # the root frame is the chain's origin
            frame = sc.find_frame(frame_name)
            urdf_joint = self.joints[frame.joint.name]
            current = current @ self._link_offset(frame_name) @ origin_matrix(urdf_joint.origin)
            if frame.joint.joint_type == "fixed":
                continue
            offsets.append(current)
            current = np.eye(4)
            names.append(frame.joint.name)
            types.append(frame.joint.joint_type)
            axes.append(self.joint_axis(urdf_joint.name))  # pytorch-kinematics' default too: z
            lo, hi = self.joint_limits(urdf_joint.name)
            lower.append(lo)
            upper.append(hi)
        offsets.append(current)
        n = len(names)
        return ChainSpec(root=root, tip=tip, joint_names=tuple(names), joint_types=tuple(types),
                         axes=np.asarray(axes, dtype=np.float64).reshape(n, 3),
                         offsets=np.stack(offsets), lower=np.asarray(lower, dtype=np.float64),
                         upper=np.asarray(upper, dtype=np.float64))
