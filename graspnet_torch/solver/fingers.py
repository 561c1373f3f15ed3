"""What every environment whose fingers are placed by the FCNN shares (free palm, arm + hand)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from graspnet_torch.collision.cache import proxy_for
from graspnet_torch.collision.scene import has_environment
from graspnet_torch.errors import ProblemError
from graspnet_torch.robot.transforms import compose, rt_to_pose, transform_points, untransform_points
from graspnet_torch.solver.contact import ContactRule, contact_rule, tip_targets
from graspnet_torch.solver.environment import Done, Environment, Evaluation, Report
from graspnet_torch.solver.pad_term import PadTerm
from graspnet_torch.solver.whole import WholeConfiguration
from graspnet_torch.tasks.problem import GraspProblem

if TYPE_CHECKING:
    from graspnet_torch.fcnn.ik import FingerIK
    from graspnet_torch.robot.robot import Posture, Robot
    from graspnet_torch.solver.config import SolverCfg
    from graspnet_torch.solver.result import TrialResult

__all__ = ["FingerEnvironment"]


class FingerEnvironment(WholeConfiguration, Environment):
    """What every environment whose fingers are placed by the FCNN shares (free palm, arm + hand):
    the contacts expressed in each contact finger's base frame from a palm frame, the finger
    joints by expert competition (+ refinement), the final polish and the float64 report.

    One problem, or a batch of P problems with ``runs`` trials each (trial t on problem
    t // runs, :attr:`problem_index`): then the fingers are the union of the problems' contact
    fingers in robot order, the contacts are per trial (T, F, 3) and a mask (T, F) keeps each
    trial's errors to its own problem's fingers (the others are inert: zero error, zero Jacobian,
    at home in collision counts and results).

    Subclasses set ``n``, ``lower``, ``upper`` ((n,), or (T, n) for a batch) and define
    :meth:`palm_frame` (the palm in the world for a configuration), :meth:`palm_frame_jacobian`
    (with its Jacobian, for the polish) and :meth:`_exact_bounds` (the exact bounds, float64). The
    whole configuration (the polish, ``solver=dls``, warm starts): :mod:`graspnet_torch.solver.whole`.
    """

    n: int
    lower: Tensor
    upper: Tensor
    frame64: tuple[Tensor, Tensor] | None = None  # the search frame in the world (R, t), per trial or one
    joint_box: tuple[Tensor, Tensor] | None = None  # (F, j) contact fingers' joint bounds narrower than the limits
    subsets = False  # every trial evaluated every iteration: fixed-seed results stay bit-for-bit what they were

    def __init__(self, robot, problem, solver: SolverCfg, ik, dtype: torch.dtype = torch.float32,
                 device: torch.device | str = "cpu", collisions: bool = False, runs: int = 1):
        import numpy as np


        problems = [problem] if isinstance(problem, GraspProblem) else list(problem)
        for p in problems:  # ik None: a warm start's environment (Levenberg-Marquardt, no FCNN)
            missing = [f for f in p.fingers if ik is not None and f not in ik.experts]
            if missing:
                raise ProblemError(f"{p.source}: no FCNN experts for finger(s) {', '.join(missing)}")
        self.robot, self.problems, self.problem, self.ik = robot, problems, problems[0], ik
        self.world_problems = problems
        fingers, polish = solver.fingers, solver.polish
        self.refine, self.candidates, self.final_refine = fingers.refine, fingers.candidates, fingers.final_refine
        self.polish_iterations, self.polish_tol = polish.iterations, polish.tolerance_mm / 1000
        self.min_gain = polish.min_gain
        self.polishes = polish.mode == "whole" and polish.iterations > 0
        self.tolerance_mm = solver.tolerance_mm
        kw = {"dtype": dtype, "device": device}
        self.mask = self.problem_index = None
        self.rules = [contact_rule(robot, p, solver) for p in problems]  # each problem's contact model
        if len(problems) == 1:
            self.fingers = self.problem.fingers
            contacts64 = tip_targets(robot, self.problem, self.rules[0].model)  # (F, 3): where the tips go
        else:  # a batch: the union of the contact fingers, per-trial contacts and a mask
            used = {f for p in problems for f in p.fingers}
            self.fingers = tuple(f for f in robot.finger_names if f in used)
            column = {f: k for k, f in enumerate(self.fingers)}
            contacts = np.zeros((len(problems), len(self.fingers), 3))
            mask = np.zeros((len(problems), len(self.fingers)))
            for i, (p, rule) in enumerate(zip(problems, self.rules, strict=True)):
                for f, x in zip(p.fingers, tip_targets(robot, p, rule.model), strict=True):
                    contacts[i, column[f]], mask[i, column[f]] = x, 1.0
            rep = np.repeat(np.arange(len(problems)), runs)
            contacts64 = contacts[rep]  # (T, F, 3)
            self.mask = torch.as_tensor(mask[rep], **kw)  # (T, F)
            self.problem_index = torch.as_tensor(rep, device=device)
            self.subsets = True  # once most trials have stopped, the loop evaluates the others only
        self.contacts64 = torch.as_tensor(contacts64, dtype=torch.float64)  # exact, for the polish and the report
        self.contacts = self.contacts64.to(**kw)
        self.runs = runs
        self.idx = [robot.finger_index(f) for f in self.fingers]
        base = torch.as_tensor(np.stack([robot.fingers[robot.finger_names[i]].base_in_palm for i in self.idx]), **kw)
        self.base_R, self.base_t = base[:, :3, :3], base[:, :3, 3]
        self._base64 = (self.base_R.to(torch.float64).cpu(), self.base_t.to(torch.float64).cpu())
        if ik is not None:
            ik._bank(tuple(self.fingers), dtype, torch.device(device))  # build the finger kernels now, not in the loop
        self.proxy = None
        self.pads = None  # the surface model: the pads' normals join the errors (solver/pad_term.py)
        if any(rule.surface for rule in self.rules):
            self.pads = PadTerm(robot, problems, self.rules, self.fingers, runs, robot.joints_per_finger)

        rule, batch = self.rules[0], problems if len(problems) > 1 else self.problem  # one proxy: the first's rule
        if collisions and has_environment(robot, self.problem):
            self.proxy = proxy_for(robot, batch, dtype=dtype, device=device,
                                   object_tolerance=rule.object_tolerance, touching=rule.touching)
        self.depth_proxy = None  # the surface model: how deep the links reach, a residual of the whole polish
        self.depth_allowance = rule.object_tolerance  # how deep a link may reach (the surface model)
        if self.pads is not None and has_environment(robot, self.problem):
            self.depth_proxy = proxy_for(robot, batch, dtype=torch.float64, object_tolerance=rule.object_tolerance,
                                         touching=rule.touching, fingers_apart=True)
        if self.proxy is not None or self.depth_proxy is not None:
            self.home = robot.home_posture(dtype).fingers.to(device)  # (F_all, j): fingers without a contact
            self._idx = torch.as_tensor(self.idx, device=device)
        self.counts_collisions = self.proxy is not None
        self.on_surface = self.pads is not None

    def _rule_of(self, problem: int) -> ContactRule:
        """The contact rule of problem ``problem`` of the batch (its contact model)."""
        return self.rules[problem]

    def proposal_input(self) -> tuple[Tensor, Tensor]:
        """One slot per robot finger: the contacts in this environment's frame (a free hand's
        search frame, an arm's world), zero where a row has no contact for that finger: (R, F_all,
        3) and the mask (R, F_all), float32."""
        c = self.contacts64.reshape(-1, len(self.idx), 3).float()
        R = c.shape[0]
        on = torch.ones(R, len(self.idx)) if self.mask is None else self.mask.float().cpu()
        targets = torch.zeros(R, self.robot.n_fingers, 3)
        mask = torch.zeros(R, self.robot.n_fingers)
        targets[:, self.idx] = c * on.unsqueeze(-1)
        mask[:, self.idx] = on
        return targets, mask

    def palm_frame(self, config: Tensor) -> tuple[Tensor, Tensor]:
        """(T, n) configurations -> the palm in the world: R (T, 3, 3), t (T, 3)."""
        raise NotImplementedError

    def palm_frame_jacobian(self, config: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """(T, n) configurations -> the palm frame R (T, 3, 3), t (T, 3) and its Jacobian (T, 6, n)
        (rows d t / d config, then the angular velocity w: dR = [w]_x R)."""
        raise NotImplementedError

    def _exact_bounds(self) -> tuple[Tensor, Tensor]:
        """The exact bounds of the configuration, float64 on the CPU: (n,) or (T, n) for a batch."""
        raise NotImplementedError

    def clamp(self, config: Tensor, rows: Tensor | None = None) -> Tensor:
        """(B, n) configurations of trials ``rows`` (None: all, in order) -> float64 on the CPU,
        within the exact bounds."""
        lo, hi = (b if b.dim() == 1 or rows is None else b[rows.cpu()] for b in self._exact_bounds())
        return torch.minimum(torch.maximum(config.detach().to(torch.float64).cpu(), lo), hi)

    def _rows(self, value: Tensor | None, rows: Tensor | None) -> Tensor | None:
        """A per-trial tensor of a batch at the trials ``rows`` (as is for one problem)."""
        if value is None or self.mask is None or rows is None:
            return value
        return value[rows.to(value.device)]

    def targets(self, config: Tensor, palm: tuple[Tensor, Tensor] | None = None, rows: Tensor | None = None
                ) -> Tensor:
        """Contacts in each contact finger's base frame. config: (B, n) -> (B, F, 3); ``palm``: its
        palm frame if already known; ``rows``: the trials of the rows (None: all, in order)."""

        R, t = palm if palm is not None else self.palm_frame(config)
        in_palm = untransform_points(R.unsqueeze(1), t.unsqueeze(1), self._rows(self.contacts, rows))
        return untransform_points(*self.bases(config), in_palm)

    def bases(self, config: Tensor) -> tuple[Tensor, Tensor]:
        """The contact fingers' bases in the palm frame: (F, 3, 3), (F, 3) fixed, or per row (B, F,
        3, 3), (B, F, 3) where the configuration carries the joints the fingers share (its last
        :attr:`shared_slots` columns)."""
        if not self.shared_slots:
            return (self.base_R, self.base_t) if config.dtype == self.base_R.dtype else self._base64
        R, t = self.robot.base_frames(config[:, -self.shared_slots:])
        return R[:, self.idx], t[:, self.idx]

    def _all_bases(self, config: Tensor) -> tuple[Tensor, Tensor] | None:
        """Every finger's base in the palm per configuration (the collision proxy's), where the
        configuration carries the joints the fingers share; else None (the fixed ones)."""
        return self.robot.base_frames(config[:, -self.shared_slots:]) if self.shared_slots else None

    def fcnn(self) -> FingerIK:
        """The FCNN the search's finger steps use; an environment built without one (a warm start's,
        Levenberg-Marquardt only) refuses them: :class:`ProblemError`."""
        if self.ik is None:
            raise ProblemError(f"{self.problem.source}: this environment has no FCNN (built for a warm start): the "
                               f"search needs the robot's trained finger IK")
        return self.ik

    def _shared_of(self, config: Tensor) -> Tensor | None:
        """The shared joints (B, S) of configurations (None: the robot holds them)."""
        return config[:, -self.shared_slots:] if self.shared_slots else None

    def _finger_joints(self, config: Tensor, palm: tuple[Tensor, Tensor] | None = None, rows: Tensor | None = None
                      ) -> tuple[Tensor, Tensor]:
        """Finger joints (B, F, j) within limits and fingertip errors (B, F) in metres (zero for
        a finger a trial's problem does not use)."""
        targets = self.targets(config, palm, rows)
        ik = self.fcnn()
        if self.candidates > 1 and self.refine > 0:
            q, err = ik.solve_fingers(targets, self.fingers, self.refine, self.candidates)
        elif self.refine <= 0:
            q, err = ik.compete(targets, self.fingers)
        else:
            q, _err, tips, J = ik.compete_jacobian(targets, self.fingers)
            q, err = ik.refine(q, targets, self.fingers, self.refine, start=(tips, J))
        mask = self._rows(self.mask, rows)
        return q, err if mask is None else err * mask

    def _every(self, q: Tensor, rows: Tensor | None) -> Tensor:
        """Every finger's joints (B, F_all, j): the contact fingers' ``q`` (B, F, j), the others
        (and in a batch, the fingers a trial's problem does not use) at home."""
        home = self.home.to(q).expand(q.shape[0], -1, -1)
        mask = self._rows(self.mask, rows)
        if mask is not None:
            q = torch.where(mask.to(q.device).unsqueeze(-1) > 0, q, home[:, self.idx])
        return home.index_copy(1, self._idx.to(q.device), q)

    def _pid(self, rows: Tensor | None) -> Tensor | None:
        return self._rows(self.problem_index, rows) if self.problem_index is not None else None

    def evaluate(self, config: Tensor, trials: Tensor | None = None) -> Evaluation:
        """config: (B, n) of the trials ``trials`` (None: all, in order) -> E (B,) of eq. 3,
        per-finger errors (B, F), finger joints (B, F, j) and, with a collision proxy, the
        collision count (B,) of the whole posture (the fingers without a contact at home)."""
        palm, levels = self._palm_and_levels(config)
        q, errors = self._finger_joints(config, palm, trials)
        contact = None
        if self.pads is not None:  # the surface model: a pad facing away counts as a tip off its target
            penalty = self.pads.penalty(self._pad_normals(palm[0], config, q), trials)
            errors, contact = errors + penalty, self.pads.contact_errors(errors, penalty, trials)
        collisions = None
        if self.proxy is not None:
            collisions = self.proxy.count(palm, self._every(q, trials), self.body(config), levels, self._pid(trials),
                                          self._all_bases(config))
        return Evaluation(error=errors.sum(dim=1), finger_errors=errors, joints=q, collisions=collisions,
                          config=config, contact_errors=contact)

    def _pad_normals(self, R: Tensor, config: Tensor, q: Tensor) -> Tensor:
        """The contact fingers' pad normals in the environment's frame (B, F, 3) with the palm
        turned by R (B, 3, 3), the bases of ``config`` (B, n) and the finger joints q (B, F, j)."""
        local, _ = self.pads.local(q)
        base_R = self.bases(config)[0]
        return (R.unsqueeze(1) @ base_R @ local.unsqueeze(-1)).squeeze(-1)

    def _palm_and_levels(self, config: Tensor) -> tuple[tuple[Tensor, Tensor], list[Tensor] | None]:
        """The palm frame of configurations (T, n) and, where the proxy needs them, the body's chain
        frames (None: a free palm)."""
        return self.palm_frame(config), None

    def body(self, config: Tensor) -> Tensor | None:
        """The body joints of configurations (T, n) for the collision proxy (None: a free palm)."""
        return None

    def finish(self, config: Tensor, evaluation: Evaluation, done: Done | None = None) -> tuple[Tensor, Evaluation]:
        """Refine the finger joints of the reported configurations (``solver.fingers.final_refine`` steps,
        the configuration kept); never worse. With ``solver.polish.mode: whole``, instead polish the
        configuration and the fingers together (:meth:`polish`; ``done`` as :meth:`local_solve`'s:
        the rows that may stop, given the converged ones). Returns the configurations and their
        evaluation."""
        iterations, whole = self.final_refine, self.polishes
        if iterations > 0 and not whole:  # the whole polish moves the fingers too
            with torch.inference_mode():
                q, err = self.fcnn().refine(evaluation.joints, self.targets(config), self.fingers, iterations)
            if self.mask is not None:
                err = err * self.mask
            contact = None
            if self.pads is not None:
                penalty = self.pads.penalty(self._pad_normals(self.palm_frame(config)[0], config, q))
                err, contact = err + penalty, self.pads.contact_errors(err, penalty).clone()
            evaluation = Evaluation(error=err.sum(dim=1).clone(), finger_errors=err.clone(), joints=q.clone(),
                                    collisions=evaluation.collisions, contact_errors=contact)
        if whole:
            x = self._whole_start(config, evaluation.joints)
            config, evaluation = self.whole_result(self.local_solve(x, self.polish_iterations, self.polish_tol, done),
                                                   config)
            config, evaluation = self._align(config, evaluation, self.tolerance_mm / 1000)  # the surface model
        return config, evaluation

    @classmethod
    def around(cls, robot: Robot, problem: GraspProblem, posture: Posture, solver: SolverCfg, ik: FingerIK | None,
               dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu", collisions: bool = False
               ) -> FingerEnvironment:
        """The usual environment, with the contact fingers' joints kept within
        ``solver.polish.warm_step_deg`` of the posture's (:meth:`near`)."""
        return cls(robot, problem, solver, ik, dtype, device, collisions).near(posture, solver.polish.warm_step_deg)

    def report(self, config: Tensor, evaluation: Evaluation, rows: Tensor | None = None) -> Report:
        """Per trial (of ``rows``, None: all), the result fields of the reported configuration,
        recomputed in float64: the palm pose, every finger's joints (the non-contact fingers at
        home), the fingertip errors of its problem's contact fingers by forward kinematics against
        the contacts, and ``error``
        (E, metres). The loop runs in float32, whose rounded limits can exceed the exact ones by
        ~1e-7: configurations and joints are clamped to the exact bounds and limits first."""
        import math


        robot = self.robot
        exact = self.clamp(config, rows)
        T = exact.shape[0]
        flo, fhi = (torch.as_tensor(a) for a in robot.finger_limits)
        home = robot.home_posture(torch.float64).fingers.expand(T, -1, -1)
        q = home.clone()
        chosen = torch.clamp(evaluation.joints.detach().to(torch.float64).cpu(), flo[self.idx], fhi[self.idx])
        if self.mask is not None:  # a finger a trial's problem does not use stays at home
            chosen = torch.where(self._rows(self.mask, rows).cpu().unsqueeze(-1) > 0, chosen, home[:, self.idx])
        q[:, self.idx] = chosen
        R, t = self.palm_frame(exact)
        contacts = self._rows(self.contacts64, rows)
        if self.frame64 is not None:  # the search frame G -> the world: the palm G o pose, the contacts G c

            G_R, G_t = (self._rows(g, rows) if g.shape[0] > 1 else g for g in self.frame64)
            R, t = compose(G_R, G_t, R, t)
            contacts = transform_points(G_R.unsqueeze(-3), G_t.unsqueeze(-2), contacts)
        shared = self._shared_of(exact)
        tips = transform_points(R.unsqueeze(-3), t.unsqueeze(-2), robot.fingertips_palm(q, shared))[:, self.idx]
        err = torch.linalg.vector_norm(tips - contacts, dim=-1)  # (T, F), metres
        palm = rt_to_pose(R, t).tolist()
        deg = 180.0 / math.pi
        column = {f: k for k, f in enumerate(self.fingers)}
        columns = [[(f, column[f]) for f in p.fingers] for p in self.problems]  # each problem's, once
        err_rows = err.tolist()
        joints = robot.finger_joints_to_file_many(q, shared)  # every joint, mimic and shared joints included
        pid = None if self.problem_index is None else self._rows(self.problem_index, rows).tolist()
        out, total = [], []
        for k in range(T):
            pose = palm[k]
            errors = {f: err_rows[k][c] for f, c in columns[0 if pid is None else pid[k]]}
            total.append(sum(errors.values()))
            out.append({
                "palm_pose": pose[:3] + [a * deg for a in pose[3:]],
                "joints": joints[k],
                "fingertip_error_mm": {f: e * 1000 for f, e in errors.items()},
                "total_error_mm": total[-1] * 1000,
            })
        self._add_fields(out, exact)
        return Report(fields=out, evaluation=Evaluation(error=torch.tensor(total, dtype=torch.float64)),
                      error_mm=[f["total_error_mm"] for f in out],
                      landed=[max(f["fingertip_error_mm"].values()) <= self.tolerance_mm for f in out])

    def _add_fields(self, fields: list[dict], config: Tensor) -> None:
        """Add what a subclass reports beyond the fingers to each trial's ``fields`` (an arm's joints);
        ``config``: (T, n) the reported configurations, float64 within the exact bounds."""

    @staticmethod
    def describe(trial: TrialResult) -> str:
        worst = max(trial.fingertip_error_mm, key=trial.fingertip_error_mm.get)
        return f"{trial.total_error_mm:.3g} mm from its contacts ({worst} {trial.fingertip_error_mm[worst]:.3g} mm)"

    @staticmethod
    def summary(trial: TrialResult, fingers: Sequence[str]) -> str:
        per_finger = ", ".join(f"{f} {trial.fingertip_error_mm[f]:.3f}" for f in fingers)
        return f"total error {trial.total_error_mm:.3f} mm ({per_finger})"

    @staticmethod
    def columns(trial: TrialResult, fingers: Sequence[str]) -> dict[str, float]:
        return {"total mm": trial.total_error_mm, **{f"{f} mm": trial.fingertip_error_mm[f] for f in fingers}}
