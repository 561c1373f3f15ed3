"""The gripper's environment (MANUS, paper section 7): 9 joints -> two gripper points -> eq. 24-29.

The configuration network chooses the mobile base (x, y, yaw) and the arm's joints (n = 9 for
``manus``); forward kinematics places the two points marked on the jaws; the evaluation is
d (eq. 26-28: the smaller of the two pairings' summed distances, metres) and the alignment
|n_gripper . n_object| (eq. 24), from which :class:`~graspnet_torch.rewards.Reward` builds
R = (R1 + R2) / 2 (eq. 29), shaped by the collision count (R2-R4) when the problem has an object
or obstacles. No FCNN.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import Tensor

from graspnet_torch.collision.cache import proxy_for
from graspnet_torch.collision.scene import has_environment
from graspnet_torch.errors import ProblemError
from graspnet_torch.least_squares import LMOptions, LMResult, levenberg_marquardt
from graspnet_torch.rewards import manus_reward, r1
from graspnet_torch.robot.frames import RobotLevels
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.robot.transforms import rt_to_pose
from graspnet_torch.solver.config import SolverCfg
from graspnet_torch.solver.environment import Done, Environment, Evaluation, Report
from graspnet_torch.solver.search_space import gripper_bounds
from graspnet_torch.tasks.problem import GraspProblem

if TYPE_CHECKING:
    from graspnet_torch.fcnn.ik import FingerIK
    from graspnet_torch.solver.result import TrialResult

__all__ = ["ALIGNMENT_MIN", "CLEARANCE_M", "GripperEnvironment"]

CLEARANCE_M = 0.005  # the loop and the polish keep 5 mm from obstacles, floor and own links (proxy margin)
ALIGNMENT_MIN = 0.999  # a gripper's grasp: |n_gripper . n_object| above this (about 2.6 degrees)
SETTLE_DAMPING = 0.05  # _refine (gripper.settle): the settling steps' fixed lambda (m), a couple of steps
# _least_squares (the polish, solver=dls): lambda's start, least and largest (m); / 3 kept, * 4 refused
POLISH_DAMPING = (1e-2, 1e-4, 10.0)
BOUND_EDGE = 1e-9  # _least_squares: a joint within this of its bound (m or rad) is at it (the active set)


class GripperEnvironment(Environment):
    """Evaluates body configurations of a gripper robot for one two-point problem, or for a batch
    of problems (``runs`` trials each, trial t on problem t // runs), batched.

    Attributes:
        n: body joints (9 for ``manus``: base x, y, yaw + 6 arm joints).
        lower, upper: (n,) search bounds (m / rad), or (T, n) for a batch of problems.
        problem_index: (T,) each trial's problem in a batch, or None (one problem).
        subsets: True: once most trials have stopped, the loop evaluates only the others.
    """

    error_key = "distance_mm"
    subsets = True

    def __init__(self, robot: Robot, problem: GraspProblem | Sequence[GraspProblem], solver: SolverCfg,
                 ik: FingerIK | None = None, dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu",
                 collisions: bool = False, runs: int = 1):
        problems = [problem] if isinstance(problem, GraspProblem) else list(problem)
        for p in problems:
            if robot.gripper_kernel is None or p.points is None:
                raise ProblemError(f"{p.source}: robot '{robot.name}' has no gripper points or the problem no "
                                   f"'points'")
        self.robot, self.problems, self.problem = robot, problems, problems[0]
        self.world_problems = problems
        self.n = len(robot.body_joint_names)
        cfg = solver.gripper
        self.refine, self.final_refine, self.tolerance_mm = cfg.settle, cfg.polish_iterations, solver.tolerance_mm
        # inside the loop (solver.polish.from_r), a trial near a grasp is polished as a hand's is
        self.polishes = solver.polish.mode == "whole" and solver.polish.iterations > 0
        self.polish_iterations, self.polish_tol = solver.polish.iterations, solver.polish.tolerance_mm / 1000
        bounds = [gripper_bounds(robot, p, cfg.approach_m, cfg.approach_deg) for p in problems]
        targets = np.stack([p.points_world() for p in problems])  # (P, 2, 3)
        kw = {"dtype": dtype, "device": device}
        self.problem_index = None
        if len(problems) > 1:
            self.problem_index = torch.arange(len(problems), device=device).repeat_interleave(runs)
            rep = np.repeat(np.arange(len(problems)), runs)
            self._bounds = (np.stack([b[0] for b in bounds])[rep], np.stack([b[1] for b in bounds])[rep])
            targets = targets[rep]
        else:
            self._bounds = bounds[0]
        self.lower = torch.as_tensor(self._bounds[0], **kw)
        self.upper = torch.as_tensor(self._bounds[1], **kw)
        self._targets64 = torch.as_tensor(targets, dtype=torch.float64)  # (T or 1, 2, 3)
        self.targets = self._targets64.to(**kw)
        # the body chain's frames P_1..P_n as batched products (robot/frames.py), from which the
        # gripper points and their Jacobian follow in closed form (see :meth:`kinematics`)
        levels = RobotLevels(robot, dtype, device)
        self._chain = levels.body
        self._axes = torch.as_tensor(robot.body.axes, **kw).unsqueeze(-1)  # (n, 3, 1)
        self._revolute = self._chain.revolute.view(1, -1, 1, 1)
        self._palm_offset = levels.palm_offset
        zero = robot.link_frames(robot.home_posture())
        palm_inv = np.linalg.inv(zero[robot.cfg.palm_link])
        self._points_local = torch.as_tensor(np.stack([(palm_inv @ zero[name])[:, 3] for name in
                                                       robot.cfg.gripper_points], axis=1), **kw)  # (4, 2)
        self.proxy = None
        if collisions and has_environment(robot, self.problem):
            self.proxy = proxy_for(robot, problems, dtype=dtype, device=device, clearance=CLEARANCE_M)
            self._no_fingers = torch.zeros(1, 0, 0, **kw)
        self.counts_collisions = self.proxy is not None

    def proposal_input(self) -> tuple[Tensor, Tensor]:
        """The object's two points in the world, as two slots: (R, 2, 3), mask (R, 2) of ones."""
        targets = self._targets64.float()
        return targets, torch.ones(targets.shape[:2])

    def evaluate(self, config: Tensor, trials: Tensor | None = None) -> Evaluation:
        """config: (T, n) -> the ``solver.gripper.settle`` settling steps, then d (T,) of eq. 26 as
        ``error``, the alignment (T,) of eq. 24 and, with a proxy, the collision count; ``config``
        the settled configurations. ``trials`` (B,): the trials the rows of ``config`` (B, n)
        belong to, when the loop evaluates only its active trials (None: all, in order)."""
        return self.settled(config, trials, True)

    def settled(self, config: Tensor, trials: Tensor | None = None, settle: bool = True) -> Evaluation:
        """:meth:`evaluate`, with the settling steps (``settle``) or of the configurations as given."""
        targets, lower, upper, pid = self._per_trial(trials)
        if self.refine > 0 and settle:
            config, levels, points = self._refine(config, self.refine, targets, lower, upper)
        else:
            levels, points, _ = self.kinematics(config)
        _r, alignment, _r2, d = manus_reward(points, targets.expand_as(points))
        collisions = None
        if self.proxy is not None:
            end = levels[:, -1] @ self._palm_offset
            none = self._no_fingers.expand(config.shape[0], 0, 0)
            collisions = self.proxy.count((end[:, :3, :3], end[:, :3, 3]), none, config, list(levels.unbind(1)), pid)
        return Evaluation(error=d, alignment=alignment, collisions=collisions, config=config)

    def reward_base(self, evaluation: Evaluation, a: float) -> Tensor:
        """R = (R1 + R2) / 2 of eq. 29: R1 = |n_gripper . n_object| (eq. 24), R2 = 1 - tanh(a d)."""
        return (evaluation.alignment + r1(evaluation.error, a)) / 2

    def grasped(self, evaluation: Evaluation, tolerance: float) -> Tensor:
        """d within ``tolerance`` metres, aligned above :data:`ALIGNMENT_MIN`, no collision where counted."""
        ok = (evaluation.error < tolerance) & (evaluation.alignment > ALIGNMENT_MIN)
        if evaluation.collisions is not None:
            ok = ok & (evaluation.collisions == 0)
        return ok

    def kinematics(self, q: Tensor, jacobian: bool = False) -> tuple[Tensor, Tensor, Tensor | None]:
        """q (T, n) -> the chain's frames P_1..P_n (T, n, 4, 4), the gripper points (T, 2, 3) and,
        if asked, their Jacobian (T, 6, n). Joint k turns about (or slides along) its axis a_k,
        which P_{k+1} carries into the world (M_k(q) leaves a_k and, revolute, the origin fixed):

            w_k = R(P_{k+1}) a_k,  o_k = t(P_{k+1});  dp/dq_k = w_k x (p - o_k) (revolute), w_k (prismatic)
        """
        levels = torch.stack(self._chain.levels(q, self.n), dim=1)  # (T, n, 4, 4)
        points = self._points(levels)
        if not jacobian:
            return levels, points, None
        return levels, points, self._jacobian(levels, points)

    def _points(self, levels: Tensor) -> Tensor:
        end = levels[:, -1] @ self._palm_offset  # the palm (gripper) frame
        return (end[:, :3, :] @ self._points_local).transpose(1, 2)  # (T, 2, 3)

    def _jacobian(self, levels: Tensor, points: Tensor) -> Tensor:
        T = levels.shape[0]
        w = (levels[:, :, :3, :3] @ self._axes).squeeze(-1)  # (T, n, 3) joint axes in the world
        arm = points.unsqueeze(1) - levels[:, :, None, :3, 3]  # (T, n, 2, 3): p - o_k
        col = torch.where(self._revolute, torch.linalg.cross(w.unsqueeze(2).expand_as(arm), arm), w.unsqueeze(2))
        return col.reshape(T, self.n, 6).transpose(1, 2)

    def _per_trial(self, trials: Tensor | None) -> tuple[Tensor, Tensor, Tensor, Tensor | None]:
        """Targets (B or 1, 2, 3), bounds (B or 1, n) and problem indices (B,) of some trials."""
        if trials is None or self.problem_index is None:
            return self.targets, self.lower, self.upper, self.problem_index
        return self.targets[trials], self.lower[trials], self.upper[trials], self.problem_index[trials]

    def _refine(self, q: Tensor, steps: int, targets: Tensor, lower: Tensor, upper: Tensor
                ) -> tuple[Tensor, Tensor | None, Tensor]:
        """``steps`` Levenberg-Marquardt steps (:func:`~graspnet_torch.least_squares.levenberg_marquardt`,
        fixed damping :data:`SETTLE_DAMPING`, the Jacobian of :meth:`kinematics`, no collision test,
        steps clamped to the bounds) of the gripper points towards each trial's nearer pairing, kept
        where they lower the point error: the learner proposes, a few steps settle the proposal, and
        that is evaluated and reported. q: (T, n), targets: (T or 1, 2, 3), lower, upper: (T or 1, n)
        -> q (T, n), its frames (T, n, 4, 4; None without a proxy, their user), points (T, 2, 3)."""
        T = q.shape[0]
        tg = targets.expand(T, 2, 3)
        lower, upper = lower.expand(T, -1), upper.expand(T, -1)
        q = torch.minimum(torch.maximum(q, lower), upper)  # as the LM starts: its first model call is at this q
        start = [self.kinematics(q, jacobian=True)]
        levels = start[0][0]
        goal = torch.where(_pairing(start[0][1], tg).view(-1, 1, 1), tg.flip(1), tg).reshape(T, 6)
        tried: list[tuple[Tensor, Tensor, Tensor]] = []  # (rows, x, frames) of every trial point

        def points(x: Tensor, rows: Tensor) -> tuple[Tensor, Tensor]:
            if start:  # the first call: at q
                _levels, pts, J = start.pop()
            else:
                frames, pts, J = self.kinematics(x, jacobian=True)
                tried.append((rows, x, frames))
            return pts.reshape(-1, 6), J

        settle = LMOptions(lam=SETTLE_DAMPING, lam_min=SETTLE_DAMPING, lam_max=SETTLE_DAMPING, active_set=False)
        solved = levenberg_marquardt(points, goal, q, lower, upper, steps, settle)
        if self.proxy is None:
            return solved.x, None, solved.value.view(T, 2, 3)
        for rows, x, frames in tried:  # each row's frames: those of the trial point it kept (else q's)
            levels = levels.index_copy(0, rows, torch.where((solved.x[rows] == x).all(1).view(-1, 1, 1, 1), frames,
                                                            levels[rows]))
        return solved.x, levels, solved.value.view(T, 2, 3)

    def finish(self, config: Tensor, evaluation: Evaluation, done: Done | None = None) -> tuple[Tensor, Evaluation]:
        """Polish the reported configurations: ``solver.gripper.polish_iterations`` damped least-squares steps (float64)
        on the two gripper points against the object points of each trial's nearer pairing,
        within the bounds, each step kept only where it lowers d (never worse). The analogue of
        the hand's final finger refinement: the loop finds the basin, the polish lands in it.
        Every trial is polished for the whole budget (``done`` is not used: the MANUS protocol's
        figures are those of every learner).

            dq = J^T (J J^T + lambda^2 I)^-1 e,   J = d(points)/dq (6 x n, the kernel's analytic Jacobian, float64)
        """
        iterations = self.final_refine
        if iterations <= 0:
            return config, evaluation
        q = self.clamp(config)
        T = q.shape[0]
        targets = self._targets64.expand(T, 2, 3)
        goal = torch.cat([targets.reshape(T, 6), targets.flip(1).reshape(T, 6)])
        solved = self._least_squares(q.repeat(2, 1), goal, iterations)  # both pairings (eq. 26-28) at once
        q2, err = solved.x, solved.err
        crossed = err[T:] < err[:T]
        q = torch.where(crossed.unsqueeze(1), q2[T:], q2[:T])
        ev = self.evaluate(q.to(config))
        return ev.config, ev

    def _least_squares(self, q: Tensor, goal: Tensor, iterations: int, tol: float = 0.0,
                       done: Callable[[Tensor], Tensor] | None = None, trace: list[Tensor] | None = None,
                       trials: Tensor | None = None) -> LMResult:
        """Levenberg-Marquardt (:func:`~graspnet_torch.least_squares.levenberg_marquardt`)
        on the gripper points, float64, within the bounds, never into a collision the proxy sees.

        q: (B, n) start, B a multiple of the trials (row r is trial r % T), or the rows of the
        trials ``trials`` (B,); goal: (B, 6) the two object points in the pairing of each row.
        Returns where each row ended (``x``, ``err``).
        """
        lo, hi = (torch.as_tensor(a) for a in self._bounds)
        T = self.lower.shape[0] if self.lower.dim() == 2 else None
        trial_of = None
        if T is not None:  # a batch of problems: the trial of each row
            trial_of = trials.cpu() if trials is not None else torch.arange(q.shape[0]) % T
            lo, hi = lo[trial_of], hi[trial_of]

        def points(x: Tensor, rows: Tensor) -> tuple[Tensor, Tensor]:
            p, J = self.robot.gripper_points_jacobian(x)  # (B, 2, 3), (B, 2, 3, n)
            return p.reshape(-1, 6), J.reshape(-1, 6, self.n)

        def count(x: Tensor, rows: Tensor) -> Tensor:
            pid = None if trial_of is None else self.problem_index[trial_of[rows]]
            return self._count(x, pid)

        lam, lam_min, lam_max = POLISH_DAMPING
        return levenberg_marquardt(points, goal, q, lo, hi, iterations, LMOptions(
            lam=lam, lam_min=lam_min, lam_max=lam_max, edge=BOUND_EDGE, tol=tol, done=done, trace=trace,
            count=count if self.proxy is not None else None))

    # solver=dls: the whole configuration is the body's joints (no fingers)

    def random_whole(self, trials: int, gen: torch.Generator) -> Tensor:
        """(T, n) configurations uniform within each trial's bounds, float64 on the CPU."""
        lo, hi = (torch.as_tensor(a) for a in self._bounds)
        u = torch.rand(trials, self.n, generator=gen, dtype=torch.float64, device=gen.device).cpu()
        return lo + (hi - lo) * u

    def whole_of(self, posture: Posture) -> Tensor:
        """The posture's body joints (1, n), within the (first) trial's bounds."""
        lo, hi = (torch.as_tensor(a, dtype=torch.float64).reshape(-1, self.n)[0] for a in self._bounds)
        return torch.minimum(torch.maximum(posture.body.to(torch.float64).reshape(1, -1), lo), hi)

    def local_solve(self, x: Tensor, iterations: int, tol: float = 0.0, done: Done | None = None,
                    trace: list[Tensor] | None = None, rows: Tensor | None = None) -> LMResult:
        """Levenberg-Marquardt from x (T, n) onto both pairings of the object points at once
        (eq. 26-28), each trial keeping its better one; a trial stops once either pairing is
        within ``tol`` or ``done`` says so. ``rows``: the trials of x's rows (None: every trial, in order)."""
        T = x.shape[0]
        targets = self._targets64 if rows is None or self._targets64.shape[0] == 1 else self._targets64[rows.cpu()]
        targets = targets.expand(T, 2, 3)
        goal = torch.cat([targets.reshape(T, 6), targets.flip(1).reshape(T, 6)])

        def either(stopped: Tensor) -> Tensor:
            one = stopped[:T] | stopped[T:]
            if done is not None:
                one = one | done(one)
            return one.repeat(2)

        both: list[Tensor] | None = [] if trace is not None else None
        solved = self._least_squares(x.repeat(2, 1), goal, iterations, tol, either, both,
                                     None if rows is None else rows.repeat(2))
        if trace is not None:
            trace.extend(torch.minimum(e[:T], e[T:]) for e in both)
        crossed = solved.err[T:] < solved.err[:T]
        pick = torch.where(crossed, torch.arange(T, 2 * T), torch.arange(T))
        return LMResult(x=solved.x[pick], err=solved.err[pick], value=solved.value[pick],
                        count=None if solved.count is None else solved.count[pick],
                        steps=torch.maximum(solved.steps[:T], solved.steps[T:]))

    def whole_result(self, solved: LMResult, like: Tensor, rows: Tensor | None = None) -> tuple[Tensor, Evaluation]:
        """The configurations (B, n) of solved rows (of the trials ``rows``, None: all) and their
        evaluation (no settling steps)."""
        config = solved.x.to(like)
        return config, self.settled(config, rows, settle=False)

    def polish(self, config: Tensor, evaluation: Evaluation, trials: Tensor, done: Done | None = None
               ) -> tuple[Tensor, Evaluation]:
        """``solver.polish.iterations`` Levenberg-Marquardt steps on both pairings of the object
        points (:meth:`local_solve`) from the configurations (B, n) of the trials ``trials`` (B,),
        never into a collision the proxy sees: a learner near a grasp lands in it, and stops.
        Rows stop below ``solver.polish.tolerance_mm`` or when ``done`` says so."""
        solved = self.local_solve(self.clamp(config, trials), self.polish_iterations, self.polish_tol, done,
                                  rows=trials)
        return self.whole_result(solved, config, trials)

    def _count(self, q: Tensor, pid: Tensor | None = None) -> Tensor:
        """(B,) the proxy's collision count of configurations (B, n) of the trials of problems
        ``pid`` (B,); None: all trials (B = T) or copies of them (trial t's at t, t + T, ...)."""
        config = q.to(self.lower)
        if pid is None:
            pid = self.problem_index
        if pid is not None and config.shape[0] != pid.shape[0]:
            pid = pid.repeat(config.shape[0] // pid.shape[0])
        levels, palm = self.proxy.body_levels_and_palm(config)
        return self.proxy.count(palm, self._no_fingers.expand(config.shape[0], 0, 0), config, levels, pid).to(q.device)

    def clamp(self, config: Tensor, rows: Tensor | None = None) -> Tensor:
        """(B, n) configurations of the trials ``rows`` (None: all T) clipped to their bounds,
        float64 on the CPU."""
        lo, hi = (torch.as_tensor(a) for a in self._bounds)
        if rows is not None and lo.dim() == 2:
            lo, hi = lo[rows.cpu()], hi[rows.cpu()]
        return torch.clamp(config.detach().to(torch.float64).cpu(), lo, hi)

    def report(self, config: Tensor, evaluation: Evaluation, rows: Tensor | None = None) -> Report:
        """Per trial (of ``rows``, None: all), recomputed in float64: every body joint by name
        (m / degrees), the palm (gripper) pose, the two gripper points, d in mm, the alignment and
        ``error`` (d, metres)."""
        q = self.clamp(config, rows)
        points = self.robot.gripper_points(q)
        targets = self._targets64 if rows is None or self._targets64.shape[0] == 1 else self._targets64[rows.cpu()]
        _r, alignment, _r2, d = manus_reward(points, targets.expand_as(points))
        palm = rt_to_pose(*self.robot.palm_frame(q))
        deg = 180.0 / math.pi
        out = []
        for k in range(q.shape[0]):
            pose = palm[k].tolist()
            out.append({
                "arm_joints": self.robot.body_joints_to_file(q[k]),
                "palm_pose": pose[:3] + [a * deg for a in pose[3:]],
                "gripper_points": points[k].tolist(),
                "distance_mm": float(d[k]) * 1000,
                "alignment": float(alignment[k]),
            })
        evaluation = Evaluation(error=torch.tensor([float(x) for x in d], dtype=torch.float64),
                                alignment=torch.tensor([f["alignment"] for f in out], dtype=torch.float64))
        return Report(fields=out, evaluation=evaluation, error_mm=[f["distance_mm"] for f in out],
                      landed=[f["distance_mm"] <= self.tolerance_mm and f["alignment"] > ALIGNMENT_MIN for f in out])

    @classmethod
    def check(cls, robot: Robot, problem: GraspProblem, solver: SolverCfg) -> None:
        """The problem's ``approach`` names known joints within their limits (:func:`gripper_bounds`)."""
        gripper_bounds(robot, problem, solver.gripper.approach_m, solver.gripper.approach_deg)

    @staticmethod
    def describe(trial: TrialResult) -> str:
        return f"d = {trial.distance_mm:.3g} mm, alignment {trial.alignment:.4f}"

    @staticmethod
    def summary(trial: TrialResult, fingers: Sequence[str]) -> str:
        """d (eq. 26) and the alignment (eq. 24)."""
        return (f"d {trial.distance_mm:.3f} mm, alignment {trial.alignment:.6f} "
                f"({math.degrees(math.acos(min(1.0, trial.alignment))):.2f} deg)")

    @staticmethod
    def columns(trial: TrialResult, fingers: Sequence[str]) -> dict[str, float]:
        return {"d mm": trial.distance_mm, "alignment": round(trial.alignment, 6)}

    @staticmethod
    def marks(problem: GraspProblem, trial: TrialResult) -> np.ndarray:
        """The object's two points and the gripper's two."""
        return np.concatenate([problem.points_world(), np.asarray(trial.gripper_points)])


def _pairing(points: Tensor, targets: Tensor) -> Tensor:
    """(T,) True where the crossed pairing (eq. 28) is the nearer: gripper point 1 -> object point 2.
    points, targets: (T, 2, 3)."""
    d1 = (targets - points).norm(dim=-1).sum(-1)
    d2 = (targets.flip(-2) - points).norm(dim=-1).sum(-1)
    return d2 < d1
