"""A batched forward-kinematics / Jacobian kernel compiled from serial-chain constants.

Generic for any serial chain of revolute and prismatic joints, and for a *stack* of K chains that
share their sequence of joint types (e.g. all fingers of a hand, evaluated in one call).

How it works. Each joint axis is first rotated onto the local z axis by folding a constant
rotation ``A_i`` (``A_i e_z = axis_i``; an exact signed permutation when the axis is a coordinate
axis) into the neighbouring fixed transforms, so that every joint motion is ``Rz(q)`` or
``Tz(q)``. The chain is then traced once, symbolically, over "structure of arrays" registers of
shape (K, B): for a revolute joint, with c = cos q and s = sin q, the rotation's columns u, v mix

    u' = c u + s v,      v' = c v - s u,

and the fixed transforms that follow are applied as ``p += R' t`` and ``R = R' C``. Entries that
are exactly 0 or 1, or equal across the stack, are folded at trace time (a URDF's axes and
offsets are mostly zeros, so most of the 3x3 products vanish), and dead code is removed for each
output mode. The geometric Jacobian uses ``J_v,i = z_i x (p - o_i)``, ``J_w,i = z_i`` (revolute) and
``J_v,i = z_i`` (prismatic), where ``z_i``, ``o_i`` are joint i's axis and origin in the root frame.

The result is a straight-line program of elementwise torch ops on contiguous (K, B) tensors: fast
at large batch (memory-bound, no 3x3 bmm) and differentiable by autograd. It is checked against
pytorch-kinematics in the tests.

Small batches are bound by the number of ops, not by arithmetic, so for short chains (n <= 5) and
small batches positions and Jacobians take a second, exact route: with the basis (1, cos q_i,
sin q_i) of each revolute joint (1, q_i of a prismatic one), the tip position is *multilinear*,

    p(q) = sum_m W_m  prod_i v_i[m_i],      v_i = (1, c_i, s_i),

with float64 weights W (3^n x 3 per chain) expanded once from the same folded offsets. Then FK is
one Kronecker product of the v_i and one matrix product; d p / d q_i replaces v_i by (0, -s_i, c_i),
so FK and all n Jacobian columns come from one product over n + 1 variants: ~14 ops instead of ~60.
``strategy='auto'`` picks it when the work is small; both routes are tested against
pytorch-kinematics.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.robot.chain import ChainSpec

__all__ = ["ChainKernel"]

_SNAP = 1e-12  # constants within this of 0 or +-1 are made exact


def _snap(a: np.ndarray) -> np.ndarray:
    a = np.where(np.abs(a) < _SNAP, 0.0, a)
    a = np.where(np.abs(a - 1.0) < _SNAP, 1.0, a)
    return np.where(np.abs(a + 1.0) < _SNAP, -1.0, a)


def _axis_frame(axis: np.ndarray) -> np.ndarray:
    """A rotation A with ``A @ e_z = axis``; a signed permutation when ``axis`` is +-e_k."""
    a = np.asarray(axis, dtype=np.float64)
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(a)))] = 1.0
    c0 = helper - helper.dot(a) * a
    c0 /= np.linalg.norm(c0)
    c1 = np.cross(a, c0)
    return _snap(np.stack([c0, c1, a], axis=1))


class _Const:
    """A value that does not depend on q: one float64 number per chain of the stack, (K,)."""

    __slots__ = ("v",)

    def __init__(self, v: np.ndarray):
        self.v = v

    def is_zero(self) -> bool:
        return not np.any(self.v)


_Value = "int | _Const"  # a register id or a constant


@dataclass
class _Instr:
    dst: int
    op: str  # mul | scale | axpy | addmul | addc
    srcs: tuple[int, ...]
    coef: int | None = None  # index into the coefficient table
    value: float = 1.0


@dataclass
class _Trace:
    """The traced program: instructions over registers 0..n_regs-1.

    Registers ``0..n-1`` hold cos(q_i), ``n..2n-1`` sin(q_i) and ``2n..3n-1`` q_i; each is (K, B).
    """

    n: int
    n_regs: int = 0
    instrs: list[_Instr] = field(default_factory=list)
    coefs: list[np.ndarray] = field(default_factory=list)  # (K,) per-chain coefficients
    outputs: dict[str, list] = field(default_factory=dict)

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


class _Tracer:
    """Symbolic evaluation of the chain over registers, with constant folding."""

    def __init__(self, K: int, n: int):
        self.K = K
        self.t = _Trace(n=n, n_regs=3 * n)

    def const(self, v) -> _Const:
        return _Const(_snap(np.broadcast_to(np.asarray(v, dtype=np.float64), (self.K,)).copy()))

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
        items = [(f, _snap(np.broadcast_to(c, (self.K,)).copy())) for f, c in merged.items()]
        items = [(f, c) for f, c in items if np.any(c)]
        c0 = _snap(c0)
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


def _trace(offsets: np.ndarray, types: tuple[str, ...]) -> _Trace:
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
    return tr.t


@dataclass
class _Program:
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


_REV_TERMS = np.stack([np.diag([0.0, 0.0, 1.0, 1.0]), np.diag([1.0, 1.0, 0.0, 0.0]),
                       np.array([[0.0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]])])  # Rz = E0 + c E1 + s E2
_PRI_TERMS = np.stack([np.eye(4), np.zeros((4, 4)), np.zeros((4, 4))])  # Tz = I + q N (N set below)
_PRI_TERMS[1, 2, 3] = 1.0
MULTILINEAR_MAX_JOINTS = 5
MULTILINEAR_MAX_WORK = 8192  # elements of the monomial tensor; measured crossover with the traced program


def _multilinear_weights(folded: np.ndarray, types: tuple[str, ...]) -> np.ndarray:
    """(K, 3^n, 3) weights of the tip position over the monomials prod_i v_i[m_i] (row-major m)."""
    K, n = folded.shape[0], len(types)
    out = []
    for k in range(K):
        v = folded[k, n] @ np.array([0.0, 0.0, 0.0, 1.0])  # tip in the last joint's frame (homogeneous)
        for i in range(n - 1, -1, -1):
            terms = _REV_TERMS if types[i] == "revolute" else _PRI_TERMS
            v = np.einsum("ij,ajk,...k->a...i", folded[k, i], terms, v)
        out.append(v[..., :3].reshape(3**n, 3))
    return np.stack(out)


class ChainKernel:
    """Batched FK and Jacobians of K serial chains with the same sequence of joint types.

    Build it from one :class:`ChainSpec` (a single chain: joint tensors are ``(..., n)``) or from a
    list (a stack: joint tensors are ``(..., K, n)``, chain k gets ``q[..., k, :]``). Outputs are
    in each chain's root frame and in the dtype/device of ``q``.
    """

    def __init__(self, specs: ChainSpec | Sequence[ChainSpec]):
        self.stacked = not isinstance(specs, ChainSpec)
        self.specs: tuple[ChainSpec, ...] = tuple(specs) if self.stacked else (specs,)
        if not self.specs:
            raise ValueError("ChainKernel needs at least one chain")
        types = self.specs[0].joint_types
        for spec in self.specs[1:]:
            if spec.joint_types != types:
                raise ValueError(f"chains '{self.specs[0].tip}' and '{spec.tip}' differ in their joint "
                                 f"types ({types} vs {spec.joint_types}); stack only alike chains")
        self.joint_types = types
        self.n_joints = len(types)
        self.num_chains = len(self.specs)
        folded = np.stack([self._fold(spec) for spec in self.specs])  # (K, n+1, 4, 4)
        self._trace = _trace(folded, types)
        self._programs: dict[tuple, _Program] = {}
        self._ml_weights = _multilinear_weights(folded, types) if self.n_joints <= MULTILINEAR_MAX_JOINTS else None
        self._ml_cache: dict[tuple, tuple[Tensor, Tensor]] = {}

    @staticmethod
    def _fold(spec: ChainSpec) -> np.ndarray:
        """Offsets with each joint axis rotated onto z: G_i = A_{i-1}^T F_i A_i."""
        n = spec.n_joints
        A = [np.eye(4) for _ in range(n + 2)]  # A[i+1] belongs to joint i; A[0] = A[n+1] = I
        for i in range(n):
            A[i + 1][:3, :3] = _axis_frame(spec.axes[i])
        return np.stack([_snap(A[i].T @ spec.offsets[i] @ A[i + 1]) for i in range(n + 1)])

    # ------------------------------------------------------------------ compile and run
    def _program(self, outputs: tuple[str, ...], dtype: torch.dtype, device: torch.device) -> _Program:
        key = (outputs, dtype, device)
        prog = self._programs.get(key)
        if prog is not None:
            return prog
        tr = self._trace
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
        prog = _Program(tr.n_regs, steps, outs, len(kept))
        self._programs[key] = prog
        return prog

    def num_ops(self, outputs: tuple[str, ...] = ("p",)) -> int:
        """Number of elementwise torch ops the program for ``outputs`` runs (besides cos/sin/stack)."""
        return self._program(outputs, torch.float32, torch.device("cpu")).n_ops

    def _check(self, q: Tensor) -> tuple[int, ...]:
        if not isinstance(q, Tensor):
            raise TypeError(f"joint values must be a torch.Tensor, got {type(q).__name__}")
        want = (self.num_chains, self.n_joints) if self.stacked else (self.n_joints,)
        if q.dim() < len(want) or tuple(q.shape[q.dim() - len(want):]) != want:
            shape = "(..., " + ", ".join(map(str, want)) + ")"
            raise ValueError(f"joint tensor must have shape {shape} for chain(s) ending at "
                             f"{', '.join(s.tip for s in self.specs)}; got {tuple(q.shape)}")
        if not q.is_floating_point():
            raise TypeError(f"joint tensor must be floating point, got {q.dtype}")
        return tuple(q.shape[: q.dim() - len(want)])

    def _run(self, q: Tensor, outputs: tuple[str, ...]) -> list[Tensor]:
        batch = self._check(q)
        K, n = self.num_chains, self.n_joints
        B = int(np.prod(batch)) if batch else 1
        prog = self._program(outputs, q.dtype, q.device)
        qT = q.reshape(B, K, n).permute(2, 1, 0).contiguous()  # (n, K, B)
        regs: list = [None] * prog.n_regs
        if "revolute" in self.joint_types:
            regs[0:n] = torch.cos(qT).unbind(0)
            regs[n : 2 * n] = torch.sin(qT).unbind(0)
        if "prismatic" in self.joint_types:
            regs[2 * n : 3 * n] = qT.unbind(0)
        for dst, fn in prog.steps:
            regs[dst] = fn(regs)
        vals = [regs[v] if isinstance(v, int) else v.expand(K, B) for v in prog.outputs]
        results, start = [], 0
        lead = batch + ((K,) if self.stacked else ())
        for name in outputs:
            shape = (3,) if name == "p" else (3, 3) if name == "R" else (3, n)
            m = int(np.prod(shape))
            block = vals[start : start + m]
            start += m
            # (B, K, m), contiguous (strided outputs make some later ops, e.g. vector_norm, 50x slower)
            out = torch.stack(block, dim=0).permute(2, 1, 0).contiguous() if block else q.new_zeros(B, K, 0)
            results.append(out.reshape(*lead, *shape))
        return results

    def _use_multilinear(self, q: Tensor, strategy: str, jacobian: bool) -> bool:
        """Validates q and picks the route (the traced program validates q again, cheaply)."""
        self._check(q)
        if strategy == "soa":
            return False
        if strategy == "multilinear":
            if self._ml_weights is None:
                raise ValueError(f"the multilinear route needs at most {MULTILINEAR_MAX_JOINTS} joints")
            return True
        if strategy != "auto":
            raise ValueError(f"strategy must be 'auto', 'soa' or 'multilinear', got '{strategy}'")
        if self._ml_weights is None:
            return False
        n = self.n_joints
        return q.numel() // max(n, 1) * (n + 1 if jacobian else 1) * 3**n <= MULTILINEAR_MAX_WORK

    def _run_multilinear(self, q: Tensor, jacobian: bool) -> list[Tensor]:
        K, n = self.num_chains, self.n_joints
        batch = tuple(q.shape[: q.dim() - (2 if self.stacked else 1)])
        B = q.numel() // (K * n) if n else 1
        key = (q.dtype, q.device)
        if key not in self._ml_cache:
            W = torch.as_tensor(self._ml_weights, dtype=q.dtype, device=q.device)  # (K, M, 3)
            rev = torch.tensor([t == "revolute" for t in self.joint_types], device=q.device).view(n, 1)
            eye = torch.eye(n + 1, n, dtype=torch.bool, device=q.device).unsqueeze(-1)  # variant j: d / d q_j
            self._ml_cache[key] = (W, rev, eye)
        W, rev, eye = self._ml_cache[key]
        qq = q.reshape(B, K, n)
        c, s = torch.cos(qq), torch.sin(qq)
        one = torch.ones_like(c)
        prismatic = "prismatic" in self.joint_types
        zero = torch.zeros_like(c) if (jacobian or prismatic) else None
        if prismatic:
            V = torch.where(rev, torch.stack([one, c, s], -1), torch.stack([one, qq, zero], -1))
        else:
            V = torch.stack([one, c, s], -1)  # (B, K, n, 3)
        if jacobian:
            dV = torch.stack([zero, -s, c], -1) if "prismatic" not in self.joint_types else torch.where(
                rev, torch.stack([zero, -s, c], -1), torch.stack([zero, one, zero], -1))
            V = torch.where(eye, dV.unsqueeze(2), V.unsqueeze(2))  # (B, K, n + 1, n, 3)
        factors = V.unbind(-2)
        m = factors[0]
        for f in factors[1:]:
            m = (m.unsqueeze(-1) * f.unsqueeze(-2)).flatten(-2)
        M = m.shape[-1]
        out = torch.bmm(m.transpose(0, 1).reshape(K, -1, M), W)  # (K, B * variants, 3)
        lead = batch + ((K,) if self.stacked else ())
        if not jacobian:
            return [out.transpose(0, 1).reshape(*lead, 3)]
        out = out.view(K, B, n + 1, 3).transpose(0, 1)  # (B, K, n + 1, 3)
        p = out[:, :, n].reshape(*lead, 3)
        J = out[:, :, :n].transpose(-1, -2).reshape(*lead, 3, n)
        return [p, J]

    # ------------------------------------------------------------------ public API
    def position(self, q: Tensor, strategy: str = "auto") -> Tensor:
        """Tip positions. q: (..., [K,] n) -> (..., [K,] 3).

        ``strategy``: 'auto' (the multilinear route for small work, else the traced program),
        'soa' or 'multilinear' to force one.
        """
        if self._use_multilinear(q, strategy, jacobian=False):
            return self._run_multilinear(q, jacobian=False)[0]
        return self._run(q, ("p",))[0]

    def position_jacobian(self, q: Tensor, strategy: str = "auto") -> tuple[Tensor, Tensor]:
        """Tip positions and position Jacobians d p / d q.

        q: (..., [K,] n) -> p: (..., [K,] 3), J: (..., [K,] 3, n). ``strategy`` as in :meth:`position`.
        """
        if self._use_multilinear(q, strategy, jacobian=True):
            p, J = self._run_multilinear(q, jacobian=True)
            return p, J
        p, J = self._run(q, ("p", "Jv"))
        return p, J

    def pose(self, q: Tensor) -> tuple[Tensor, Tensor]:
        """Tip frames. q: (..., [K,] n) -> R: (..., [K,] 3, 3), p: (..., [K,] 3)."""
        p, R = self._run(q, ("p", "R"))
        return R, p

    def pose_jacobian(self, q: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Tip frames and geometric Jacobians (rows: linear velocity, then angular velocity).

        q: (..., [K,] n) -> R: (..., [K,] 3, 3), p: (..., [K,] 3), J: (..., [K,] 6, n).
        """
        p, R, Jv, Jw = self._run(q, ("p", "R", "Jv", "Jw"))
        return R, p, torch.cat([Jv, Jw], dim=-2)

    def __repr__(self) -> str:
        tips = ", ".join(s.tip for s in self.specs)
        return (f"ChainKernel({self.num_chains} chain(s) -> {tips}; {self.n_joints} joints; "
                f"ops p={self.num_ops(('p',))} p+J={self.num_ops(('p', 'Jv'))})")
