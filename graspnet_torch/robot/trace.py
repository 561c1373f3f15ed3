"""The straight-line program behind :class:`~graspnet_torch.robot.kernel.ChainKernel`'s traced route.

A stack of K chains with the same joint types (axes folded onto z, see the kernel's module
docstring) is evaluated once, symbolically, over "structure of arrays" registers of shape (K, B):
registers ``0..n-1`` hold cos(q_i), ``n..2n-1`` sin(q_i) and ``2n..3n-1`` q_i. Each value is a
register or a constant (one float64 per chain, (K,)). Entries that are exactly 0 or 1, or equal
across the stack, are folded at trace time; a coefficient that differs between chains lives in a
table of (K,) arrays. :func:`compile_program` removes the dead code of an output mode and binds
the table to a dtype and device.

Every folding decision is a test of a (K,) array (is it all zero? equal across the stack?);
the trace keeps these arrays (:attr:`Trace.decisions`). A subset of the chains folds exactly as
the whole stack does when each test gives the same answer on the subset's rows; then the
subset's trace is the stack's with its coefficient rows selected (:meth:`Trace.rows`), the same
instructions on the same values: the same results, bit for bit, as tracing the subset anew.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

__all__ = ["Program", "Trace", "compile_program", "snap", "trace_chain"]

_SNAP = 1e-12  # constants within this of 0 or +-1 are made exact


def snap(a: np.ndarray) -> np.ndarray:
    """Entries within 1e-12 of 0, 1 or -1 made exact."""
    a = np.where(np.abs(a) < _SNAP, 0.0, a)
    a = np.where(np.abs(a - 1.0) < _SNAP, 1.0, a)
    return np.where(np.abs(a + 1.0) < _SNAP, -1.0, a)


class _Const:
    """A value that does not depend on q: one float64 number per chain of the stack, (K,)."""

    __slots__ = ("v",)

    def __init__(self, v: np.ndarray):
        self.v = v


@dataclass
class _Instr:
    dst: int
    op: str  # mul | scale | axpy | addmul | addc
    srcs: tuple[int, ...]
    coef: int | None = None  # index into the coefficient table
    value: float = 1.0


@dataclass
class Trace:
    """The traced program: instructions over registers 0..n_regs-1.

    Attributes:
        coefs: the coefficient table, (K,) per-chain arrays.
        outputs: name ('p', 'R', 'Jv', 'Jw') -> register ids or constants.
        decisions: (M, K) every array a folding decision tested (see the module docstring).
    """

    n: int
    n_regs: int = 0
    instrs: list[_Instr] = field(default_factory=list)
    coefs: list[np.ndarray] = field(default_factory=list)
    outputs: dict[str, list] = field(default_factory=dict)
    tested: list[np.ndarray] = field(default_factory=list)
    decisions: np.ndarray | None = None

    def coef(self, c: np.ndarray) -> tuple[int | None, float]:
        """A coefficient as a python float when equal across the stack, else a table index."""
        if np.all(c == c[0]):
            return None, float(c[0])
        self.coefs.append(c)
        return len(self.coefs) - 1, 1.0

    def emit(self, op: str, srcs: tuple[int, ...], c: np.ndarray | None = None, value: float = 1.0) -> int:
        coef = None
        if c is not None:
            coef, value = self.coef(c)
        dst = self.n_regs
        self.n_regs += 1
        self.instrs.append(_Instr(dst, op, srcs, coef, value))
        return dst

    def folds_alike(self, rows: Sequence[int]) -> bool:
        """Whether the chains ``rows`` alone fold as the whole stack does (every decision the same)."""
        D = self.decisions
        if D is None or D.shape[0] == 0:
            return True
        sub = D[:, list(rows)]
        return bool(np.array_equal((D != 0).any(1), (sub != 0).any(1))
                    and np.array_equal((D == D[:, :1]).all(1), (sub == sub[:, :1]).all(1)))

    def rows(self, rows: Sequence[int]) -> Trace:
        """The trace of the chains ``rows`` (in that order) where they fold alike
        (:meth:`folds_alike`): the same instructions, coefficients and constants at those rows."""
        r = list(rows)
        outputs = {k: [v if isinstance(v, int) else _Const(v.v[r]) for v in vals] for k, vals in self.outputs.items()}
        return Trace(self.n, self.n_regs, self.instrs, [c[r] for c in self.coefs], outputs,
                     decisions=None if self.decisions is None else self.decisions[:, r])


class _Tracer:
    """Symbolic evaluation of the chain over registers, with constant folding."""

    def __init__(self, K: int, n: int):
        self.K = K
        self.t = Trace(n=n, n_regs=3 * n)

    def const(self, v) -> _Const:
        return _Const(snap(np.broadcast_to(np.asarray(v, dtype=np.float64), (self.K,)).copy()))

    # terms: list of (coef (K,), factors: tuple of 1 or 2 registers); c0: constant part
    @staticmethod
    def prod(a, b, sign: float = 1.0) -> tuple[np.ndarray | float, list]:
        if isinstance(a, _Const) and isinstance(b, _Const):
            return sign * a.v * b.v, []
        if isinstance(a, _Const):
            return 0.0, [(sign * a.v, (b,))]
        if isinstance(b, _Const):
            return 0.0, [(sign * b.v, (a,))]
        return 0.0, [(np.full(1, sign), tuple(sorted((a, b))))]

    @staticmethod
    def lin(coef, a) -> tuple[np.ndarray | float, list]:
        if isinstance(a, _Const):
            return coef * a.v, []
        return 0.0, [(np.asarray(coef, dtype=np.float64) * np.ones(1), (a,))]

    def sum(self, parts: Sequence[tuple]) -> int | _Const:
        """Materialise a sum of ``prod``/``lin`` results; returns a register or a constant."""
        c0 = np.zeros(self.K)
        merged: dict[tuple[int, ...], np.ndarray] = {}
        for const, terms in parts:
            c0 = c0 + const
            for coef, factors in terms:
                merged[factors] = merged.get(factors, np.zeros(self.K)) + coef
        items = [(f, snap(np.broadcast_to(c, (self.K,)).copy())) for f, c in merged.items()]
        c0 = snap(c0)
        self.t.tested.extend([c for _, c in items] + [c0])  # every decision below tests one of these
        items = [(f, c) for f, c in items if np.any(c)]
        if not items:
            return _Const(c0)

        def cost(item):  # start with a free alias, then a scalar product
            f, c = item
            uniform = np.all(c == c[0])
            return (0 if (len(f) == 1 and uniform and c[0] == 1.0) else 1 if uniform else 2)

        items.sort(key=cost)
        (f, c), rest = items[0], items[1:]
        if len(f) == 1:
            acc = f[0] if np.all(c == 1.0) else self.t.emit("scale", f, c)
        else:
            acc = self.t.emit("mul", f)
            if not np.all(c == 1.0):
                acc = self.t.emit("scale", (acc,), c)
        for f, c in rest:
            if len(f) == 1:
                acc = self.t.emit("axpy", (acc, f[0]), c)
            elif np.all(c == c[0]):
                acc = self.t.emit("addmul", (acc, *f), value=float(c[0]))
            else:
                scaled = self.t.emit("scale", (f[0],), c)
                acc = self.t.emit("addmul", (acc, scaled, f[1]), value=1.0)
        if np.any(c0):
            acc = self.t.emit("addc", (acc,), c0)
        return acc


def trace_chain(offsets: np.ndarray, types: tuple[str, ...]) -> Trace:
    """Trace T = G_0 M_0 G_1 ... M_{n-1} G_n; offsets: (K, n+1, 4, 4) with axes folded in."""
    K, n = offsets.shape[0], len(types)
    tr = _Tracer(K, n)
    R = [[tr.const(offsets[:, 0, r, c]) for c in range(3)] for r in range(3)]  # R[row][col]
    p = [tr.const(offsets[:, 0, r, 3]) for r in range(3)]
    z_axes, origins = [], []
    for i, kind in enumerate(types):
        z_axes.append([R[r][2] for r in range(3)])
        origins.append(list(p))
        if kind == "revolute":
            cos_i, sin_i = i, n + i
            u = [tr.sum([tr.prod(cos_i, R[r][0]), tr.prod(sin_i, R[r][1])]) for r in range(3)]
            v = [tr.sum([tr.prod(cos_i, R[r][1]), tr.prod(sin_i, R[r][0], -1.0)]) for r in range(3)]
            R = [[u[r], v[r], R[r][2]] for r in range(3)]
        else:
            q_i = 2 * n + i
            p = [tr.sum([tr.lin(1.0, p[r]), tr.prod(q_i, R[r][2])]) for r in range(3)]
        G = offsets[:, i + 1]
        p = [tr.sum([tr.lin(1.0, p[r])] + [tr.lin(G[:, k, 3], R[r][k]) for k in range(3)]) for r in range(3)]
        R = [[tr.sum([tr.lin(G[:, k, c], R[r][k]) for k in range(3)]) for c in range(3)] for r in range(3)]
    jv, jw = [], []
    for i, kind in enumerate(types):
        z = z_axes[i]
        if kind == "revolute":
            d = [tr.sum([tr.lin(1.0, p[r]), tr.lin(-1.0, origins[i][r])]) for r in range(3)]
            jv.append([tr.sum([tr.prod(z[(r + 1) % 3], d[(r + 2) % 3]), tr.prod(z[(r + 2) % 3], d[(r + 1) % 3], -1.0)])
                       for r in range(3)])
            jw.append(z)
        else:
            jv.append(z)
            jw.append([tr.const(0.0)] * 3)
    tr.t.outputs = {
        "p": p,
        "R": [R[r][c] for r in range(3) for c in range(3)],
        "Jv": [jv[i][r] for r in range(3) for i in range(n)],  # row-major (3, n)
        "Jw": [jw[i][r] for r in range(3) for i in range(n)],
    }
    tr.t.decisions = np.stack(tr.t.tested) if tr.t.tested else np.zeros((0, K))
    tr.t.tested = []
    return tr.t


@dataclass
class Program:
    """A dead-code-eliminated trace bound to a dtype/device: ``steps`` run on the register list."""

    n_regs: int
    steps: list[tuple[int, Callable[[list], Tensor]]]
    outputs: list  # register ids or (K, 1) constant tensors
    n_ops: int


def _bind(instr: _Instr, coefs: list[Tensor]) -> Callable[[list], Tensor]:
    s, v = instr.srcs, instr.value
    c = coefs[instr.coef] if instr.coef is not None else v
    if instr.op == "mul":
        a, b = s
        return lambda r: r[a] * r[b]
    if instr.op == "scale":
        (a,) = s
        return lambda r: r[a] * c
    if instr.op == "axpy":
        a, b = s
        if instr.coef is None:
            return lambda r: torch.add(r[a], r[b], alpha=v)
        return lambda r: torch.addcmul(r[a], r[b], c)
    if instr.op == "addmul":
        a, b, d = s
        return lambda r: torch.addcmul(r[a], r[b], r[d], value=v)
    if instr.op == "addc":
        (a,) = s
        return lambda r: r[a] + c
    raise AssertionError(instr.op)


def compile_program(tr: Trace, outputs: tuple[str, ...], dtype: torch.dtype, device: torch.device) -> Program:
    """The instructions ``outputs`` need (dead code removed), bound to ``dtype`` and ``device``."""
    values = [v for name in outputs for v in tr.outputs[name]]
    live = {v for v in values if isinstance(v, int)}
    kept = []
    for ins in reversed(tr.instrs):  # dead-code elimination
        if ins.dst in live:
            kept.append(ins)
            live.update(ins.srcs)
    kept.reverse()
    coefs = [torch.as_tensor(c, dtype=dtype, device=device).reshape(-1, 1) for c in tr.coefs]
    steps = [(ins.dst, _bind(ins, coefs)) for ins in kept]
    outs = [v if isinstance(v, int) else torch.as_tensor(v.v, dtype=dtype, device=device).reshape(-1, 1)
            for v in values]
    return Program(tr.n_regs, steps, outs, len(kept))
