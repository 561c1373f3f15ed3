"""``gt.Solver``: a solver built once per robot and settings, for programs that call it many times,
and for sequences (tracking).

    solver = gt.Solver("hand")                    # the robot, its FCNN, its settings: once
    result = solver.solve(problem)                # the search only
    result = solver.solve(problem, start=result)  # warm: from a previous result's posture
    results = solver.track(frames)                # a sequence, each frame from the last

A warm start runs Levenberg-Marquardt over the whole configuration (the palm pose, searched in
the start palm's own frame, or the arm's joints, with the contact fingers' joints: the local
solver of ``solver=dls``) from the given posture, no finger joint moving more than
``solver.polish.warm_step_deg``; where it does not land, once more from the posture moved toward
mid-range joints with its contacts held (``solver.polish.centre``). When it lands (every contact
within ``solver.tolerance_mm``, no collision) that is the result, one trial. Otherwise the frame
gets the full search (``solver.method``, ``trials`` trials), with the warm trial kept among its
trials, the successful trial nearest the start reported, and (as for a sequence's first frame)
centred. ``search=False`` (a caller with other starts to try: the grasp synthesis' sampled
postures) stops at the first landing: a start that does not land is the result, not retried
centred, not searched.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path

import torch
from torch import Tensor

from graspnet_torch.errors import ProblemError
from graspnet_torch.fcnn.ik import FingerIK
from graspnet_torch.robot.config import RobotCfg
from graspnet_torch.robot.robot import Posture, Robot
from graspnet_torch.solver import api
from graspnet_torch.solver.config import DEFAULT_TRIALS, NoiseCfg, RewardCfg, SolverCfg
from graspnet_torch.solver.dls import run_dls
from graspnet_torch.solver.environment import Environment
from graspnet_torch.solver.environments import build_environment
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.solver.result import GraspResult, TrialResult
from graspnet_torch.srv.network import SRVNetCfg
from graspnet_torch.tasks.problem import GraspProblem
from graspnet_torch.threads import check_threads, torch_threads

__all__ = ["Solver", "Start"]

CENTRE_STEPS = 5  # Levenberg-Marquardt iterations of each of the six steps of a centring (solver.polish.centre)

Start = GraspResult | TrialResult | Posture
"""What a warm start starts from: a result (its best trial), a trial, or a posture."""


class Solver:
    """A robot, its trained finger IK (FCNN: read when a search first needs it) and solver settings,
    resolved once.

    Args:
        robot: a shipped robot's name, a robot config (or its YAML path), or a built robot.
        trials: as :func:`gt.solve` (so are the next ones; None: the robot's ``solver_defaults``
            over the paper's).
        seed: as :func:`gt.solve`.
        max_iterations: as :func:`gt.solve`.
        solver: as :func:`gt.solve`.
        srv: as :func:`gt.solve`.
        reward: as :func:`gt.solve`.
        noise: as :func:`gt.solve`.
        device: as :func:`gt.solve`.
        finger_ik: the FCNN to use instead of the robot's trained one.
        threads: torch CPU threads for each call's work (None: the package's default, 1); the
            caller's count is put back after each call.

    Collision models of a problem's scene are built once per distinct geometry
    (:mod:`graspnet_torch.collision.cache`), problem files once per file version.
    """

    def __init__(self, robot: str | Path | RobotCfg | Robot = "hand", *, trials: int = DEFAULT_TRIALS, seed: int = 0,
                 max_iterations: int | None = None, solver: SolverCfg | None = None, srv: SRVNetCfg | None = None,
                 reward: RewardCfg | None = None, noise: NoiseCfg | float | None = None,
                 finger_ik: FingerIK | None = None, device: str | torch.device = "cpu", threads: int | None = None):
        self.robot = api.as_robot(robot)
        self._finger_ik = finger_ik  # None: the robot's, read when a search first needs it
        self.trials, self.seed, self.device = int(trials), int(seed), device
        self.threads = check_threads(threads)
        self.noise = NoiseCfg(float(noise)) if isinstance(noise, int | float) else (noise or NoiseCfg())
        self.solver_cfg, self.srv, self.reward = api.settings_of(self.robot, solver, srv, reward, max_iterations)

    @property
    def finger_ik(self) -> FingerIK | None:
        """The FCNN the search uses: the one given, else the robot's trained one, read on first use
        (a warm start does not need it: a robot without a checkpoint solves warm starts; its
        search raises ``CheckpointError`` with the command that trains one)."""
        if self._finger_ik is None:
            self._finger_ik = api.finger_ik_for(self.robot)
        return self._finger_ik

    def __repr__(self) -> str:
        return f"Solver({self.robot.name!r}, trials={self.trials}, method={self.solver_cfg.method!r})"

    def problem(self, problem: GraspProblem | str | Path) -> GraspProblem:
        """A problem, a problem file or a shipped task's name -> the problem, checked to be this robot's."""

        p = api.as_problem(problem)
        if p.robot != self.robot.name:
            raise ProblemError(f"{p.source}: the problem is for robot '{p.robot}', this solver's is "
                               f"'{self.robot.name}'")
        return p

    def solve(self, problem: GraspProblem | str | Path, *, start: Start | None = None, seed: int | None = None,
              search: bool = True) -> GraspResult:
        """One problem: the search (``trials`` trials), or first a warm start from ``start`` (see
        the module's docstring). ``search=False``: a warm start that does not land is the result
        (one trial, not a success): neither the centred retry nor the search follows (for callers
        that have other starts to try: of the shipped hand's 256 sampled starts on 10 objects, the 72
        that did not land were retried and none landed, at 15 % of the solving time where some did)."""
        with torch_threads(self.threads):
            return self._solve(self.problem(problem), start, self.seed if seed is None else int(seed), search)

    def _solve(self, problem: GraspProblem, start: Start | None, seed: int, search: bool = True) -> GraspResult:
        warm = None
        if start is not None:
            warm = self._warm(problem, self._posture(start), seed, retry=search)
            if warm.success or not search:
                return warm
        cold = api.solve_with(self.robot, self.finger_ik, problem, self.trials, seed, self.solver_cfg, self.srv,
                              self.reward, self.noise, self.device)
        if warm is None:
            return cold
        cold.trials = warm.trials + cold.trials  # the warm trial, then the search's
        cold.chosen = self._nearest(cold, self._posture(start))
        return self._centred(problem, cold, seed)

    def solve_many(self, problems: Sequence[GraspProblem | str | Path], *, seed: int | None = None
                   ) -> list[GraspResult]:
        """P problems of this robot as one batch (:func:`gt.solve_many`)."""
        return api.solve_many([self.problem(p) for p in problems], trials=self.trials,
                              seed=self.seed if seed is None else int(seed), solver=self.solver_cfg, srv=self.srv,
                              reward=self.reward, noise=self.noise, robot=self.robot, finger_ik=self.finger_ik,
                              device=self.device, threads=self.threads)

    def track(self, problems: Iterable[GraspProblem | str | Path], *, start: Start | None = None
              ) -> list[GraspResult]:
        """A sequence of frames in order, each warm-started from the previous frame's result (the
        first from ``start``, else searched), falling back to a full search where the warm start
        does not land. Frame k searches with seed ``seed + k``."""
        return list(self.iter_track(problems, start=start))

    def iter_track(self, problems: Iterable[GraspProblem | str | Path], *, start: Start | None = None
                   ) -> Iterator[GraspResult]:
        """:meth:`track`, one frame's result at a time (frames may arrive while it runs). A
        frame that fails leaves the start of the next one where the last success was."""
        previous = start
        for k, problem in enumerate(problems):
            with torch_threads(self.threads):  # each frame's work; the caller's count between frames
                result = self.solve(problem, start=previous, seed=self.seed + k)
                if previous is None:  # the search's posture, moved away from the limits for the frames after it
                    result = self._centred(self.problem(problem), result, self.seed + k)
            previous = result if result.success or previous is None else previous
            yield result

    # -- the warm start --------------------------------------------------------------------------

    def _nearest(self, result: GraspResult, posture: Posture) -> int | None:
        """Among the successful collision-free trials, the one whose joints (fingers, and an arm's)
        move least from ``posture`` (the largest change of any joint): no jump between frames where
        the search found a nearby solution. None: no such trial (the usual best stands)."""
        ok = [k for k, t in enumerate(result.trials) if t.success and t.collisions == 0]
        if not ok:
            return None

        def moved(trial: TrialResult) -> float:
            other = trial_posture(self.robot, trial)
            change = [(other.fingers - posture.fingers).abs().max(), (other.body - posture.body).abs().amax(0)
                      if other.body.numel() else torch.zeros(())]
            return float(torch.stack(change).max())

        return min(ok, key=lambda k: moved(result.trials[k]))

    def _centred(self, problem: GraspProblem, result: GraspResult, seed: int) -> GraspResult:
        """A searched frame of a sequence: its reported trial moved toward the middle of the
        fingers' joint ranges, contacts held (``solver.polish.centre``), then landed as a warm
        start is; where that lands, it is added as the last trial and reported (else the result
        stands)."""
        weight = self.solver_cfg.polish.centre
        if weight is None or not result.success:
            return result
        posture = self._posture(result)
        env = self._around(problem, posture)
        x = env.centre(env.whole_of(posture), weight, CENTRE_STEPS)
        centred = self._land(problem, env, x, seed)
        if centred.success:
            result.trials = result.trials + centred.trials
            result.chosen = len(result.trials) - 1
        return result

    def _posture(self, start: Start) -> Posture:
        if isinstance(start, Posture):
            return start
        return trial_posture(self.robot, start.best if isinstance(start, GraspResult) else start)

    def _warm(self, problem: GraspProblem, posture: Posture, seed: int, retry: bool = True) -> GraspResult:
        """Levenberg-Marquardt from the posture (``solver.polish.iterations`` steps, to
        ``solver.polish.tolerance_mm``), its fingers' joints within ``solver.polish.warm_step_deg``
        of the posture's; where it does not land and ``retry``, once more from the posture centred
        (``solver.polish.centre``, in the same environment): a result of one trial."""
        env = self._around(problem, posture)
        x = env.whole_of(posture)
        warm = self._land(problem, env, x, seed)
        weight = self.solver_cfg.polish.centre
        if warm.success or weight is None or not retry:
            return warm
        return self._land(problem, env, env.centre(x, weight, CENTRE_STEPS), seed)

    def _around(self, problem: GraspProblem, posture: Posture) -> Environment:
        cfg = self.solver_cfg
        return build_environment(self.robot, problem, self._finger_ik, cfg, api.DTYPES[cfg.dtype], self.device,
                                 self.reward, around=posture)

    def _land(self, problem: GraspProblem, env: Environment, x: Tensor, seed: int) -> GraspResult:
        """Levenberg-Marquardt from x (1, m) in ``env``: a result of one trial."""

        cfg = self.solver_cfg
        local = replace(cfg, method="dls", max_iterations=cfg.polish.iterations)
        outcome = run_dls(env, 1, seed, local, self.reward, None, start=x)
        return api.result_of(self.robot, problem, env, outcome, 1, seed, cfg, self.srv, self.reward, self.noise)
