"""The training sets of a finger's experts: every stored (fingertip, posture) pair, kept forever
(the paper's change to Oyama & Tachi, section 3.2), each owned by one expert."""

from __future__ import annotations

import torch
from torch import Tensor

from graspnet_torch.fcnn.experts import ExpertSet

__all__ = ["TrainingSet"]


class TrainingSet:
    """Growable buffers of points ``x`` (P, 3), postures ``q`` (P, n) and owners (P,).

    Args:
        n_joints: joints per posture.
        dtype: storage dtype of x and q.
    """

    def __init__(self, n_joints: int, dtype: torch.dtype = torch.float32, capacity: int = 4096):
        self.n_joints = n_joints
        self._x = torch.zeros(capacity, 3, dtype=dtype)
        self._q = torch.zeros(capacity, n_joints, dtype=dtype)
        self._owner = torch.zeros(capacity, dtype=torch.long)
        self.size = 0
        self._index: tuple[Tensor, Tensor, Tensor] | None = None  # sort order, counts, offsets

    @property
    def x(self) -> Tensor:
        return self._x[: self.size]

    @property
    def q(self) -> Tensor:
        return self._q[: self.size]

    @property
    def owner(self) -> Tensor:
        return self._owner[: self.size]

    def __len__(self) -> int:
        return self.size

    def add(self, x: Tensor, q: Tensor, owner: Tensor | int) -> None:
        """Append points. x: (P, 3); q: (P, n); owner: (P,) or one expert index."""
        P = x.shape[0]
        if P == 0:
            return
        if not isinstance(owner, Tensor) or owner.dim() == 0:
            owner = torch.as_tensor(owner, dtype=torch.long).expand(P)
        need = self.size + P
        if need > self._x.shape[0]:
            cap = max(need, 2 * self._x.shape[0])
            for name in ("_x", "_q", "_owner"):
                old = getattr(self, name)
                new = old.new_zeros((cap, *old.shape[1:]))
                new[: self.size] = old[: self.size]
                setattr(self, name, new)
        self._x[self.size:need] = x.to(self._x)
        self._q[self.size:need] = q.to(self._q)
        self._owner[self.size:need] = owner
        self.size = need
        self._index = None

    def counts(self, n_experts: int) -> Tensor:
        """(n_experts,) points owned by each expert."""
        return torch.bincount(self.owner, minlength=n_experts)[:n_experts]

    def _sorted(self, n_experts: int) -> tuple[Tensor, Tensor, Tensor]:
        if self._index is None or self._index[1].shape[0] != n_experts:
            order = torch.argsort(self.owner, stable=True)
            counts = self.counts(n_experts)
            offsets = torch.cumsum(counts, 0) - counts
            self._index = (order, counts, offsets)
        return self._index

    def sample(self, n_experts: int, m: int, generator: torch.Generator) -> tuple[Tensor, Tensor, Tensor]:
        """m points per expert, uniformly with replacement from its own set.

        Returns x: (E, m, 3), q: (E, m, n), has_data: (E,) bool (experts without points get
        arbitrary rows, to be masked out of the loss).
        """
        order, counts, offsets = self._sorted(n_experts)
        u = torch.rand(n_experts, m, generator=generator)
        local = torch.floor(u * counts.clamp(min=1).unsqueeze(1)).long()
        rows = order[(offsets.unsqueeze(1) + local).clamp(max=max(self.size - 1, 0))]
        return self._x[rows], self._q[rows], counts > 0

    @torch.no_grad()
    def reassign(self, experts: ExpertSet, chunk: int = 65536) -> int:
        """Move every point to the expert that fits it best: the one whose output for the
        point's fingertip is closest to the stored posture (normalised joint units).

        Returns the number of points that changed owner.
        """
        E = experts.n_active
        if self.size == 0 or E < 2:
            return 0
        new_owner = torch.empty_like(self.owner)
        for s in range(0, self.size, chunk):
            x, q = self.x[s:s + chunk], self.q[s:s + chunk]
            pred = experts.normalize_q(experts(x.float()))  # (E, c, n)
            err = (pred - experts.normalize_q(q.float()).unsqueeze(0)).square().mean(-1)
            new_owner[s:s + chunk] = torch.argmin(err, dim=0)
        moved = int((new_owner != self.owner).sum())
        self._owner[: self.size] = new_owner
        self._index = None
        return moved

    def state_dict(self) -> dict[str, Tensor]:
        return {"x": self.x.clone(), "q": self.q.clone(), "owner": self.owner.clone()}

    def load_state_dict(self, state: dict[str, Tensor]) -> None:
        self.size = 0
        self._index = None
        self.add(state["x"], state["q"], state["owner"])
