"""A hand with no trained FCNN yet (a user's own config, before ``train_fcnn.py``): what does not
need the FCNN works (building a ``gt.Solver``, warm starts, grasps from an object from their
sampled postures), and the search refuses in one line with the command that trains one."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

import graspnet_torch as gt
from graspnet_torch.paths import configs_dir, repo_root
from graspnet_torch.solver import NoiseCfg
from graspnet_torch.solver.postures import trial_posture


@pytest.fixture(scope="module")
def own_hand(tmp_path_factory) -> Path:
    """The shipped hand's config under another name, in a folder with no checkpoint beside it."""
    folder = tmp_path_factory.mktemp("own_hand")
    data = yaml.safe_load((configs_dir() / "robot" / "hand.yaml").read_text())
    data.update(name="own_hand", urdf=str(repo_root() / "urdf" / "hand" / "hand.urdf"))
    path = folder / "own_hand.yaml"
    path.write_text(yaml.safe_dump(data))
    assert not (folder / "own_hand.fcnn.pt").exists()
    return path


def test_the_search_refuses_with_the_command_that_trains_one(own_hand):
    solver = gt.Solver(own_hand, trials=4)  # built: the FCNN is read when a search first needs it
    problem = gt.random_reachable_problem(solver.robot, 3)
    with pytest.raises(gt.CheckpointError, match=r"own_hand\.fcnn\.pt: FCNN checkpoint not found; train one with "
                                                 r"`python scripts/train_fcnn\.py robot=.*own_hand\.yaml`") as err:
        solver.solve(problem)
    assert "\n" not in str(err.value)


def test_a_warm_start_lands_without_the_fcnn(own_hand):
    """A solvable problem (a posture's own fingertips) warm-started near that posture lands, its
    fingertips on the contacts, though no FCNN exists for the robot."""
    solver = gt.Solver(own_hand, trials=4)
    problem = gt.random_reachable_problem(solver.robot, 5)
    shipped = gt.solve(gt.GraspProblem.from_mapping({**problem.to_mapping(), "robot": "hand"}), trials=8, seed=0)
    assert shipped.success
    result = solver.solve(problem, start=trial_posture(gt.load_robot("hand"), shipped.best), search=False)
    assert result.success and result.best.total_error_mm < 1.0


def test_grasps_from_an_object_need_no_fcnn_with_sampled_starts(own_hand):
    cube = gt.Shape("box", [0.06, 0.06, 0.06], [0.0, 0.0, 0.2, 0.0, 0.0, 0.0])
    grasps = gt.synthesize_grasps(own_hand, cube, n_grasps=2, candidates=16, seed=0)
    assert len(grasps) == 2 and all(g.success for g in grasps)
    assert all(g.result.robot == "own_hand" for g in grasps)
    with pytest.raises(gt.CheckpointError, match=r"own_hand\.fcnn\.pt: FCNN checkpoint not found"):
        gt.synthesize_grasps(own_hand, cube, n_grasps=1, candidates=4, seed=0, start="random")


def test_an_environment_built_without_an_fcnn_refuses_the_search():
    """A warm start's environment (no FCNN) solves by Levenberg-Marquardt only; the search's finger
    steps refuse it in one line instead of failing deep inside."""
    from graspnet_torch.solver.api import build_environment, search, settings_of

    robot = gt.load_robot("hand")
    problem = gt.random_reachable_problem(robot, 4)
    solver, srv, reward = settings_of(robot, None, None, None, 5)
    env = build_environment(robot, problem, None, solver)
    with pytest.raises(gt.ProblemError, match="this environment has no FCNN") as err:
        search(env, 2, 0, solver, srv, reward, NoiseCfg())
    assert "\n" not in str(err.value)
