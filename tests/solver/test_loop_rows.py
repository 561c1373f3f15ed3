"""The SRV loop's compaction onto the rows still running: a part of the tracker and the curves'
assembly give what one tracker of every trial and every trial's rows would have."""

from __future__ import annotations

import torch

import graspnet_torch as gt
from graspnet_torch.rewards import Reward
from graspnet_torch.solver.config import RewardCfg
from graspnet_torch.solver.environment import Evaluation
from graspnet_torch.solver.tracker import Curves, Tracker


def _tracker(trials: int = 8, stop: int | None = 2) -> Tracker:
    pid = torch.arange(trials) // 4  # two problems of four trials
    t = Tracker(trials, Reward(RewardCfg(), 100), 100, pid, stop)
    config = torch.arange(trials * 2, dtype=torch.float32).view(trials, 2)
    ev = Evaluation(error=torch.rand(trials), finger_errors=torch.rand(trials, 3), config=config)
    t.offer(config, ev, torch.rand(trials), torch.rand(trials))
    return t


def test_part_counts_the_successes_outside_it_and_absorbs_back():
    t = _tracker()
    assert t.finish(torch.tensor([True] + [False] * 7), 3)  # one success of problem 0 (stop: 2)
    rows = torch.tensor([1, 2, 5, 6])
    part = t.part(rows)
    assert part.n_active == 4 and part.problem_index.tolist() == [0, 0, 1, 1]
    assert part.finish(torch.tensor([True, False, False, False]), 7)  # problem 0's second: it ends
    assert part.active.tolist() == [False, False, True, True]
    assert part.iterations.tolist() == [7, 7, 100, 100]
    new_config = part.config + 100
    part.config = new_config
    t.absorb(part, rows)
    assert t.active.tolist() == [False, False, False, True, True, True, True, True]
    assert t.iterations.tolist() == [3, 7, 7, 100, 100, 100, 100, 100]
    assert t.succeeded.tolist() == [True, True] + [False] * 6
    assert torch.equal(t.config[rows], new_config) and t.n_active == 5
    assert torch.equal(t.evaluation.finger_errors[rows], part.evaluation.finger_errors)


def test_absorb_drops_an_evaluation_part_the_rows_lost():
    t = _tracker(stop=None)
    rows = torch.tensor([0, 3])
    part = t.part(rows)
    part.evaluation = Evaluation(error=part.evaluation.error, config=part.config)  # a polish without errors
    t.absorb(part, rows)
    assert t.evaluation.finger_errors is None and t.evaluation.config is not None


def test_curves_assemble_as_every_rows_held_at_its_stop():
    T, K = 6, 7
    iterations = torch.tensor([2, 7, 3, 7, 1, 5])
    full = torch.rand(K, T, 3)
    curves = Curves()
    rows = torch.tensor([1, 3, 5])  # from iteration 3 on, the rows of the trials still running
    for k in range(K):
        curves.add(None if k < 3 else rows, float(k), {"errors": full[k] if k < 3 else full[k, rows],
                                                       "expected": full[k] if k < 3 else full[k, rows]})
    out = curves.tensors(iterations)
    stop = iterations - 1
    want = torch.where((torch.arange(K).view(-1, 1) > stop).unsqueeze(-1), full[stop, torch.arange(T)], full)
    assert torch.equal(out["errors"], want)
    assert torch.equal(out["expected"], want.mean(-1))
    assert out["time"].tolist() == [float(k) for k in range(K)]


def test_solve_many_with_a_straggler_holds_every_curve_at_its_stop():
    hand = gt.load_robot("hand")
    problems = [gt.random_reachable_problem(hand, 20_000 + k, (3, 5)) for k in range(30)]
    results = gt.solve_many(problems, trials=4, seed=12, solver={"start": "random", "max_iterations": 150})
    its = torch.cat([r.outcome.iterations for r in results])
    assert int((its == 1).sum()) > 90 and int(its.max()) > 100  # most stop at once; a few run on
    for r in results:
        h, n = r.outcome.history, r.outcome.iterations
        K = h["total"].shape[0]
        for t in range(n.shape[0]):
            s = int(n[t]) - 1
            assert torch.all(h["total"][s:, t] == h["total"][s, t])
        assert torch.equal(h["errors"][-1], h["errors"][torch.clamp(n - 1, max=K - 1), torch.arange(n.shape[0])])
