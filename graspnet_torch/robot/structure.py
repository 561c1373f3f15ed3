"""What a robot is made of and the configurations it takes: :class:`Finger` (a finger's chain and
where its base sits on the palm) and :class:`Posture` (a whole-robot configuration), shared by the
robot's modules (:mod:`graspnet_torch.robot.robot` re-exports both)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from torch import Tensor

from graspnet_torch.robot.fingers import FingerChain

__all__ = ["Finger", "Posture"]


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
