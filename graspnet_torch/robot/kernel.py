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
output mode (the tracer: :mod:`graspnet_torch.robot.trace`). The geometric Jacobian uses
``J_v,i = z_i x (p - o_i)``, ``J_w,i = z_i`` (revolute) and ``J_v,i = z_i`` (prismatic), where
``z_i``, ``o_i`` are joint i's axis and origin in the root frame.

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

A kernel of some chains of a stack (:meth:`ChainKernel.rows`: a problem's contact fingers among
a hand's) is made from the stack's parts, not traced and expanded again.

:class:`TreeKernel` gives every link's frame of a whole tree (the robot's link frames: collision
scenes, pictures, the viewer, reach) as batched products of 4x4 frames, depth by depth.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.robot.chain import ChainSpec
from graspnet_torch.robot.trace import Program, compile_program, snap, trace_chain

__all__ = ["ChainKernel", "TreeKernel", "motion_terms"]

def motion_terms(axes: np.ndarray, types: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n, 4, 4) A and B of M(q) = I + s(q) A + c(q) B, and (n,) revolute mask."""
    n = len(types)
    A, B = np.zeros((n, 4, 4)), np.zeros((n, 4, 4))
    for i, (a, kind) in enumerate(zip(axes, types, strict=True)):
        if kind == "revolute":
            K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
            A[i, :3, :3], B[i, :3, :3] = K, K @ K
        else:
            A[i, :3, 3] = a
    return A, B, np.array([t == "revolute" for t in types])


def _axis_frame(axis: np.ndarray) -> np.ndarray:
    """A rotation A with ``A @ e_z = axis``; a signed permutation when ``axis`` is +-e_k."""
    a = np.asarray(axis, dtype=np.float64)
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(a)))] = 1.0
    c0 = helper - helper.dot(a) * a
    c0 /= np.linalg.norm(c0)
    c1 = np.cross(a, c0)
    return snap(np.stack([c0, c1, a], axis=1))


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
        self._folded = np.stack([self._fold(spec) for spec in self.specs])  # (K, n+1, 4, 4)
        self._trace = trace_chain(self._folded, types)
        self._ml_weights = (_multilinear_weights(self._folded, types) if self.n_joints <= MULTILINEAR_MAX_JOINTS
                            else None)
        self._programs: dict[tuple, Program] = {}
        self._ml_cache: dict[tuple, tuple[Tensor, Tensor]] = {}
        self._views: dict[tuple[int, ...], ChainKernel] = {}

    def rows(self, rows: Sequence[int]) -> ChainKernel:
        """The kernel of the chains ``rows`` of this stack, in that order (joints ``(..., len(rows),
        n)``), the same object for the same rows. Built from this kernel's parts: the folded
        offsets and multilinear weights at those rows, and its traced program with the
        coefficients at those rows wherever the rows fold alike
        (:meth:`~graspnet_torch.robot.trace.Trace.folds_alike`), else the rows traced anew. Either
        way its results are those of ``ChainKernel([specs[r] for r in rows])``, bit for bit."""
        key = tuple(int(r) for r in rows)
        view = self._views.get(key)
        if view is None:
            if not key or min(key) < 0 or max(key) >= self.num_chains:
                raise ValueError(f"rows {list(key)} of a stack of {self.num_chains} chain(s)")
            view = object.__new__(ChainKernel)
            view.stacked, view.specs = True, tuple(self.specs[r] for r in key)
            view.joint_types, view.n_joints, view.num_chains = self.joint_types, self.n_joints, len(key)
            view._folded = self._folded[list(key)]
            view._trace = (self._trace.rows(key) if self._trace.folds_alike(key)
                           else trace_chain(view._folded, self.joint_types))
            view._ml_weights = None if self._ml_weights is None else self._ml_weights[list(key)]
            view._programs, view._ml_cache, view._views = {}, {}, {}
            self._views[key] = view
        return view

    @staticmethod
    def _fold(spec: ChainSpec) -> np.ndarray:
        """Offsets with each joint axis rotated onto z: G_i = A_{i-1}^T F_i A_i."""
        n = spec.n_joints
        A = [np.eye(4) for _ in range(n + 2)]  # A[i+1] belongs to joint i; A[0] = A[n+1] = I
        for i in range(n):
            A[i + 1][:3, :3] = _axis_frame(spec.axes[i])
        return np.stack([snap(A[i].T @ spec.offsets[i] @ A[i + 1]) for i in range(n + 1)])

    # ------------------------------------------------------------------ compile and run
    def _program(self, outputs: tuple[str, ...], dtype: torch.dtype, device: torch.device) -> Program:
        key = (outputs, dtype, device)
        prog = self._programs.get(key)
        if prog is None:
            prog = self._programs[key] = compile_program(self._trace, outputs, dtype, device)
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


class TreeKernel:
    """Batched frames of every link of a kinematic tree (a whole URDF: the robot's link frames).

    Each joint's motion is ``M(q) = I + s(q) A + c(q) B`` (:func:`motion_terms`), so its offset
    and motion cost two fused multiply-adds on precomputed products, ``F M(q) = F + s (F A) +
    c (F B)``; the joints of one depth are then placed on their parents' frames in one batched
    product, depth after depth (the joints a branch shares, once), and each link is its joint's
    frame times a constant. A tree has too many joints for the chain kernel's traced program to
    pay at small batches (op-bound); these products match it at large ones.

    Args:
        parents: (n,) each joint's parent joint (-1: the root), listed before it.
        types: (n,) 'revolute' | 'prismatic'.
        axes: (n, 3) unit axes, each in its joint's frame.
        offsets: (n, 4, 4) each joint's frame (before its motion) in its parent joint's frame
            (after the parent's motion; the root's for -1).
        attach: (L,) the joint each link moves with (-1: the root);
        poses: (L, 4, 4) the link's pose in that joint's frame (after its motion).
    """

    def __init__(self, parents: Sequence[int], types: Sequence[str], axes: np.ndarray, offsets: np.ndarray,
                 attach: Sequence[int], poses: np.ndarray):
        n = len(types)
        self.n_joints, self.n_links, self.joint_types = n, len(attach), tuple(types)
        A, B, self._revolute = motion_terms(np.asarray(axes, dtype=np.float64).reshape(n, 3), self.joint_types)
        offsets = np.asarray(offsets, dtype=np.float64).reshape(n, 4, 4)
        self._consts_np = (offsets, offsets @ A, offsets @ B, np.asarray(poses, dtype=np.float64))
        depth: list[int] = []
        for i in range(n):
            if not -1 <= parents[i] < i:
                raise ValueError(f"joint {i}'s parent {parents[i]} is not listed before it")
            depth.append(0 if parents[i] < 0 else depth[parents[i]] + 1)
        # per depth: its joints, and their parents' slots in the frames (slot n: the root, the identity)
        self._depths = [(torch.as_tensor([i for i in range(n) if depth[i] == d]),
                         torch.as_tensor([parents[i] % (n + 1) for i in range(n) if depth[i] == d]))
                        for d in range(max(depth, default=-1) + 1)]
        self._attach = torch.as_tensor([j % (n + 1) for j in attach], dtype=torch.long)
        self._consts: dict[tuple, tuple[Tensor, ...]] = {}

    def frames(self, q: Tensor) -> Tensor:
        """Every link's frame in the tree's root, in the dtype/device of q. q: (B, n) -> (B, L, 4, 4)."""
        if q.dim() != 2 or q.shape[1] != self.n_joints or not q.is_floating_point():
            raise ValueError(f"joint tensor must be floating point of shape (B, {self.n_joints}); got "
                             f"{tuple(q.shape)} {q.dtype}")
        key = (q.dtype, q.device)
        if key not in self._consts:
            rev = torch.as_tensor(self._revolute, device=q.device)
            self._consts[key] = (*(torch.as_tensor(a, dtype=q.dtype, device=q.device) for a in self._consts_np), rev,
                                 torch.eye(4, dtype=q.dtype, device=q.device))
        F, FA, FB, poses, rev, eye = self._consts[key]
        if self._revolute.all():
            s, c = torch.sin(q), 1 - torch.cos(q)
        else:
            s = torch.where(rev, torch.sin(q), q)
            c = torch.where(rev, 1 - torch.cos(q), torch.zeros_like(q))
        local = torch.addcmul(torch.addcmul(F, s[..., None, None], FA), c[..., None, None], FB)  # (B, n, 4, 4)
        X = q.new_empty(q.shape[0], self.n_joints + 1, 4, 4)  # every joint's frame, then the root's
        X[:, -1] = eye
        for joints, parents in self._depths:
            X[:, joints] = torch.matmul(X[:, parents], local[:, joints])
        return torch.matmul(X[:, self._attach], poses)

    def __repr__(self) -> str:
        return f"TreeKernel({self.n_joints} joints in {len(self._depths)} depths -> {self.n_links} links)"
