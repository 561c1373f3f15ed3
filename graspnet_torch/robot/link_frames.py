"""Every link's world pose in postures (:class:`LinkFrames`, a part of
:class:`~graspnet_torch.robot.robot.Robot`): pytorch-kinematics over the whole URDF, for pictures
and collision scenes (the hot loops use the robot's kernels)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.robot.chain import ChainSpec, UrdfModel
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.shared import SharedJoints
from graspnet_torch.robot.structure import Finger, Posture
from graspnet_torch.robot.transforms import pose_to_matrix

__all__ = ["LinkFrames"]


class LinkFrames:
    """The link-frame methods of :class:`~graspnet_torch.robot.robot.Robot` (which builds the
    attributes below; ``_shared_rows``: :class:`~graspnet_torch.robot.joint_files.JointValues`)."""

    cfg: RobotCfg
    urdf: UrdfModel
    fingers: dict[str, Finger]
    shared: SharedJoints
    body: ChainSpec | None
    body_joint_names: tuple[str, ...]

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
            root_to_palm = self.urdf.fixed_transform(self.urdf.root_link, self.cfg.palm_link)
            world = pose_to_matrix(palm_pose.detach().to(torch.float64).cpu()).numpy() @ np.linalg.inv(root_to_palm)
            frames = world[:, None] @ frames
        return links, frames
