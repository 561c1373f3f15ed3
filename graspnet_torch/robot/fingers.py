"""A finger's chain seen through its free joints, and a batched kernel over fingers of any shape.

Real hands differ from the paper's 4-joint fingers in three ways, all handled here so that the
rest of the project keeps one layout, ``(..., F, n)``:

- **Mimic joints.** A URDF ``<mimic joint="L" multiplier="m" offset="b"/>`` joint follows its
  leader: ``q_mimic = m q_L + b``. It is not a free variable. With the finger's free joints
  ``q_free`` (n_f values) every movable joint of the chain is an affine function of them,

      q_all = A q_free + c,          A: (n_all, n_f), c: (n_all,),

  and, by the chain rule, the tip's Jacobian with respect to the free joints is
  ``J_free = J_all A``. Mimic joints of mimic joints compose; a leader outside the finger's chain
  is refused.
- **Different joint counts.** Fingers are padded to the largest count n: finger k's free joints
  fill slots ``0..n_k-1`` of ``q[..., k, :]``; the other slots are padding. Padding never moves
  anything: its Jacobian columns are exactly zero and its limits are [0, 0], so damped least
  squares, clamping and the FCNN (whose padded outputs are 0) all leave it at 0.
- **Tip offsets** are folded into the chain's last fixed transform by :class:`Robot`, so a
  ``ChainSpec``'s tip may be a point in the last link's frame.

Fingers whose full chains have the same sequence of joint types run as one stacked
:class:`~graspnet_torch.robot.kernel.ChainKernel`; a hand of identical fingers without mimic
joints (the shipped ``hand``) uses that kernel directly, with no overhead.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.robot.chain import ChainSpec
from graspnet_torch.robot.kernel import ChainKernel

__all__ = ["FingerChain", "FingerKernel"]


@dataclass(frozen=True)
class FingerChain:
    """A serial chain (every movable joint, mimic joints included) and its free joints.

    Attributes:
        spec: the whole chain from the finger's base to its tip (tip offset folded in).
        coupling: (n_all, n_f) A of ``q_all = A q_free + c`` (identity without mimic joints).
        coupling_offset: (n_all,) c.
        free: indices of the free joints among the chain's joints, in chain order.
        lower, upper: (n_f,) limits of the free joints (rad or m): the joint's own limits,
            narrowed so that every joint that follows it stays within its own limits too.
    """

    spec: ChainSpec
    coupling: np.ndarray
    coupling_offset: np.ndarray
    free: tuple[int, ...]
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def from_spec(cls, spec: ChainSpec, mimic: dict[str, tuple[str, float, float]] | None = None,
                  what: str = "finger") -> FingerChain:
        """From a chain and its mimic joints: name -> (leader, multiplier, offset).

        Raises ValueError (with ``what`` in the message) for a leader outside the chain, a cycle
        of mimic joints or a free joint whose range is empty or a single value.
        """
        mimic = {k: v for k, v in (mimic or {}).items() if k in spec.joint_names}
        names = spec.joint_names
        index = {name: i for i, name in enumerate(names)}
        for joint, (leader, _m, _b) in mimic.items():
            if leader not in index:
                raise ValueError(f"{what}: mimic joint '{joint}' follows '{leader}', which is not a joint of "
                                 f"this finger's chain ({', '.join(names)})")
        free = tuple(i for i, name in enumerate(names) if name not in mimic)
        n_all, n_f = len(names), len(free)
        A, c = np.zeros((n_all, n_f)), np.zeros(n_all)
        col = {i: k for k, i in enumerate(free)}

        def resolve(i: int, seen: tuple[int, ...] = ()) -> tuple[np.ndarray, float]:
            if i in seen:
                raise ValueError(f"{what}: mimic joints {', '.join(names[j] for j in seen)} form a cycle")
            if i in col:
                row = np.zeros(n_f)
                row[col[i]] = 1.0
                return row, 0.0
            leader, m, b = mimic[names[i]]
            row, off = resolve(index[leader], (*seen, i))
            return m * row, m * off + b

        for i in range(n_all):
            A[i], c[i] = resolve(i)
        lower, upper = spec.lower[list(free)].copy(), spec.upper[list(free)].copy()
        for i in range(n_all):  # a joint driven by one free joint: keep it within its own limits
            nz = np.nonzero(A[i])[0]
            if i in col or nz.size != 1:
                continue
            k, m = int(nz[0]), float(A[i, nz[0]])
            lo, hi = sorted(((spec.lower[i] - c[i]) / m, (spec.upper[i] - c[i]) / m))
            if max(lower[k], lo) <= min(upper[k], hi):  # never empty the range (inconsistent URDF limits)
                lower[k], upper[k] = max(lower[k], lo), min(upper[k], hi)
        stuck = [k for k in range(n_f) if not lower[k] < upper[k]]
        if stuck:  # nothing to learn or search: the FCNN's training data would be empty
            k = stuck[0]
            raise ValueError(f"{what}: joint '{names[free[k]]}' cannot move (its <limit> range, within the limits of "
                             f"the joints that follow it, is [{lower[k]:g}, {upper[k]:g}]); make it a fixed joint or "
                             f"widen its limits")
        return cls(spec, A, c, free, lower, upper)

    # ------------------------------------------------------------------ the free joints
    @property
    def root(self) -> str:
        return self.spec.root

    @property
    def tip(self) -> str:
        return self.spec.tip

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The free joints, in chain order."""
        return tuple(self.spec.joint_names[i] for i in self.free)

    @property
    def joint_types(self) -> tuple[str, ...]:
        return tuple(self.spec.joint_types[i] for i in self.free)

    @property
    def n_joints(self) -> int:
        """Free joints (what the FCNN learns and the solver chooses)."""
        return len(self.free)

    @property
    def all_joint_names(self) -> tuple[str, ...]:
        """Every movable joint of the chain, mimic joints included, in chain order."""
        return self.spec.joint_names

    @property
    def mimic_joint_names(self) -> tuple[str, ...]:
        return tuple(n for i, n in enumerate(self.spec.joint_names) if i not in self.free)

    @cached_property
    def identity(self) -> bool:
        """True when every joint is free (no coupling to apply)."""
        return self.n_joints == self.spec.n_joints

    def expand(self, q: np.ndarray) -> np.ndarray:
        """Every joint from the free ones (float64 reference). q: (..., n_f) -> (..., n_all)."""
        q = np.asarray(q, dtype=np.float64)
        return q @ self.coupling.T + self.coupling_offset

    def transform(self, q: np.ndarray) -> np.ndarray:
        """Reference evaluation: free joints (n_f,) -> (4, 4) tip pose in the finger's base frame."""
        return self.spec.transform(self.expand(q))


