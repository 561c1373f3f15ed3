"""Every link's world pose in postures (:class:`LinkFrames`, a part of
:class:`~graspnet_torch.robot.robot.Robot`): the whole URDF tree as one
:class:`~graspnet_torch.robot.kernel.TreeKernel` (batched, float64), for pictures, collision
scenes, the viewer and reach. pytorch-kinematics is the oracle in the tests only."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.robot.chain import ChainSpec, UrdfModel, origin_matrix
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.kernel import TreeKernel
from graspnet_torch.robot.shared import SharedJoints
from graspnet_torch.robot.structure import Finger, Posture
from graspnet_torch.robot.transforms import pose_to_matrix

__all__ = ["LinkFrames", "LinkTree", "link_tree"]

_TYPES = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic"}


@dataclass(frozen=True)
class LinkTree:
    """A URDF's links and movable joints as a :class:`TreeKernel`.

    Attributes:
        links: every link, depth first from the root, children in the URDF's joint order
            (pytorch-kinematics' frame order).
        joints: the movable joints (the kernel's joint order), each after its parent.
        kernel: joints (B, len(joints)) -> the links' frames (B, len(links), 4, 4) in the root.
    """

    links: tuple[str, ...]
    joints: tuple[str, ...]
    kernel: TreeKernel


def link_tree(urdf: UrdfModel) -> LinkTree:
    """The tree of ``urdf``: a link's frame is its parent's times its link origin, its joint's
    origin and the joint's motion (pytorch-kinematics' convention; the root's: its link origin)."""
    children: dict[str, list] = {}
    for j in urdf.robot.joints:
        children.setdefault(j.parent, []).append(j)

    def offset(link: str) -> np.ndarray:
        return origin_matrix(getattr(urdf.links[link], "origin", None))

    root = urdf.root_link
    links, attach, poses = [root], [-1], [offset(root)]
    joints, parents, types, axes, offsets = [], [], [], [], []
    stack = [(j, 0) for j in reversed(children.get(root, []))]
    while stack:  # depth first, children in joint order
        j, up = stack.pop()  # up: the parent link's index in ``links``
        step = offset(j.child) @ origin_matrix(j.origin)
        if j.type in _TYPES:
            parents.append(attach[up])
            offsets.append(poses[up] @ step)
            joints.append(j.name)
            types.append(_TYPES[j.type])
            axes.append(urdf.joint_axis(j.name))
            attach.append(len(joints) - 1)
            poses.append(np.eye(4))
        else:
            attach.append(attach[up])
            poses.append(poses[up] @ step)
        links.append(j.child)
        stack.extend((c, len(links) - 1) for c in reversed(children.get(j.child, [])))
    kernel = TreeKernel(parents, types, np.asarray(axes).reshape(-1, 3), np.asarray(offsets).reshape(-1, 4, 4),
                        attach, np.stack(poses))
    return LinkTree(tuple(links), tuple(joints), kernel)


class LinkFrames:
    """The link-frame methods of :class:`~graspnet_torch.robot.robot.Robot` (which builds the
    attributes below; ``_shared_rows``: :class:`~graspnet_torch.robot.joint_files.JointValues`)."""

    cfg: RobotCfg
    urdf: UrdfModel
    fingers: dict[str, Finger]
    shared: SharedJoints
    body: ChainSpec | None
    body_joint_names: tuple[str, ...]
    wrist: dict[str, float]

    def root_to_palm(self) -> np.ndarray:
        """(4, 4) float64 pose of ``palm_link`` in the URDF root link of a free hand, its wrist
        joints (those between them) held where :attr:`wrist` says: the links above the palm are
        rigid with it there. A robot with a body has no such pose (its body joints move the palm)."""
        if "_root_to_palm" not in self.__dict__:
            self._root_to_palm = self.urdf.transform_at(self.urdf.root_link, self.cfg.palm_link, self.wrist,
                                                        f"{self.cfg.source}: palm_link")
        return self._root_to_palm

    def link_frames(self, posture: Posture) -> dict[str, np.ndarray]:
        """(4, 4) float64 world pose of every link (the tree kernel; pictures, collision scenes)."""
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

    def points_on_links(self, links: list[str], frames: np.ndarray, names: Sequence[str],
                        offsets: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """From link frames (B, L, 4, 4) of ``links`` (:meth:`link_frames_array`): the rotations
        R (B, k, 3, 3) of the links ``names`` and the points ``offsets`` (k, 3) fixed in them, in
        the world (B, k, 3) (None: the links' origins)."""
        at = frames[:, [links.index(name) for name in names]]  # (B, k, 4, 4)
        R, origin = at[..., :3, :3], at[..., :3, 3]
        return R, origin if offsets is None else np.einsum("bkij,kj->bki", R, offsets) + origin

    def tip_frames_at(self, links: list[str], frames: np.ndarray, fingers: Sequence[str]
                      ) -> tuple[np.ndarray, np.ndarray]:
        """The tip frames of ``fingers`` from link frames (B, L, 4, 4) of ``links``: R (B, k, 3, 3),
        t (B, k, 3) (a tip offset moves the origin, not the axes)."""
        cfgs = [self.cfg.fingers[f] for f in fingers]
        offsets = np.array([(0.0, 0.0, 0.0) if c.tip_offset is None else c.tip_offset for c in cfgs], dtype=np.float64)
        return self.points_on_links(links, frames, [c.tip for c in cfgs], offsets)

    def link_frames_of(self, body: Tensor | None, fingers: Tensor, palm_pose: Tensor | None = None,
                       shared: Tensor | np.ndarray | None = None) -> tuple[list[str], np.ndarray]:
        """The links' names and world poses (B, L, 4, 4) float64 from joints: body (B, m) (a robot
        with a body; else None), fingers (B, F, n) free joints (padded), palm_pose (B, 6) (a free
        hand's), shared (B, S) (default: where they are held). A free hand's wrist joints are
        held where :attr:`wrist` says, the links above its palm placed by :meth:`root_to_palm`."""
        if "_link_tree" not in self.__dict__:  # the tree, and where each of its joints' values comes from, once
            self._link_tree = link_tree(self.urdf)
            self._joint_columns = self._joint_sources(self._link_tree.joints)
        tree, names = self._link_tree, self._link_tree.joints
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
            elif kind == "wrist":
                th[:, c] = self.wrist[names[c]]
            elif kind == "shared":
                leader, m, b = self.shared.followers.get(names[c], (names[c], 1.0, 0.0))
                th[:, c] = m * s[:, index[leader]] + b
        frames = tree.kernel.frames(torch.as_tensor(th)).numpy()
        if self.body is None:
            palm = pose_to_matrix(palm_pose.detach().to(torch.float64).cpu()).numpy()
            world = palm @ np.linalg.inv(self.root_to_palm())
            frames = world[:, None] @ frames
        return list(tree.links), frames

    def _joint_sources(self, names: Sequence[str]) -> list[tuple[str, int, int]]:
        """Where each joint's value comes from: ('body', column, 0), ('finger', finger, joint of its
        whole chain), ('wrist', 0, 0) (:attr:`wrist`), ('shared', 0, 0) (a shared joint or a
        follower) or ('none', 0, 0) (held at 0)."""
        body_names = list(self.body_joint_names) if self.body is not None else []
        sources = []
        for name in names:
            if name in body_names:
                sources.append(("body", body_names.index(name), 0))
                continue
            if name in self.wrist:
                sources.append(("wrist", 0, 0))
                continue
            for k, f in enumerate(self.fingers.values()):
                if name in f.chain.all_joint_names:
                    sources.append(("finger", k, f.chain.all_joint_names.index(name)))
                    break
            else:
                sources.append(("shared", 0, 0) if name in self.shared.names or name in self.shared.followers
                               else ("none", 0, 0))
        return sources
