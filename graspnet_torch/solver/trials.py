"""A problem's trial results from its environment's float64 report: the collision count by FCL,
the noise-free reinforcement, the contact model's fields (the surface model's pads, pre-grasp and
squeeze: :mod:`graspnet_torch.solver.contact`), ``success`` and, where no trial succeeded, why."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import torch

from graspnet_torch.collision.scene import has_environment
from graspnet_torch.rewards import Reward
from graspnet_torch.robot.robot import Robot
from graspnet_torch.solver.config import RewardCfg, SolverCfg
from graspnet_torch.solver.contact import (
    contact_rule,
    describe_pad,
    grasp_postures,
    posture_fields,
    surface_fields,
    within_cone,
)
from graspnet_torch.solver.environment import Environment, Report
from graspnet_torch.solver.environments import environment_class
from graspnet_torch.solver.loop import LoopOutcome
from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.solver.result import TrialResult
from graspnet_torch.tasks.problem import GraspProblem

__all__ = ["COLLISIONS_NAMED", "failure_reason", "trial_results"]


def trial_results(robot: Robot, problem: GraspProblem, env: Environment, report: Report, outcome: LoopOutcome,
            reward: RewardCfg, solver: SolverCfg) -> tuple[list[TrialResult], str | None]:
    """Per-trial results of one problem from the environment's float64 report of its reported
    configurations: the collision count by FCL (INTERFACE.md) of each reported posture when the
    problem has an object or obstacles, the noise-free reinforcement recomputed from them, and
    ``success``: the grasp (the report's ``landed``: every contact within ``solver.tolerance_mm``,
    and no collision; in the surface model instead every pad, measured, within the tolerance of its
    contact and within the cone, and no collision). Also the one-line reason no trial succeeded, or None."""
    rule = contact_rule(robot, problem, solver)
    exact = has_environment(robot, problem)  # the postures are needed only to check them (FCL) or their pads
    postures = [trial_posture(robot, f) for f in report.fields] if exact or rule.surface else []
    reports = None
    if exact:
        reports = rule.scene(robot, problem).check_many(postures)
    collisions = None if reports is None else torch.tensor([c.count for c in reports])
    evaluation = replace(report.evaluation, collisions=collisions)
    r = Reward(reward, solver.max_iterations, env.reward_base)(evaluation, outcome.iterations.cpu())
    touching, counts, all_fields, errors = list(report.landed), [], [], []
    surface = surface_fields(robot, problem, postures) if rule.surface else None
    for t, f in enumerate(report.fields):
        count = 0 if collisions is None else int(collisions[t])
        fields, error = dict(f), report.error_mm[t]
        if surface is not None:  # the pads, measured: on their contacts, facing into the object (the search's
            # error adds a pad's hinge from 0.97 of the cone on, which a grasp within the cone need not meet)
            fields.update(surface[t])
            touching[t] = within_cone(fields, rule.cone_deg) and \
                max(fields["pad_distance_mm"].values()) <= solver.tolerance_mm
        counts.append(count)
        all_fields.append(fields)
        errors.append(error)
    around = grasp_postures(robot, problem, postures, solver) if rule.surface else None
    if around is not None:  # the surface model's pre-grasp and squeeze of every trial
        for fields, pair in zip(all_fields, around, strict=True):
            fields["pregrasp"], fields["squeeze"] = (posture_fields(robot, p) for p in pair)
    out = [TrialResult(success=count == 0 and ok, iterations=int(outcome.iterations[t]), reinforcement=float(r[t]),
                       wall_time_s=outcome.wall_time_s, collisions=count, error_mm=error, **fields)
           for t, (count, ok, error, fields) in enumerate(zip(counts, touching, errors, all_fields, strict=True))]
    failure = None
    if not any(t.success for t in out):
        failure = failure_reason(robot, problem, out, reports, report.landed, solver.tolerance_mm)
        if rule.surface and any(report.landed) and not any(touching):
            worst = min((t for t, ok in enumerate(report.landed) if ok), key=lambda t: out[t].error_mm)
            failure = f"no pad faces into the object: {describe_pad(out[worst].fields)} (solver.normal_cone_deg=" \
                      f"{solver.normal_cone_deg:g})"
    return out, failure


COLLISIONS_NAMED = 3  # a "colliding" failure names this many of the most frequent colliding pairs


def failure_reason(robot: Robot, problem: GraspProblem, trials: Sequence[TrialResult], reports: Sequence | None,
                   landed: Sequence[bool], tolerance_mm: float) -> str:
    """Why no trial is a grasp, in one line: a contact out of reach of the search space (no palm
    position or arm configuration in it brings that finger there), else every configuration that
    reached the contacts (``landed``) colliding (with what, by FCL), else the budget ended far
    away (the best trial's errors)."""
    env = environment_class(robot)
    far = env.unreachable(robot, problem)
    if far:
        return (f"out of reach: no configuration in the search space brings the {', '.join(far)} fingertip"
                f"{'s' if len(far) > 1 else ''} to {'their contacts' if len(far) > 1 else 'its contact'}")
    landed = [k for k, ok in enumerate(landed) if ok]
    if landed and reports is not None:
        what: dict[str, int] = {}
        names = [f"obstacles[{k}]" for k in range(len(problem.obstacles))] + ["the floor"]
        for k in landed:
            rep = reports[k]
            for link, o in rep.obstacle_pairs:
                key = f"{link} with {names[o] if o < len(names) else f'obstacle {o}'}"
                what[key] = what.get(key, 0) + 1
            for link in rep.object_links:
                what[f"{link} in the object"] = what.get(f"{link} in the object", 0) + 1
            for a, b in rep.self_pairs:
                what[f"{a} with {b}"] = what.get(f"{a} with {b}", 0) + 1
        common = ", ".join(k for k, _ in sorted(what.items(), key=lambda kv: -kv[1])[:COLLISIONS_NAMED])
        return (f"colliding: all {len(landed)} configuration(s) that reached the contacts collide (FCL: {common})")
    best = min(trials, key=lambda t: t.error_mm)
    return (f"far: the budget ended with the best trial {env.describe(best)} after {best.iterations} iteration(s) "
            f"(tolerance {tolerance_mm:g} mm)")
