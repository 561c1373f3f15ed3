"""A robot's joint values by name and in file units (:class:`JointValues`, a part of
:class:`~graspnet_torch.robot.robot.Robot`): every movable joint of each finger (the joints fingers
share and mimic joints included) from the free joints and back, degrees (revolute) or metres
(prismatic) in the files people read and write, radians inside."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.robot.chain import ChainSpec
from graspnet_torch.robot.shared import SharedJoints
from graspnet_torch.robot.structure import Finger, Posture

__all__ = ["JointValues"]


class JointValues:
    """The joint-value methods of :class:`~graspnet_torch.robot.robot.Robot` (which builds the
    attributes below)."""

    fingers: dict[str, Finger]
    shared: SharedJoints
    shared_reference: np.ndarray
    body: ChainSpec | None
    n_fingers: int
    joints_per_finger: int
    body_joint_names: tuple[str, ...]
    body_joint_types: tuple[str, ...]
    wrist: dict[str, float]

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
        """The inverse of :meth:`body_joints_to_file`: (m,) float64 (rad or m); a robot without a
        body: (0,)."""
        d = math.pi / 180
        return torch.tensor([values[n] * (d if t == "revolute" else 1.0)
                             for n, t in zip(self.body_joint_names, self.body_joint_types, strict=True)],
                            dtype=torch.float64)

    def joint_values(self, posture: Posture) -> dict[str, float]:
        """Every movable URDF joint's value in a posture (radians / metres), mimic joints at their
        coupled values, joints shared by several fingers where they are held
        (:attr:`shared_reference`), a free hand's wrist joints where they are held (:attr:`wrist`)."""
        out = dict(zip(self.body_joint_names, posture.body.tolist(), strict=True)) | self.wrist
        out.update(self.shared.joint_values(self._shared_rows(posture.shared, 1)[0]))
        for name, values in self.finger_joint_values(posture.fingers, posture.shared).items():
            out.update(zip(self.finger_all_joint_names(name), values, strict=True))
        return out