@dataclass
class _Group:
    """Fingers whose full chains share their joint types: one stacked kernel."""

    idx: list[int]
    kernel: ChainKernel
    A: np.ndarray  # (Kg, n_all, n): coupling padded to the stack's width
    c: np.ndarray  # (Kg, n_all)
    plain: bool  # A = [I 0], c = 0: q_all is the first n_all slots
    cache: dict


class FingerKernel:
    """Batched fingertip positions and Jacobians over the free joints of one or more fingers.

    ``FingerKernel(chain)`` (a :class:`FingerChain`, or a ``ChainSpec``: every joint free) takes
    joints ``(..., n_f)``; ``FingerKernel([chains])`` takes ``(..., K, n)``, n = ``width`` or the
    largest free-joint count (fingers with fewer are padded, see the module docstring). Outputs are in each
    finger's base frame and in the dtype/device of q.
    """

    def __init__(self, chains: FingerChain | ChainSpec | Sequence[FingerChain | ChainSpec], width: int | None = None):
        self.stacked = not isinstance(chains, FingerChain | ChainSpec)
        given = chains if self.stacked else (chains,)
        self.chains: tuple[FingerChain, ...] = tuple(c if isinstance(c, FingerChain) else FingerChain.from_spec(c)
                                                     for c in given)
        if not self.chains:
            raise ValueError("FingerKernel needs at least one finger")
        self.num_chains = len(self.chains)
        self.n_joints = max([c.n_joints for c in self.chains] + [width or 0])
        by_types: dict[tuple[str, ...], list[int]] = {}
        for k, c in enumerate(self.chains):
            by_types.setdefault(c.spec.joint_types, []).append(k)
        self._groups: list[_Group] = []
        n = self.n_joints
        for types, idx in by_types.items():
            specs = [self.chains[k].spec for k in idx]
            A = np.zeros((len(idx), len(types), n))
            for g, k in enumerate(idx):
                A[g, :, : self.chains[k].n_joints] = self.chains[k].coupling
            c = np.stack([self.chains[k].coupling_offset for k in idx])
            plain = all(self.chains[k].identity for k in idx)
            kernel = ChainKernel(specs if self.stacked else specs[0])
            self._groups.append(_Group(idx, kernel, A, c, plain, {}))
        self._finish()

    def _finish(self) -> None:
        order = [k for g in self._groups for k in g.idx]
        self._inverse = torch.as_tensor(np.argsort(order))
        only = self._groups[0]
        # one group, no mimic joint, no padding: the stacked kernel itself
        self._direct = (only.kernel if len(self._groups) == 1 and only.plain and only.kernel.n_joints == self.n_joints
                        else None)
        self._selected: dict[tuple[int, ...], FingerKernel] = {}

    def select(self, fingers: Sequence[int]) -> FingerKernel:
        """The kernel of the fingers ``fingers`` (indices of this stacked kernel's chains, in that
        order; joints ``(..., len(fingers), n)``, n as here), the same object for the same indices:
        a robot's kernel built once serves every subset of its fingers. Made from this kernel's
        parts (:meth:`~graspnet_torch.robot.kernel.ChainKernel.rows`); its results are those of
        ``FingerKernel([chains[k] for k in fingers], width=n)``, bit for bit."""
        key = tuple(int(k) for k in fingers)
        sub = self._selected.get(key)
        if sub is not None:
            return sub
        if not self.stacked or not key or min(key) < 0 or max(key) >= self.num_chains:
            raise ValueError(f"select: fingers {list(key)} of a stacked kernel of {self.num_chains} finger(s)")
        sub = object.__new__(FingerKernel)
        sub.stacked, sub.num_chains, sub.n_joints = True, len(key), self.n_joints
        sub.chains = tuple(self.chains[k] for k in key)
        group_of = {k: (g, row) for g in self._groups for row, k in enumerate(g.idx)}
        by_types: dict[tuple[str, ...], list[int]] = {}  # as the constructor groups them: first appearance
        for pos, k in enumerate(key):
            by_types.setdefault(self.chains[k].spec.joint_types, []).append(pos)
        sub._groups = []
        for idx in by_types.values():
            g = group_of[key[idx[0]]][0]
            rows = [group_of[key[pos]][1] for pos in idx]
            sub._groups.append(_Group(idx, g.kernel.rows(rows), g.A[rows], g.c[rows],
                                      all(sub.chains[pos].identity for pos in idx), {}))
        sub._finish()
        self._selected[key] = sub
        return sub

    def chain_kernel(self, fingers: Sequence[int]) -> ChainKernel:
        """The :class:`ChainKernel` of the full chains of ``fingers`` (indices of this stacked
        kernel's chains, in that order, all with the same joint types: joints ``(..., len(fingers),
        n_all)``), made from this kernel's parts (:meth:`ChainKernel.rows`, the same object for the
        same rows): FK and Jacobians of a subset of a robot's fingers without tracing them anew."""
        group_of = {k: (g, row) for g in self._groups for row, k in enumerate(g.idx)}
        key = [int(k) for k in fingers]
        if not self.stacked or not key or any(k not in group_of for k in key):
            raise ValueError(f"chain_kernel: fingers {key} of a stacked kernel of {self.num_chains} finger(s)")
        groups = {id(group_of[k][0]) for k in key}
        if len(groups) > 1:
            raise ValueError(f"chain_kernel: fingers {key} differ in their joint types")
        return group_of[key[0]][0].kernel.rows([group_of[k][1] for k in key])

    @property
    def specs(self) -> tuple[ChainSpec, ...]:
        return tuple(c.spec for c in self.chains)

    def _check(self, q: Tensor) -> None:
        if not isinstance(q, Tensor) or not q.is_floating_point():
            raise TypeError(f"finger joints must be a floating-point torch.Tensor, got "
                            f"{q.dtype if isinstance(q, Tensor) else type(q).__name__}")
        want = (self.num_chains, self.n_joints) if self.stacked else (self.n_joints,)
        if q.dim() < len(want) or tuple(q.shape[q.dim() - len(want):]) != want:
            shape = "(..., " + ", ".join(map(str, want)) + ")"
            raise ValueError(f"finger joints must have shape {shape} for finger(s) ending at "
                             f"{', '.join(c.tip for c in self.chains)}; got {tuple(q.shape)}")

    def _consts(self, g: _Group, q: Tensor) -> tuple[Tensor, Tensor]:
        key = (q.dtype, q.device)
        if key not in g.cache:
            g.cache[key] = (torch.as_tensor(g.A, dtype=q.dtype, device=q.device),
                            torch.as_tensor(g.c, dtype=q.dtype, device=q.device))
        return g.cache[key]

    def _select(self, g: _Group, q: Tensor) -> Tensor:
        """The group's fingers' full joints: (..., [K,] n) -> (..., Kg, n_all) (stacked) or (..., n_all)."""
        if self.stacked and len(self._groups) > 1:
            q = q.index_select(-2, torch.as_tensor(g.idx, device=q.device))
        n_all = g.A.shape[1]
        if g.plain:
            return q[..., :n_all]
        A, c = self._consts(g, q)
        if not self.stacked:
            return q @ A[0].T + c[0]
        return torch.einsum("kan,...kn->...ka", A, q) + c

    def _join(self, parts: list[Tensor], dim: int) -> Tensor:
        if len(parts) == 1:
            return parts[0]
        out = torch.cat(parts, dim=dim)
        return out.index_select(dim, self._inverse.to(out.device))

    def position(self, q: Tensor) -> Tensor:
        """Fingertips. q: (..., [K,] n) -> (..., [K,] 3)."""
        if self._direct is not None:
            return self._direct.position(q)
        self._check(q)
        return self._join([g.kernel.position(self._select(g, q)) for g in self._groups], -2)

    def position_jacobian(self, q: Tensor) -> tuple[Tensor, Tensor]:
        """Fingertips and d tip / d q_free (zero columns for padding).

        q: (..., [K,] n) -> p: (..., [K,] 3), J: (..., [K,] 3, n).
        """
        if self._direct is not None:
            return self._direct.position_jacobian(q)
        self._check(q)
        ps, Js = [], []
        n = self.n_joints
        for g in self._groups:
            p, J = g.kernel.position_jacobian(self._select(g, q))
            if g.plain:
                J = torch.nn.functional.pad(J, (0, n - J.shape[-1]))
            else:
                A, _ = self._consts(g, q)
                J = J @ (A if self.stacked else A[0])
            ps.append(p)
            Js.append(J)
        return self._join(ps, -2), self._join(Js, -3)

    def __repr__(self) -> str:
        tips = ", ".join(c.tip for c in self.chains)
        return (f"FingerKernel({self.num_chains} finger(s) -> {tips}; {self.n_joints} free joints; "
                f"{len(self._groups)} group(s))")
