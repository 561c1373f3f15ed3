"""The whole configuration of a finger environment: x = [configuration (n), the contact fingers'
joints (F * j)], float64 on the CPU: what the whole polish, ``solver=dls`` and a warm start move
together (padding slots have limits [0, 0]). Mixed into
:class:`~graspnet_torch.solver.fingers.FingerEnvironment`, whose attributes it reads.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Self

import torch
from torch import Tensor

from graspnet_torch.least_squares import LMOptions, Prior, levenberg_marquardt
from graspnet_torch.robot.transforms import frame_point_jacobian, transform_points
from graspnet_torch.solver.environment import Done, Evaluation
from graspnet_torch.solver.pad_term import PadTerm, skew

if TYPE_CHECKING:
    from graspnet_torch.collision.proxy import CollisionProxy
    from graspnet_torch.fcnn.ik import FingerIK
    from graspnet_torch.least_squares import LMResult
    from graspnet_torch.robot.robot import Posture, Robot

__all__ = ["DEPTH_STEP", "WholeConfiguration"]

DEPTH_STEP = 1e-7  # the forward differences' step of the depth residuals (radians, metres; float64)
DEPTH_ROWS = 128  # whole_depths' rows per chunk: 128 x (m + 1) configurations' frames at a time
ALIGN_SHARE = 0.5  # a grasp's pads are turned in with the hinge at this share of the cone (_align)
SURFACE_TIPS_M = 1e-5  # the surface model's polish has converged once its pads are within this of their
SURFACE_SLACK_M = 5e-5  # contacts (or the polish tolerance, if larger), each pad within this of its hinge
SURFACE_DEPTH_SHARE = 0.25  # (0.06 degrees) and each link's depth within this share of the allowance:
# driving every residual to the polish's 0.001 mm crawled (env1: 22 steps of 16 rows, 0.2 s, for a
# 0.01 mm overlap of two fingers), and a link 0.27 mm deep in env2 kept 16 rows polishing 30 steps


class WholeConfiguration:
    """The whole-configuration methods of :class:`~graspnet_torch.solver.fingers.FingerEnvironment`
    (its attributes below; :meth:`palm_frame_jacobian`, :meth:`_exact_bounds`, :meth:`clamp`,
    :meth:`bases` and the others it calls are the environment's)."""

    robot: Robot
    ik: FingerIK | None
    n: int
    idx: list[int]
    fingers: tuple[str, ...]
    mask: Tensor | None
    contacts64: Tensor
    lower: Tensor
    proxy: CollisionProxy | None
    depth_proxy: CollisionProxy | None
    depth_allowance: float
    joint_box: tuple[Tensor, Tensor] | None
    polish_iterations: int
    polish_tol: float
    min_gain: float
    pads: PadTerm | None
    shared_slots: int

    def near(self, posture: Posture, step_deg: float | None) -> Self:
        """Keep the contact fingers' joints within ``step_deg`` degrees (a prismatic joint: that
        many mm) of the posture's, within their limits (None: the limits only): a warm start
        from the previous frame of a sequence moves no finger joint by more. Returns self."""
        if step_deg is not None:
            import math

            chains = [self.robot.fingers[self.robot.finger_names[i]].chain for i in self.idx]
            j = self.robot.joints_per_finger
            unit = torch.tensor([[math.radians(step_deg) if c.spec.joint_types[k] != "prismatic" else step_deg / 1000
                                  for k in c.free] + [0.0] * (j - len(c.free))  # free joints; padding slots
                                 for c in chains], dtype=torch.float64)
            q = posture.fingers[self.idx].to(torch.float64)
            flo, fhi = (torch.as_tensor(a)[self.idx] for a in self.robot.finger_limits)
            lo, hi = torch.maximum(flo, q - unit), torch.minimum(fhi, q + unit)
            self.joint_box = (torch.minimum(lo, fhi), torch.maximum(hi, flo))  # a posture beyond a limit: the limit
        return self

    def whole_bounds(self, rows: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """Lower and upper bounds of x, (m,) or (B, m) for a batch: the configuration's bounds,
        then the joint limits (or :attr:`joint_box`)."""
        box = self.joint_box if self.joint_box is not None else \
            tuple(torch.as_tensor(a)[self.idx] for a in self.robot.finger_limits)
        flo, fhi = (b.reshape(-1) for b in box)
        lo, hi = (b if b.dim() == 1 or rows is None else b[rows.cpu()] for b in self._exact_bounds())
        if lo.dim() == 2:
            flo, fhi = flo.expand(lo.shape[0], -1), fhi.expand(lo.shape[0], -1)
        return torch.cat([lo, flo], -1), torch.cat([hi, fhi], -1)

    def _whole_start(self, config: Tensor, joints: Tensor, rows: Tensor | None = None) -> Tensor:
        """x (B, m) of configurations (B, n) and contact-finger joints (B, F, j), within bounds."""
        lo, hi = self.whole_bounds(rows)
        B = config.shape[0]
        x = torch.cat([self.clamp(config, rows), joints.detach().to(torch.float64).cpu().reshape(B, -1)], 1)
        return torch.minimum(torch.maximum(x, lo), hi)

    def whole_of(self, posture: Posture) -> Tensor:
        """x (1, m) of a posture: :meth:`_config_of` its palm (or body), its contact fingers' joints."""
        joints = posture.fingers[self.idx].to(torch.float64).unsqueeze(0)
        return self._whole_start(self._config_of(posture), joints, None if self.mask is None else torch.zeros(1).long())

    def _config_of(self, posture: Posture) -> Tensor:
        """(1, n) the configuration that places the palm (or the body) where ``posture`` has it."""
        raise NotImplementedError

    def random_whole(self, trials: int, gen: torch.Generator) -> Tensor:
        """x (T, m) uniform within the bounds and joint limits (``solver=dls``'s restarts)."""
        lo, hi = self.whole_bounds()
        u = torch.rand(trials, lo.shape[-1], generator=gen, dtype=torch.float64, device=gen.device).cpu()
        return lo + (hi - lo) * u

    def _goal64(self, rows: Tensor | None = None) -> Tensor:
        """The contacts, flattened, float64: (3F,) or (B, 3F) for a batch (zero where masked)."""
        c = self._rows(self.contacts64, rows)
        if self.mask is None:
            return c.reshape(-1)
        return (c * self._rows(self.mask, rows).to(c).unsqueeze(-1).cpu()).reshape(c.shape[0], -1)

    def whole_tips(self, x: Tensor, rows: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """Contact fingertips in the world, flattened, of x (B, m) float64 of the trials ``rows``
        -> (B, 3F), and their Jacobian d tips / d x (B, 3F, m) (zero where a batch's mask is): the
        palm's columns by :func:`~graspnet_torch.robot.transforms.frame_point_jacobian`, each
        finger's R B_R dk/dq (free joints; mimic joints through their coupling)."""
        B, F, j, n = x.shape[0], len(self.idx), self.robot.joints_per_finger, self.n
        R, t, Jc = self.palm_frame_jacobian(x[:, :n])
        kernel = self.robot.finger_kernel.select(self.idx)  # the contact fingers' (no FCNN needed)
        local, Jq = kernel.position_jacobian(x[:, n:].reshape(B, F, j))  # (B, F, 3), (B, F, 3, j)
        base_R, base_t = self.bases(x[:, :n])
        in_palm = transform_points(base_R, base_t, local)
        tips = transform_points(R.unsqueeze(1), t.unsqueeze(1), in_palm)
        palm = frame_point_jacobian(R, Jc, in_palm)  # (B, F, 3, n); zero in the shared joints' columns
        if self.shared_slots:  # the bases move with the shared joints: central differences, d in_palm / d s
            S, h = self.shared_slots, 1e-6
            for k in range(S):
                step = torch.zeros_like(x[:, :n])
                step[:, n - S + k] = h
                moved = [transform_points(*self.bases(x[:, :n] + sign * step), local) for sign in (1.0, -1.0)]
                palm[..., n - S + k] = (R.unsqueeze(1) @ ((moved[0] - moved[1]) / (2 * h)).unsqueeze(-1)).squeeze(-1)
            fingers = torch.einsum("nab,nfbc,nfcj->nfaj", R, base_R, Jq)  # R B_R(s) dk/dq
        else:
            fingers = torch.einsum("nab,nfbj->nfaj", R, torch.einsum("fab,nfbj->nfaj", base_R, Jq))  # R B_R dk/dq
        mask = self._rows(self.mask, rows)
        if mask is not None:
            mask = mask.to(tips).cpu().unsqueeze(-1)
            tips, palm, fingers = tips * mask, palm * mask.unsqueeze(-1), fingers * mask.unsqueeze(-1)
        J = x.new_zeros(B, F, 3, n + F * j)
        J[..., :n] = palm
        J[..., n:].view(B, F, 3, F, j).diagonal(dim1=1, dim2=3).copy_(fingers.permute(0, 2, 3, 1))  # block diagonal
        return tips.reshape(B, -1), J.reshape(B, 3 * F, -1)

    def whole_pads(self, x: Tensor, rows: Tensor | None = None, margin: float | None = None
                   ) -> tuple[Tensor, Tensor]:
        """The surface model's pad residuals (:mod:`~graspnet_torch.solver.pad_term`) of x (B, m)
        of the trials ``rows``: (B, 3F) and their Jacobian (B, 3F, m): the palm's columns by its angular velocity
        (d m = w x m), each finger's R B_R d(R_f n)/dq; the shared joints' (the bases move) by
        central differences."""
        B, F, j, n = x.shape[0], len(self.idx), self.robot.joints_per_finger, self.n
        R, _, Jc = self.palm_frame_jacobian(x[:, :n])
        local, Jq = self.pads.local(x[:, n:].reshape(B, F, j), jacobian=True)  # (B, F, 3), (B, F, 3, j)
        RB = R.unsqueeze(1) @ self.bases(x[:, :n])[0]  # (B, F, 3, 3): each finger's base in the frame
        world = (RB @ local.unsqueeze(-1)).squeeze(-1)
        palm = -skew(world) @ Jc[:, None, 3:, :]  # (B, F, 3, n)
        for k in range(self.shared_slots):
            S, h = self.shared_slots, 1e-6
            step = torch.zeros_like(x[:, :n])
            step[:, n - S + k] = h
            moved = [R.unsqueeze(1) @ self.bases(x[:, :n] + sign * step)[0] @ local.unsqueeze(-1)
                     for sign in (1.0, -1.0)]
            palm[..., n - S + k] = ((moved[0] - moved[1]) / (2 * h)).squeeze(-1)
        r, D = self.pads.residual(world, rows, margin)
        palm, fingers = D @ palm, D @ RB @ Jq
        J = x.new_zeros(B, F, 3, n + F * j)
        J[..., :n] = palm
        J[..., n:].view(B, F, 3, F, j).diagonal(dim1=1, dim2=3).copy_(fingers.permute(0, 2, 3, 1))  # block diagonal
        return r.reshape(B, -1), J.reshape(B, 3 * F, -1)

    def whole_depths(self, x: Tensor, rows: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """The surface model's depth residuals of x (B, m) of the trials ``rows``: how far each
        link reaches into the object and obstacles, and into another finger (B, L), the root sum
        of squares of its spheres' penetrations and overlaps
        (:class:`~graspnet_torch.collision.proxy.CollisionProxy`: ``penetrations``,
        ``overlapping_pairs``; goal 0), and their Jacobian (B, L, m) by forward differences: the
        m + 1 points of every row in one batched call, on the spheres that penetrate or overlap at
        x only (the others' derivative is zero). In chunks of :data:`DEPTH_ROWS` rows (a batch of
        thousands of trials would hold (m + 1) times its frames at once)."""
        B, m = x.shape
        if B > DEPTH_ROWS:
            parts = [self.whole_depths(x[a: a + DEPTH_ROWS], None if rows is None else rows[a: a + DEPTH_ROWS])
                     for a in range(0, B, DEPTH_ROWS)]
            return torch.cat([v for v, _ in parts]), torch.cat([J for _, J in parts])
        X = (x.unsqueeze(1) + torch.cat([x.new_zeros(1, m), DEPTH_STEP * torch.eye(m, dtype=x.dtype)])).reshape(-1, m)
        every = None if rows is None else rows.repeat_interleave(m + 1)
        F, j, proxy = len(self.idx), self.robot.joints_per_finger, self.depth_proxy
        config = X[:, : self.n]
        frames = proxy.frames(self.palm_frame(config), self._every(X[:, self.n:].reshape(-1, F, j), every),
                              self.body(config), None, self._all_bases(config))  # (n_frames, B (m + 1), 3, 4)
        at = proxy.centres(frames[:, :: m + 1])  # (B, S, 3): every sphere at x
        value = proxy.penetrations(at, None, self._pid(rows))  # (B, S)
        t, a, b = proxy.overlapping_pairs(at)  # (N,): row, sphere, sphere
        link, L = proxy.sphere_links(), len(proxy.links)
        sq = proxy.link_depths(value).square()
        if t.numel():
            o2 = proxy.overlaps(at[t, a], at[t, b], a, b).square()
            sq = sq.index_put((t, link[a]), o2, accumulate=True).index_put((t, link[b]), o2, accumulate=True)
        spheres = torch.unique(torch.cat([(value > 0).any(0).nonzero().squeeze(1), a, b]))
        if spheres.numel() == 0:
            return sq.sqrt(), x.new_zeros(B, L, m)
        moved = proxy.centres(frames, spheres)  # (B (m + 1), S', 3)
        msq = proxy.link_depths(proxy.penetrations(moved, spheres, self._pid(every)), spheres).square()
        if t.numel():
            col = torch.searchsorted(spheres, torch.stack([a, b]))  # a, b among the spheres
            r = (t * (m + 1)).unsqueeze(1) + torch.arange(m + 1)  # (N, m + 1): each pair's rows
            o2 = proxy.overlaps(moved[r, col[0].unsqueeze(1)], moved[r, col[1].unsqueeze(1)], a, b).square()
            msq = msq.index_put((r.reshape(-1), link[a].repeat_interleave(m + 1)), o2.reshape(-1), accumulate=True)
            msq = msq.index_put((r.reshape(-1), link[b].repeat_interleave(m + 1)), o2.reshape(-1), accumulate=True)
        d, moved_d = sq.sqrt(), msq.sqrt().view(B, m + 1, L)
        return d, ((moved_d[:, 1:] - moved_d[:, :1]) / DEPTH_STEP).transpose(1, 2)

    def _count64(self, x: Tensor, rows: Tensor | None = None) -> Tensor:
        """The proxy's collision count (B,) of x (B, m) of the trials ``rows``."""
        F, j = len(self.idx), self.robot.joints_per_finger
        config = x[:, : self.n].to(self.lower)
        q = x[:, self.n:].reshape(-1, F, j).to(self.lower)
        return self.proxy.count(self.palm_frame(config), self._every(q, rows), self.body(config), None,
                                self._pid(rows), self._all_bases(config)).cpu()

    def local_solve(self, x: Tensor, iterations: int, tol: float = 0.0, done: Done | None = None,
                    trace: list[Tensor] | None = None, rows: Tensor | None = None,
                    prior: Prior | None = None, pad_margin: float | None = None) -> LMResult:
        """Levenberg-Marquardt (:func:`~graspnet_torch.least_squares.levenberg_marquardt`)
        on x (B, m) of the trials ``rows`` (None: all, in order): the contact fingertips onto
        their contacts, within bounds and limits, never into a collision the proxy sees (when
        there is one; the point model). The surface model instead adds residuals: the pads'
        normals (:meth:`whole_pads`) and, where there is an object, each link's depth in it, in
        the obstacles and in another finger (:meth:`whole_depths`). ``prior``: a residual term
        toward a centre (:class:`~graspnet_torch.least_squares.Prior`); ``pad_margin``: the pads'
        hinge chord (None: the term's own)."""
        trials = None if rows is None else rows.cpu()

        def tips(xx: Tensor, r: Tensor) -> tuple[Tensor, Tensor]:
            return self.whole_tips(xx, r if trials is None else trials[r])

        def tips_and_pads(xx: Tensor, r: Tensor) -> tuple[Tensor, Tensor]:
            rr = r if trials is None else trials[r]
            (v, J), (pv, pJ) = self.whole_tips(xx, rr), self.whole_pads(xx, rr, pad_margin)
            return torch.cat([v, pv], 1), torch.cat([J, pJ], 1)

        def tips_pads_depths(xx: Tensor, r: Tensor) -> tuple[Tensor, Tensor]:
            rr = r if trials is None else trials[r]
            (v, J), (dv, dJ) = tips_and_pads(xx, r), self.whole_depths(xx, rr)
            return torch.cat([v, dv], 1), torch.cat([J, dJ], 1)

        goal, model = self._goal64(trials), tips
        if self.pads is not None:  # the surface model: the pads' residuals too (goal 0)
            goal, model = torch.cat([goal, torch.zeros_like(goal)], -1), tips_and_pads
            if self.depth_proxy is not None:  # ... and how deep the links reach into the object (goal 0)
                links = len(self.depth_proxy.links)
                goal, model = torch.cat([goal, goal.new_zeros(*goal.shape[:-1], links)], -1), tips_pads_depths

        def count(xx: Tensor, r: Tensor) -> Tensor:
            return self._count64(xx, r if trials is None else trials[r])

        # The surface model takes no step filter: its pads must come onto the surface, and steps
        # kept only where the proxy's count does not rise left 10 of 12 moved-task problems
        # unsolved by 200 restarts (7 of 12 solved without it); FCL judges every result.
        filtered = self.proxy is not None and self.pads is None
        k, extra = 3 * len(self.idx), goal.shape[-1] - 3 * len(self.idx)

        def converged(e: Tensor) -> Tensor:  # the surface model: tips, pads and depths each near enough
            pads = (e[:, k: 2 * k].abs() < SURFACE_SLACK_M).all(-1)
            deep = (e[:, 2 * k: k + extra].abs() < SURFACE_DEPTH_SHARE * self.depth_allowance).all(-1)
            return (e[:, :k].norm(dim=-1) < max(tol, SURFACE_TIPS_M)) & pads & deep

        lo, hi = self.whole_bounds(trials)
        options = LMOptions(tol=tol, done=done, converged=converged if self.pads is not None and tol > 0 else None,
                            trace=trace, count=count if filtered else None, min_gain=self.min_gain)
        return levenberg_marquardt(model, goal, x, lo, hi, iterations, options, prior)

    def centre(self, x: Tensor, weight: float, iterations: int) -> Tensor:
        """x (B, m) moved toward the middle of the contact fingers' joint ranges while their
        fingertips stay on the contacts: Levenberg-Marquardt with a prior pulling each joint to
        the middle of its range (weight ``weight`` per range), the weight lowered to 0 in six
        steps of ``iterations`` each (the fit tightens as the pull fades). The result fits
        roughly; a plain :meth:`local_solve` lands it."""
        lo, hi = (torch.as_tensor(a)[self.idx].reshape(-1) for a in self.robot.finger_limits)
        span = hi - lo
        w = torch.zeros(x.shape[1], dtype=torch.float64)
        w[self.n:] = torch.where(span > 1e-9, weight / span.clamp_min(1e-9), 0.0)
        middle = torch.zeros_like(w)
        middle[self.n:] = (lo + hi) / 2
        for k in range(6):
            x = self.local_solve(x, iterations, prior=Prior(middle, w / 3 ** k)).x
        return x

    def whole_result(self, solved: LMResult, like: Tensor, rows: Tensor | None = None) -> tuple[Tensor, Evaluation]:
        """The configurations (B, n) and evaluation of solved x, in the dtype and device of ``like``."""
        B, F, j = solved.x.shape[0], len(self.idx), self.robot.joints_per_finger
        goal = self._goal64(None if rows is None else rows.cpu())
        finger_err = (goal - solved.value[:, : 3 * F]).reshape(B, F, 3).norm(dim=-1)
        kw = {"dtype": like.dtype, "device": like.device}
        contact = None
        if self.pads is not None:  # the pads' penalties (the norms of their residuals), as in evaluate
            penalty = solved.value[:, 3 * F: 6 * F].reshape(B, F, 3).norm(dim=-1)
            finger_err, contact = finger_err + penalty, self.pads.contact_errors(finger_err, penalty, rows).to(**kw)
        count = solved.count  # the step filter's count (the point model); else the proxy's, where it counts
        if count is None and self.proxy is not None:
            count = self._count64(solved.x, None if rows is None else rows.cpu())
        return solved.x[:, : self.n].to(**kw), Evaluation(
            error=finger_err.sum(1).to(**kw), finger_errors=finger_err.to(**kw),
            joints=solved.x[:, self.n:].reshape(B, F, j).to(**kw),
            collisions=None if count is None else count.to(like.device), contact_errors=contact)

    def _align(self, config: Tensor, evaluation: Evaluation, tolerance: float) -> tuple[Tensor, Evaluation]:
        """The grasps among the configurations (T, n) (``grasped`` within ``tolerance``) with
        their pads turned toward the object's inward normals as far as they stay grasps (the
        surface model): the whole polish with the pads' hinge at :data:`ALIGN_SHARE` of the cone,
        then the usual polish from there (the tips back on their contacts, the pads free inside
        the margin); a grasp takes it where it is still one, the exact check (FCL) finds it clear
        and its worst pad has turned in. A pad at the cone's edge (29 degrees, where the hinge
        starts) is at the edge of the friction cone too (0.6: 31 degrees): of 100 moved tasks'
        grasps 86 held 6/6 in MuJoCo as the search left them, 93 turned in."""
        landed = self.grasped(evaluation, tolerance).cpu()
        if self.pads is None or not bool(landed.any()):
            return config, evaluation
        idx = landed.nonzero().squeeze(1)
        x = self._whole_start(config[idx], evaluation.joints[idx], idx)
        half = 2 * math.sin(ALIGN_SHARE * math.asin(self.pads.cone / 2))  # the chord of the narrower cone
        turned = self.local_solve(x, self.polish_iterations, rows=idx, pad_margin=half).x
        back = self.local_solve(turned, self.polish_iterations, self.polish_tol, rows=idx)
        new_config, new_ev = self.whole_result(back, config, idx)

        def worst(xx: Tensor) -> Tensor:  # the widest pad (weighted chord) of x (B, m)
            return self.whole_pads(xx, idx, 0.0)[0].reshape(xx.shape[0], -1, 3).norm(dim=-1).amax(-1)

        better = self.grasped(new_ev, tolerance).cpu() & (worst(back.x) < worst(x))
        if not bool(better.any()):
            return config, evaluation
        candidate = config.index_copy(0, idx, new_config.to(config))
        trial = evaluation.put(idx.to(config.device), new_ev, candidate)
        keep = idx[better]
        keep = keep[self.confirm(candidate, trial, keep)]
        take = torch.zeros(config.shape[0], dtype=torch.bool, device=config.device)
        take = take.index_fill(0, keep.to(config.device), True)
        return torch.where(take.unsqueeze(1), candidate, config), trial.where(take, evaluation)

    def polish(self, config: Tensor, evaluation: Evaluation, trials: Tensor, done: Done | None = None
               ) -> tuple[Tensor, Evaluation]:
        """``solver.polish.iterations`` Levenberg-Marquardt steps on the whole configuration (palm
        pose or arm joints) together with the contact fingers' free joints (:meth:`local_solve`),
        from the reported ones, of the trials ``trials``: never worse. The loop finds the basin;
        the fingers alone, with the palm fixed, end where the palm left them (a few mm), the whole
        polish lands in it. Rows stop below ``solver.polish.tolerance_mm`` or when ``done`` says so."""
        x = self._whole_start(config, evaluation.joints, trials)
        solved = self.local_solve(x, self.polish_iterations, self.polish_tol, done, rows=trials)
        return self.whole_result(solved, config, trials)

