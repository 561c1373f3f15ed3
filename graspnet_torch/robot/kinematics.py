"""A robot's batched kinematics entry points (:class:`Kinematics`, a part of
:class:`~graspnet_torch.robot.robot.Robot`): fingertips in their base frames, the palm and the
world, the palm frame and gripper points from the body joints, their Jacobians; every input's shape
checked. Frames and joint tensors: :mod:`graspnet_torch.robot.robot`."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.robot.fingers import FingerKernel
from graspnet_torch.robot.kernel import ChainKernel
from graspnet_torch.robot.shared import SharedJoints
from graspnet_torch.robot.structure import Finger
from graspnet_torch.robot.transforms import pose_to_rt, transform_points, untransform_points

__all__ = ["Kinematics"]


class Kinematics:
    """The kinematics methods of :class:`~graspnet_torch.robot.robot.Robot` (which builds the
    attributes below and ``finger_index``)."""

    name: str
    fingers: dict[str, Finger]
    finger_names: tuple[str, ...]
    finger_kernel: FingerKernel | None
    body_kernel: ChainKernel | None
    gripper_kernel: ChainKernel | None
    shared: SharedJoints
    n_fingers: int
    joints_per_finger: int
    body_joint_names: tuple[str, ...]
    _consts: dict[tuple, dict[str, Tensor]]

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

    def some_fingertips_world(self, palm_pose: Tensor, q: Tensor, rows: Sequence[int]) -> Tensor:
        """The tips of the fingers ``rows`` (their indices) in the world, the shared joints where
        they are held: :meth:`fingertips_world`'s rows ``rows``, bit for bit, for their share of
        its forward kinematics (:meth:`FingerKernel.select`).

        palm_pose: (..., 6); q: (..., F, n) -> (..., len(rows), 3).
        """
        self._check_pose(palm_pose)
        R, t = pose_to_rt(palm_pose)
        return transform_points(R.unsqueeze(-3), t.unsqueeze(-2), self.some_fingertips_palm(q, rows))

    def some_fingertips_palm(self, q: Tensor, rows: Sequence[int]) -> Tensor:
        """The tips of the fingers ``rows`` in the palm frame, the shared joints where they are held
        (:meth:`some_fingertips_world` before the palm's pose). q: (..., F, n) -> (..., len(rows), 3)."""
        self._check_fingers(q)
        rows = [int(k) for k in rows]
        c = self._const(q.dtype, q.device)
        base = self.finger_kernel.select(rows).position(q[..., rows, :])  # (..., k, 3)
        return transform_points(c["base_R"][rows], c["base_t"][rows], base)

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
