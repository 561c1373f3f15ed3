"""solver.polish.from_r_free: with nothing to collide with, the first iteration's polish of every
proposal of random learners (``solver.start: random``) lands most problems at once; near an object,
in the point model, the setting changes nothing (the surface model polishes from the first iteration
wherever it is)."""

from __future__ import annotations

import dataclasses
import statistics

import pytest

import graspnet_torch as gt


def _with(solver: gt.Solver, contact_model: str = "auto", **polish) -> gt.Solver:
    cfg = solver.solver_cfg
    return gt.Solver(solver.robot, trials=8, solver=dataclasses.replace(
        cfg, start="random", contact_model=contact_model, polish=dataclasses.replace(cfg.polish, **polish)))


@pytest.fixture(scope="module")
def hand_solver():
    return gt.Solver("hand", trials=8)


def test_the_first_polish_lands_free_problems_in_fewer_iterations_than_its_ablation(hand_solver):
    problems = [gt.random_reachable_problem(hand_solver.robot, 500 + k, (4, 5)) for k in range(12)]
    first = [_with(hand_solver).solve(p) for p in problems]
    ablated = [_with(hand_solver, from_r_free=None).solve(p) for p in problems]
    assert all(r.success for r in first) and all(r.success for r in ablated)
    loop_first = statistics.median(max(t.iterations for t in r.trials) for r in first)
    loop_ablated = statistics.median(max(t.iterations for t in r.trials) for r in ablated)
    assert loop_first <= 2 < loop_ablated  # most problems land at the first iteration


def test_near_an_object_the_first_polish_setting_changes_nothing(hand_solver):
    """glass3 with R3 counts collisions: in the point model from_r applies, from_r_free is not used."""
    a = _with(hand_solver, "point").solve("glass3", seed=1)
    b = _with(hand_solver, "point", from_r_free=None).solve("glass3", seed=1)
    assert [t.to_dict() | {"wall_time_s": 0} for t in a.trials] == [t.to_dict() | {"wall_time_s": 0} for t in b.trials]
