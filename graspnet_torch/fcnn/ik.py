"""Finger inverse kinematics from trained expert sets: competition, then optional refinement.

For a fingertip target every expert of the finger proposes joint angles (clamped to the joint
limits); forward kinematics scores them and the expert with the smallest fingertip error wins
(paper section 3). Refinement runs ``refine`` steps of eq. 5 with the damped pseudo-inverse,
clamped to the limits. All experts of all requested fingers are evaluated together: their
weights are stacked (padded to the largest expert count) and the finger chains run as one
stacked kernel. Fingers with fewer free joints than the robot's widest are padded (outputs,
limits and Jacobian columns of the padding are 0), so fingers of any sizes still run in one call.
Every finger's weights are stacked once per dtype and device; a subset of fingers (a problem's
contact fingers) takes rows of them, and its kernel is selected from the robot's: a solve of a
new subset builds nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from graspnet_torch.fcnn.experts import ExpertSet
from graspnet_torch.robot.fingers import FingerKernel
from graspnet_torch.robot.ik import limited_step
from graspnet_torch.robot.robot import Robot

__all__ = ["FingerIK"]


@dataclass
class _Bank:
    """Stacked expert weights of F fingers, padded to E experts: W1 (F*E, 3, H), ... (every
    finger's, :meth:`FingerIK._full_bank`: W1 (F, E, 3, H), ...)."""

    fingers: tuple[str, ...]
    n_experts: int
    params: tuple[Tensor, ...]
    valid: Tensor  # (E, 1, F) experts that exist
    x_center: Tensor  # (F, 3)
    x_scale: Tensor
    q_mid: Tensor  # (F, n); padding: 0
    q_half: Tensor
    lower: Tensor  # (F, n); padding: 0
    upper: Tensor
    kernel: FingerKernel


class FingerIK:
    """Learned inverse kinematics of a robot's fingers.

    Args:
        robot: the robot the experts were trained for.
        experts: finger name -> trained :class:`ExpertSet`.
        damping: lambda of the damped pseudo-inverse used by refinement (m).
    """

    def __init__(self, robot: Robot, experts: dict[str, ExpertSet], damping: float = 1e-4):
        missing = [f for f in experts if f not in robot.fingers]
        if missing:
            raise ValueError(f"experts for unknown finger(s) {missing} of robot '{robot.name}'")
        self.robot = robot
        self.experts = dict(experts)
        self.damping = damping
        self._full: dict[tuple, _Bank] = {}  # every finger, per dtype / device
        self._banks: dict[tuple, _Bank] = {}  # per finger subset: rows of the full bank

    @property
    def finger_names(self) -> tuple[str, ...]:
        return tuple(f for f in self.robot.finger_names if f in self.experts)

    def n_experts(self, finger: str) -> int:
        return self.experts[finger].n_active

    # ------------------------------------------------------------------ banks
    def kernel(self, fingers: Sequence[str]) -> FingerKernel:
        """The finger kernel of ``fingers`` (joints (..., F, n)): selected from the robot's kernel
        of all its fingers (:meth:`~graspnet_torch.robot.fingers.FingerKernel.select`), the same
        object for the same fingers."""
        return self.robot.finger_kernel.select([self.robot.finger_index(f) for f in fingers])

    def cache_info(self) -> dict[str, int]:
        """How many banks this finger IK holds: ``stacked``, every finger's expert weights stacked
        (one per dtype and device), and ``subsets``, banks of finger subsets (rows of those)."""
        return {"stacked": len(self._full), "subsets": len(self._banks)}

    def _full_bank(self, dtype: torch.dtype, device: torch.device) -> _Bank:
        """Every finger with experts (:attr:`finger_names`) stacked once per dtype and device:
        params (F, E, ...), padded to the largest expert count E."""
        key = (dtype, device)
        bank = self._full.get(key)
        if bank is not None:
            return bank
        fingers = self.finger_names
        sets = [self.experts[f] for f in fingers]
        E = max(s.n_active for s in sets)
        n = self.robot.joints_per_finger
        params = []
        for name in ("W1", "b1", "W2", "b2", "W3", "b3"):
            per = []
            for s in sets:
                p = getattr(s, name).detach()[: s.n_active]
                if name in ("W3", "b3"):  # a finger with fewer joints: zero outputs in the padding
                    p = torch.nn.functional.pad(p, (0, n - p.shape[-1]))
                pad = p.new_zeros((E - s.n_active, *p.shape[1:]))
                per.append(torch.cat([p, pad]))
            params.append(torch.stack(per).to(dtype=dtype, device=device))
        valid = torch.zeros(E, 1, len(fingers), dtype=torch.bool, device=device)
        for k, s in enumerate(sets):
            valid[: s.n_active, 0, k] = True

        def stack(attr: str) -> Tensor:
            return torch.stack([torch.nn.functional.pad(getattr(s, attr), (0, n - s.n_joints)) if attr.startswith("q_")
                                else getattr(s, attr) for s in sets]).to(dtype=dtype, device=device)

        lower, upper = stack("q_lower"), stack("q_upper")
        bank = self._full[key] = _Bank(fingers, E, tuple(params), valid, stack("x_center"), stack("x_scale"),
                                       (lower + upper) / 2, (upper - lower) / 2, lower, upper, self.kernel(fingers))
        return bank

    def _bank(self, fingers: tuple[str, ...], dtype: torch.dtype, device: torch.device) -> _Bank:
        """The bank of ``fingers`` (any subset, any order): the rows of :meth:`_full_bank`, padded
        to the subset's largest expert count E (params (F*E, ...)); the finger kernel selected from
        the robot's (:meth:`~graspnet_torch.robot.fingers.FingerKernel.select`). Once per subset."""
        key = (fingers, dtype, device)
        bank = self._banks.get(key)
        if bank is not None:
            return bank
        full = self._full_bank(dtype, device)
        column = {f: k for k, f in enumerate(full.fingers)}
        rows = torch.as_tensor([column[f] for f in fingers], device=device)
        E = max(self.experts[f].n_active for f in fingers)
        params = tuple(p.index_select(0, rows)[:, :E].reshape(len(fingers) * E, *p.shape[2:]) for p in full.params)
        picked = [t.index_select(0, rows) for t in (full.x_center, full.x_scale, full.q_mid, full.q_half, full.lower,
                                                     full.upper)]
        bank = self._banks[key] = _Bank(fingers, E, params, full.valid[:E].index_select(2, rows).contiguous(), *picked,
                                        self.kernel(fingers))
        return bank

    # ------------------------------------------------------------------ solving
    @staticmethod
    def _check_targets(targets: Tensor, F: int, what: str) -> None:
        if not isinstance(targets, Tensor) or not targets.is_floating_point():
            raise TypeError(f"{what} must be a floating-point torch.Tensor, got "
                            f"{type(targets).__name__ if not isinstance(targets, Tensor) else targets.dtype}")
        want = "(B, 3)" if F == 0 else f"(B, {F}, 3)"
        ok = targets.dim() == 2 and targets.shape[1] == 3 if F == 0 else \
            targets.dim() == 3 and tuple(targets.shape[1:]) == (F, 3)
        if not ok:
            raise ValueError(f"{what} must have shape {want}, got {tuple(targets.shape)}")
        bad = ~torch.isfinite(targets).all(dim=-1)
        if bool(bad.any()):
            rows = torch.nonzero(bad.reshape(targets.shape[0], -1).any(-1)).squeeze(1)[:5].tolist()
            raise ValueError(f"{what} contain NaN or inf (first rows: {rows})")

    def _proposals(self, targets: Tensor, bank: _Bank) -> Tensor:
        """Every expert's answer for every target, clamped to the limits: (E, B, F, n)."""
        B, F = targets.shape[0], len(bank.fingers)
        E = bank.n_experts
        xn = ((targets - bank.x_center) / bank.x_scale).permute(1, 0, 2)  # (F, B, 3)
        xn = xn.unsqueeze(1).expand(F, E, B, 3).reshape(F * E, B, 3)
        W1, b1, W2, b2, W3, b3 = bank.params
        h = torch.tanh(torch.baddbmm(b1, xn, W1))
        h = torch.tanh(torch.baddbmm(b2, h, W2))
        u = torch.baddbmm(b3, h, W3).reshape(F, E, B, -1).permute(1, 2, 0, 3)  # (E, B, F, n)
        return torch.clamp(bank.q_mid + u * bank.q_half, bank.lower, bank.upper)

    def compete(self, targets: Tensor, fingers: Sequence[str], candidates: int = 1) -> tuple[Tensor, Tensor]:
        """Competition among experts, no refinement.

        targets: (B, F, 3) in each finger's base frame -> q: (B, F, n) within limits (the winning
        expert's answer), error: (B, F) m. With ``candidates = k > 1`` the k best experts' answers
        come back instead: q (k, B, F, n), error (k, B, F), best first (missing experts: inf error).
        """
        bank = self._bank(tuple(fingers), targets.dtype, targets.device)
        q = self._proposals(targets, bank)
        E, B, F, n = q.shape
        err = torch.linalg.vector_norm(bank.kernel.position(q) - targets, dim=-1)  # (E, B, F)
        err = torch.where(bank.valid, err, torch.full_like(err, float("inf")))
        if candidates <= 1:
            best, win = err.min(dim=0)
            return q.gather(0, win.unsqueeze(0).unsqueeze(-1).expand(1, B, F, n)).squeeze(0), best
        k = min(candidates, E)
        best, win = torch.topk(err, k, dim=0, largest=False)
        return q.gather(0, win.unsqueeze(-1).expand(k, B, F, n)), best

    def compete_jacobian(self, targets: Tensor, fingers: Sequence[str]) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Competition that also returns the winners' fingertips and Jacobians, so that a
        refinement can start without another forward-kinematics pass (:meth:`refine`'s ``start``).

        targets: (B, F, 3) -> q (B, F, n), error (B, F), tips (B, F, 3), J (B, F, 3, n).
        """
        bank = self._bank(tuple(fingers), targets.dtype, targets.device)
        q = self._proposals(targets, bank)
        _E, B, F, _n = q.shape
        p, J = bank.kernel.position_jacobian(q)
        err = torch.linalg.vector_norm(p - targets, dim=-1)
        err = torch.where(bank.valid, err, torch.full_like(err, float("inf")))
        best, win = err.min(dim=0)
        w = win

        def pick(t: Tensor) -> Tensor:
            return t.gather(0, w.view(1, B, F, *([1] * (t.dim() - 3))).expand(1, *t.shape[1:])).squeeze(0)

        return pick(q), best, pick(p), pick(J)

    def refine(self, q: Tensor, targets: Tensor, fingers: Sequence[str], iterations: int,
               start: tuple[Tensor, Tensor] | None = None) -> tuple[Tensor, Tensor]:
        """``iterations`` steps of eq. 5 (damped pseudo-inverse) within the joint limits: a joint
        whose step would cross its limit is locked and the step re-solved with the others
        (:func:`~graspnet_torch.robot.ik.limited_step`).

        A step is kept only where it reduces the fingertip error, so refinement never makes a
        solution worse (an undamped step near a singularity can overshoot, and the clamp to the
        limits can then land far away). Costs one forward kinematics per iteration, like plain eq. 5.

        q: (B, F, n); targets: (B, F, 3); start: optional (tips (B, F, 3), J (B, F, 3, n)) at q ->
        q: (B, F, n), error: (B, F) m.
        """
        bank = self._bank(tuple(fingers), targets.dtype, targets.device)
        p, J = start if start is not None else bank.kernel.position_jacobian(q)
        err = torch.linalg.vector_norm(targets - p, dim=-1)
        for it in range(iterations):
            q_new = limited_step(J, targets - p, q, bank.lower, bank.upper, self.damping)
            if it == iterations - 1:  # the last step needs positions only
                p_new = bank.kernel.position(q_new)
                err_new = torch.linalg.vector_norm(targets - p_new, dim=-1)
                better = err_new < err
                return torch.where(better.unsqueeze(-1), q_new, q), torch.where(better, err_new, err)
            p_new, J_new = bank.kernel.position_jacobian(q_new)
            err_new = torch.linalg.vector_norm(targets - p_new, dim=-1)
            better = err_new < err
            q = torch.where(better.unsqueeze(-1), q_new, q)
            p = torch.where(better.unsqueeze(-1), p_new, p)
            J = torch.where(better.unsqueeze(-1).unsqueeze(-1), J_new, J)
            err = torch.where(better, err_new, err)
        return q, err

    def solve_fingers(self, targets: Tensor, fingers: Sequence[str] | None = None, refine: int = 0,
                      candidates: int = 1, fallback_restarts: int = 0, tol: float = 1e-3,
                      fallback_iterations: int = 20) -> tuple[Tensor, Tensor]:
        """Joint angles of several fingers at once.

        Args:
            targets: (B, F, 3) fingertip targets, each in its finger's base frame (metres).
            fingers: the F finger names (default: every finger with experts, in robot order).
            refine: refinement iterations of eq. 5 after the competition.
            candidates: refine the answers of the ``candidates`` best experts (not only the
                winner's) and keep the best result; 1 is the paper's procedure. More candidates
                cost proportionally more refinement but rescue the rare target whose winning
                answer refines into a joint limit.
            fallback_restarts: off (0) by default. Otherwise targets whose error is still at
                least ``tol`` after the above are retried from that many random postures (refined
                ``fallback_iterations`` times; the best answer is kept). About 1 target in 10^4
                needs it (a corner of the workspace that no expert covers), so it costs almost
                nothing on average. Deterministic: the random postures come from a fixed seed.
        Returns:
            q: (B, F, n) joint angles within limits (radians), n = ``robot.joints_per_finger`` (a
            finger with fewer free joints is padded with 0); error: (B, F) fingertip error (m). Unreachable
            targets come back with their error, never an exception.
        """
        fingers = tuple(fingers) if fingers is not None else self.finger_names
        unknown = [f for f in fingers if f not in self.experts]
        if unknown:
            raise ValueError(f"no experts for finger(s) {unknown}; have {list(self.finger_names)}")
        self._check_targets(targets, len(fingers), "targets")
        if candidates <= 1 or refine <= 0:
            q, err = self.compete(targets, fingers)
            if refine > 0:
                q, err = self.refine(q, targets, fingers, refine)
        else:
            q, err = self.compete(targets, fingers, candidates)  # (k, B, F, n), (k, B, F)
            k, B, F, n = q.shape
            q, err = self.refine(q.reshape(k * B, F, n), targets.repeat(k, 1, 1), fingers, refine)
            err = err.reshape(k, B, F)
            err, pick = err.min(dim=0)
            q = q.reshape(k, B, F, n).gather(0, pick.unsqueeze(0).unsqueeze(-1).expand(1, B, F, n)).squeeze(0)
        if fallback_restarts > 0:
            q, err = self._fallback(q, err, targets, fingers, fallback_restarts, tol, fallback_iterations)
        return q, err

    def _fallback(self, q: Tensor, err: Tensor, targets: Tensor, fingers: tuple[str, ...], restarts: int,
                  tol: float, iterations: int) -> tuple[Tensor, Tensor]:
        rows = torch.nonzero((err >= tol).any(-1)).squeeze(1)
        if rows.numel() == 0:
            return q, err
        bank = self._bank(fingers, targets.dtype, targets.device)
        R, nr, (F, n) = restarts, rows.numel(), bank.lower.shape
        gen = torch.Generator(device=targets.device).manual_seed(0)
        u = torch.rand(R * nr, F, n, generator=gen, dtype=targets.dtype, device=targets.device)
        q_r, e_r = self.refine(bank.lower + (bank.upper - bank.lower) * u, targets[rows].repeat(R, 1, 1), fingers,
                               iterations)
        best, pick = e_r.reshape(R, nr, F).min(dim=0)
        q_best = q_r.reshape(R, nr, F, n).gather(0, pick.unsqueeze(0).unsqueeze(-1).expand(1, nr, F, n)).squeeze(0)
        better = best < err[rows]
        q, err = q.clone(), err.clone()
        q[rows] = torch.where(better.unsqueeze(-1), q_best, q[rows])
        err[rows] = torch.where(better, best, err[rows])
        return q, err

    def solve(self, finger: str, targets: Tensor, refine: int = 0, candidates: int = 1,
              fallback_restarts: int = 0, tol: float = 1e-3) -> tuple[Tensor, Tensor]:
        """Joint angles of one finger.

        targets: (B, 3) fingertip targets in the finger's base frame (metres) ->
        q: (B, n_f) the finger's free joints within limits, error: (B,) fingertip error (m). See :meth:`solve_fingers`.
        """
        if finger not in self.experts:
            raise ValueError(f"no experts for finger '{finger}'; have {list(self.finger_names)}")
        self._check_targets(targets, 0, "targets")
        q, err = self.solve_fingers(targets.unsqueeze(1), (finger,), refine, candidates, fallback_restarts, tol)
        return q.squeeze(1)[:, : self.robot.fingers[finger].n_joints], err.squeeze(1)

    def __repr__(self) -> str:
        counts = ", ".join(f"{f}: {self.n_experts(f)}" for f in self.finger_names)
        return f"FingerIK(robot='{self.robot.name}', experts {{{counts}}})"
