"""What the closed loop drives: an environment turns configurations into an evaluation.

The loop (``solver/loop.py``) never knows which robot it drives. A robot-and-problem pair becomes
an environment with

- ``n``, ``lower``, ``upper``: the size of the configuration the network chooses and its bounds
  (a free palm: 6 pose values; an arm: its joints);
- ``evaluate(config (T, n)) -> Evaluation``: the error the reinforcement is built from (E of
  eq. 3) and optional parts (per-finger errors, the finger joints the FCNN chose, collision
  counts);
- ``finish(config, evaluation, iterations) -> (config, Evaluation)``: a last refinement of what
  is reported (the fingers' joints; a gripper's whole configuration);
- ``report(...)``: the result fields of each trial, recomputed in float64.

Rewards (R1-R4, eq. 20-23) are functions of the evaluation, the iteration and the budget
(:class:`graspnet_torch.rewards.Reward`). :func:`build_environment` picks the environment of a
robot and a problem; a new kind of robot is a new environment, never an edit of the loop.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import TYPE_CHECKING, Protocol

import torch
from torch import Tensor

if TYPE_CHECKING:
    from graspnet_torch.solver.least_squares import LMResult

__all__ = ["Environment", "Evaluation", "FingerEnvironment"]


@dataclass
class Evaluation:
    """An environment's verdict on T configurations (leading dimension T everywhere).

    Attributes:
        error: (T,) metres: E of eq. 3, the sum of the fingertip errors.
        finger_errors: (T, F) per contact finger, or None.
        joints: (T, F, j) finger joints chosen for each contact finger, or None.
        collisions: (T,) collision count, or None when the environment has no collision component.
        alignment: (T,) a gripper's |n_gripper . n_object| (eq. 24), or None; then ``error`` is d
            (eq. 26) and the reinforcement's base is (R1 + R2) / 2 (eq. 29).
        config: (T, n) the configuration that was evaluated when the environment refined the
            proposal (a gripper's ``solver.refine`` steps), or None (the proposal itself).
    """

    error: Tensor
    finger_errors: Tensor | None = None
    joints: Tensor | None = None
    collisions: Tensor | None = None
    alignment: Tensor | None = None
    config: Tensor | None = None

    def tensors(self) -> dict[str, Tensor]:
        """The parts that are present, by name."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    def where(self, mask: Tensor, other: Evaluation) -> Evaluation:
        """Per trial: this evaluation where ``mask`` (T,) is true, else ``other``."""
        out = {}
        for name, mine in self.tensors().items():
            theirs = getattr(other, name)
            out[name] = torch.where(mask.view(-1, *([1] * (mine.dim() - 1))), mine, theirs)
        return replace(self, **out)

    def put(self, trials: Tensor, part: Evaluation, config: Tensor) -> Evaluation:
        """This evaluation with rows ``trials`` (B,) replaced by ``part`` (an evaluation of B
        trials); ``config`` (T, n): the proposals, the evaluated configuration of the rows a
        part without ``config`` leaves unrefined."""
        out = {}
        for name, theirs in part.tensors().items():
            mine = getattr(self, name)
            base = (config if name == "config" else None) if mine is None else mine
            out[name] = base.index_copy(0, trials, theirs)
        if part.config is None:
            out["config"] = None
        return replace(self, **out)

    def clone(self) -> Evaluation:
        return replace(self, **{k: v.clone() for k, v in self.tensors().items()})


class Environment(Protocol):
    """What the loop needs from a robot-specific environment."""

    n: int
    lower: Tensor  # (n,) or (T, n)
    upper: Tensor  # (n,) or (T, n)
    subsets: bool  # evaluate(config[idx], idx) allowed: once most trials stopped, the loop evaluates the rest only

    def evaluate(self, config: Tensor, trials: Tensor | None = None) -> Evaluation:
        """(T, n) configurations -> their evaluation; ``trials`` (B,): the trials that rows of a
        (B, n) ``config`` belong to when only some are evaluated (None: all, in order)."""
        ...


class FingerEnvironment:
    """What every environment whose fingers are placed by the FCNN shares (free palm, arm + hand):
    the contacts expressed in each contact finger's base frame from a palm frame, the finger
    joints by expert competition (+ refinement), the final polish and the float64 report.

    Subclasses set ``n``, ``lower``, ``upper`` and define :meth:`palm_frame` (the palm in the world
    for a configuration) and :meth:`clamp` (a configuration within its exact bounds, float64).
    """

    n: int
    lower: Tensor
    upper: Tensor
    subsets = False  # every trial evaluated every iteration: fixed-seed results stay bit-for-bit what they were

    def __init__(self, robot, problem, ik, refine: int, candidates: int, dtype: torch.dtype,
                 device: torch.device | str, collisions: bool = False):
        import numpy as np

        from graspnet_torch.errors import ProblemError

        missing = [f for f in problem.fingers if f not in ik.experts]
        if missing:
            raise ProblemError(f"{problem.source}: no FCNN experts for finger(s) {', '.join(missing)}")
        self.robot, self.problem, self.ik = robot, problem, ik
        self.refine, self.candidates = refine, candidates
        self.fingers = problem.fingers
        self.idx = [robot.finger_index(f) for f in self.fingers]
        self.contacts = torch.as_tensor(problem.contacts_world(), dtype=dtype, device=device)  # (F, 3)
        base = torch.as_tensor(np.stack([robot.fingers[robot.finger_names[i]].base_in_palm for i in self.idx]),
                               dtype=dtype, device=device)
        self.base_R, self.base_t = base[:, :3, :3], base[:, :3, 3]
        ik._bank(tuple(self.fingers), dtype, torch.device(device))  # build the finger kernels now, not in the loop
        self.proxy = None
        from graspnet_torch.collision.scene import has_environment

        if collisions and has_environment(robot, problem):
            from graspnet_torch.collision.proxy import CollisionProxy

            self.proxy = CollisionProxy(robot, problem, dtype=dtype, device=device)
            self.home = robot.home_posture(dtype).fingers.to(device)  # (F_all, j): fingers without a contact
            self._idx = torch.as_tensor(self.idx, device=device)

    def palm_frame(self, config: Tensor) -> tuple[Tensor, Tensor]:
        """(T, n) configurations -> the palm in the world: R (T, 3, 3), t (T, 3)."""
        raise NotImplementedError

    def clamp(self, config: Tensor) -> Tensor:
        """(T, n) configurations -> float64 on the CPU, within the exact bounds."""
        raise NotImplementedError

    def targets(self, config: Tensor, palm: tuple[Tensor, Tensor] | None = None) -> Tensor:
        """Contacts in each contact finger's base frame. config: (T, n) -> (T, F, 3); ``palm``: its
        palm frame if already known."""
        from graspnet_torch.robot.transforms import untransform_points

        R, t = palm if palm is not None else self.palm_frame(config)
        in_palm = untransform_points(R.unsqueeze(1), t.unsqueeze(1), self.contacts)
        return untransform_points(self.base_R, self.base_t, in_palm)

    def finger_joints(self, config: Tensor, palm: tuple[Tensor, Tensor] | None = None) -> tuple[Tensor, Tensor]:
        """Finger joints (T, F, j) within limits and fingertip errors (T, F) in metres."""
        targets = self.targets(config, palm)
        if self.candidates > 1 and self.refine > 0:
            return self.ik.solve_fingers(targets, self.fingers, self.refine, self.candidates)
        if self.refine <= 0:
            return self.ik.compete(targets, self.fingers)
        q, _err, tips, J = self.ik.compete_jacobian(targets, self.fingers)
        return self.ik.refine(q, targets, self.fingers, self.refine, start=(tips, J))

    def evaluate(self, config: Tensor, trials: Tensor | None = None) -> Evaluation:
        """config: (T, n) -> E (T,) of eq. 3, per-finger errors (T, F), finger joints (T, F, j) and,
        with a collision proxy, the collision count (T,) of the whole posture (the fingers without
        a contact at home). Every trial has the same problem, so ``trials`` changes nothing."""
        levels = None
        if self.proxy is not None and self.robot.has_body:  # the proxy's arm chain gives the palm too
            levels, palm = self.proxy.body_levels_and_palm(config)
        else:
            palm = self.palm_frame(config)
        q, errors = self.finger_joints(config, palm)
        collisions = None
        if self.proxy is not None:
            every = self.home.expand(q.shape[0], -1, -1).index_copy(1, self._idx, q)
            collisions = self.proxy.count(palm, every, config if self.robot.has_body else None, levels)
        return Evaluation(error=errors.sum(dim=1), finger_errors=errors, joints=q, collisions=collisions)

    polish = "fingers"  # 'whole': also polish the configuration with the fingers (SolverCfg.polish)
    polish_iterations = 0
    polish_tol = 0.0  # metres: a polished trial stops below this error
    whole_polish = True  # the environment has a whole polish (SolverCfg.polish applies)

    def finish(self, config: Tensor, evaluation: Evaluation, iterations: int,
               done: Callable[[Tensor], Tensor] | None = None) -> tuple[Tensor, Evaluation]:
        """Refine the finger joints of the reported configurations (the configuration kept); never
        worse. With ``polish = 'whole'``, instead polish the configuration and the fingers together
        (:meth:`polish_whole`; ``done`` as :meth:`local_solve`'s: the rows that may stop, given
        the converged ones). Returns the configurations and their evaluation."""
        whole = self.polish == "whole" and self.polish_iterations > 0
        if iterations > 0 and not whole:  # the whole polish moves the fingers too
            with torch.inference_mode():
                q, err = self.ik.refine(evaluation.joints, self.targets(config), self.fingers, iterations)
            evaluation = Evaluation(error=err.sum(dim=1).clone(), finger_errors=err.clone(), joints=q.clone(),
                                    collisions=evaluation.collisions)
        if whole:
            config, evaluation = self.polish_whole(config, evaluation, self.polish_iterations, self.polish_tol, done)
        return config, evaluation

    # The whole configuration x = [configuration (n), the contact fingers' joints (F * j)], float64 on
    # the CPU: what the whole polish and solver=dls move together (padding slots have limits [0, 0]).

    def whole_bounds(self) -> tuple[Tensor, Tensor]:
        """(m,) lower and upper bounds of x: the configuration's bounds, then the joint limits."""
        flo, fhi = (torch.as_tensor(a)[self.idx].reshape(-1) for a in self.robot.finger_limits)
        return (torch.cat([self.lower.to(torch.float64).cpu(), flo]),
                torch.cat([self.upper.to(torch.float64).cpu(), fhi]))

    def whole_start(self, config: Tensor, joints: Tensor) -> Tensor:
        """x (T, m) of configurations (T, n) and contact-finger joints (T, F, j), within bounds."""
        lo, hi = self.whole_bounds()
        T = config.shape[0]
        return torch.clamp(torch.cat([self.clamp(config), joints.detach().to(torch.float64).cpu().reshape(T, -1)], 1),
                           lo, hi)

    def random_whole(self, trials: int, gen: torch.Generator) -> Tensor:
        """x (T, m) uniform within the bounds and joint limits (``solver=dls``'s restarts)."""
        lo, hi = self.whole_bounds()
        u = torch.rand(trials, lo.numel(), generator=gen, dtype=torch.float64, device=gen.device).cpu()
        return lo + (hi - lo) * u

    def _tips64(self, x: Tensor, rows: Tensor | None = None) -> Tensor:
        """Contact fingertips in the world, flattened, of rows of x. x: (B, m) float64 -> (B, 3F)."""
        from graspnet_torch.robot.transforms import transform_points

        F, j = len(self.idx), self.robot.joints_per_finger
        R, t = self.palm_frame(x[:, : self.n])
        kernel = self.ik._bank(tuple(self.fingers), torch.float64, torch.device("cpu")).kernel
        local = kernel.position(x[:, self.n:].reshape(-1, F, j))
        in_palm = transform_points(self.base_R.to(torch.float64).cpu(), self.base_t.to(torch.float64).cpu(), local)
        return transform_points(R.unsqueeze(1), t.unsqueeze(1), in_palm).reshape(x.shape[0], -1)

    def _count64(self, x: Tensor, rows: Tensor | None = None) -> Tensor:
        """The proxy's collision count (B,) of rows of x."""
        F, j = len(self.idx), self.robot.joints_per_finger
        config = x[:, : self.n].to(self.lower)
        q = x[:, self.n:].reshape(-1, F, j).to(self.lower)
        every = self.home.expand(q.shape[0], -1, -1).index_copy(1, self._idx, q)
        return self.proxy.count(self.palm_frame(config), every, config if self.robot.has_body else None).cpu()

    def local_solve(self, x: Tensor, iterations: int, tol: float = 0.0,
                    done: Callable[[Tensor], Tensor] | None = None, trace: list[Tensor] | None = None
                    ) -> LMResult:
        """Levenberg-Marquardt (:func:`~graspnet_torch.solver.least_squares.levenberg_marquardt`)
        on x (T, m): the contact fingertips onto their contacts, within bounds and limits, never
        into a collision the proxy sees (when there is one)."""
        from graspnet_torch.solver.least_squares import levenberg_marquardt

        lo, hi = self.whole_bounds()
        goal = self.contacts.to(torch.float64).cpu().reshape(-1)
        return levenberg_marquardt(self._tips64, goal, x, lo, hi, iterations, tol=tol, done=done, trace=trace,
                                   count=self._count64 if self.proxy is not None else None)

    def whole_result(self, solved: LMResult, like: Tensor, collisions: Tensor | None = None
                     ) -> tuple[Tensor, Evaluation]:
        """The configurations (T, n) and evaluation of solved x, in the dtype and device of ``like``."""
        T, F, j = solved.x.shape[0], len(self.idx), self.robot.joints_per_finger
        goal = self.contacts.to(torch.float64).cpu().reshape(1, -1)
        finger_err = (goal - solved.value).reshape(T, F, 3).norm(dim=-1)
        kw = {"dtype": like.dtype, "device": like.device}
        count = solved.count if solved.count is not None else collisions
        return solved.x[:, : self.n].to(**kw), Evaluation(
            error=finger_err.sum(1).to(**kw), finger_errors=finger_err.to(**kw),
            joints=solved.x[:, self.n:].reshape(T, F, j).to(**kw),
            collisions=None if count is None else count.to(like.device))

    def polish_whole(self, config: Tensor, evaluation: Evaluation, iterations: int, tol: float = 0.0,
                     done: Callable[[Tensor], Tensor] | None = None) -> tuple[Tensor, Evaluation]:
        """Levenberg-Marquardt on the whole configuration (palm pose or arm joints) together with
        the contact fingers' free joints (:meth:`local_solve`), from the reported ones: never
        worse. The loop finds the basin; the fingers alone, with the palm fixed, end where the
        palm left them (a few mm), the whole polish lands in it. Rows stop at |e| < ``tol`` or
        when ``done`` says so."""
        solved = self.local_solve(self.whole_start(config, evaluation.joints), iterations, tol, done)
        return self.whole_result(solved, config, evaluation.collisions)

    def report(self, config: Tensor, evaluation: Evaluation) -> list[dict]:
        """Per trial, the result fields of the reported configuration, recomputed in float64: the
        palm pose, every finger's joints (the non-contact fingers at home), the fingertip errors by
        forward kinematics against the contacts, and ``error`` (E, metres). The loop runs in
        float32, whose rounded limits can exceed the exact ones by ~1e-7: configurations and joints
        are clamped to the exact bounds and limits first."""
        import math

        from graspnet_torch.robot.transforms import rt_to_pose, transform_points

        robot, problem = self.robot, self.problem
        exact = self.clamp(config)
        T = exact.shape[0]
        flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
        q = robot.home_posture(torch.float64).fingers.expand(T, -1, -1).clone()
        q[:, self.idx] = torch.clamp(evaluation.joints.detach().to(torch.float64).cpu(), flo[self.idx],
                                     fhi[self.idx])
        R, t = self.palm_frame(exact)
        tips = transform_points(R.unsqueeze(-3), t.unsqueeze(-2), robot.fingertips_palm(q))[:, self.idx]
        contacts = torch.as_tensor(problem.contacts_world(), dtype=torch.float64)
        err = torch.linalg.vector_norm(tips - contacts, dim=-1)  # (T, F), metres
        palm = rt_to_pose(R, t)
        deg = 180.0 / math.pi
        out = []
        for k in range(T):
            pose = palm[k].tolist()
            out.append({
                "palm_pose": pose[:3] + [a * deg for a in pose[3:]],
                "joints": robot.finger_joints_to_file(q[k]),  # every joint, mimic joints at their coupled values
                "fingertip_error_mm": {f: float(err[k, j]) * 1000 for j, f in enumerate(problem.fingers)},
                "error": float(err[k].sum()),
            })
        return out
