"""The Python API runs its work on one torch thread by default and puts the caller's count back."""

from __future__ import annotations

import pytest
import torch

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.tasks import random_sequence
from graspnet_torch.threads import default_threads, set_default_threads, torch_threads


@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)
    set_default_threads(1)


def test_one_thread_inside_and_the_callers_count_back_after(two_threads):
    assert default_threads() == 1
    with torch_threads() as n:
        assert n == torch.get_num_threads() == 1
    assert torch.get_num_threads() == 2
    with pytest.raises(RuntimeError), torch_threads(1):
        raise RuntimeError("a failing call")
    assert torch.get_num_threads() == 2  # also after an error
    set_default_threads(None)  # torch's own setting: left alone
    with torch_threads() as n:
        assert n == 2


@pytest.mark.parametrize("bad", [0, -1, 2.5, "2", True, 10**6])
def test_a_bad_thread_count_is_refused(bad):
    with pytest.raises(ConfigError, match="threads="):
        set_default_threads(bad)
    with pytest.raises(ConfigError, match="threads="):
        gt.Solver("hand", threads=bad)
    assert default_threads() == 1


def test_the_api_restores_the_callers_count_and_tracks_on_it_between_frames(two_threads):
    problem = gt.GraspProblem.from_task("glass3")
    one = gt.solve(problem, trials=2, seed=0, max_iterations=30)
    assert torch.get_num_threads() == 2
    assert gt.solve_many([problem, problem], trials=2, seed=0, max_iterations=30)[0].robot == "hand"
    assert torch.get_num_threads() == 2
    solver = gt.Solver("hand", trials=2, max_iterations=30)
    counts = [torch.get_num_threads() for _ in solver.iter_track(random_sequence(solver.robot, 0, 3))]
    assert counts == [2, 2, 2] and torch.get_num_threads() == 2
    same = gt.solve(problem, trials=2, seed=0, max_iterations=30, threads=1)
    assert same.best.palm_pose == one.best.palm_pose  # the default is one thread
