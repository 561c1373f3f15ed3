"""The validation layer: typed settings with ranges, strict types, bounded messages."""

from __future__ import annotations

import dataclasses

import pytest

import graspnet_torch as gt
from graspnet_torch.fcnn.train import FCNNTrainCfg
from graspnet_torch.jobs.configs import SolveGraspJobCfg, TrainFCNNJobCfg, TrainPostureJobCfg, estimate_solve_memory
from graspnet_torch.proposal import ProposalCfg
from graspnet_torch.settings import Free, build, lookup, setting, short, unset
from graspnet_torch.solver import NoiseCfg
from graspnet_torch.srv import SRVNetCfg


def test_defaults_build_and_equal_the_dataclass_defaults():
    for cls in (gt.SolverCfg, SRVNetCfg, gt.RewardCfg, NoiseCfg, FCNNTrainCfg, SolveGraspJobCfg, TrainFCNNJobCfg,
                ProposalCfg, TrainPostureJobCfg):
        assert build(cls, {}) == cls() == build(cls, None)


@pytest.mark.parametrize(("path", "cls"), [("solver/srv.yaml", gt.SolverCfg), ("posture/default.yaml", ProposalCfg)])
def test_the_shipped_group_yaml_lists_the_dataclass_defaults(path, cls):
    """configs/<group>/<name>.yaml, which the command line composes, says what the Python API's
    defaults are: the same values."""
    import yaml

    from graspnet_torch.paths import configs_dir

    data = yaml.safe_load((configs_dir() / path).read_text())
    data.pop("defaults", None)
    assert build(cls, unset(cls, data)) == cls()  # a null: the robot's solver_defaults, else the dataclass's


def test_every_field_of_every_job_has_a_type_the_checker_knows():
    """Walk the job schemas: each leaf's default passes its own check (a schema bug would raise)."""
    def walk(cls, prefix=""):
        for f in dataclasses.fields(cls):
            found = lookup(cls, f.name)
            assert found is not None
            tp = found[0]
            if dataclasses.is_dataclass(tp):
                walk(tp, f"{prefix}{f.name}.")
            elif tp is not Free:
                default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
                build(cls, {f.name: list(default) if isinstance(default, tuple) else default})

    for cls in (SolveGraspJobCfg, TrainFCNNJobCfg, TrainPostureJobCfg):
        walk(cls)


def test_strict_types_and_ranges():
    assert build(gt.SolverCfg, {"threshold": 1, "time_budget": 5}).threshold == 1.0  # an int is a number
    assert build(SRVNetCfg, {"hidden": [8, 9]}).hidden == (8, 9)
    bad = [({"max_iterations": True}, "expected an integer"), ({"max_iterations": 2.0}, "expected an integer"),
           ({"max_iterations": 0}, "in [1, 10000000]"), ({"threshold": "0.9"}, "expected a number"),
           ({"threshold": float("nan")}, "expected a number"), ({"dtype": "float7"}, "one of float32, float64"),
           ({"history": "yes"}, "true or false"), ({"nope": 1}, "unknown setting 'solver.nope'")]
    for data, message in bad:
        with pytest.raises(gt.ConfigError, match=message.replace("[", r"\[").replace("(", r"\(")):
            build(gt.SolverCfg, data, "solver")


def test_nested_keys_and_lookup():
    with pytest.raises(gt.ConfigError, match=r"srv.sigma.kind='cubic': expected one of linear, quadratic"):
        build(SRVNetCfg, {"sigma": {"kind": "cubic"}}, "srv")
    assert lookup(SolveGraspJobCfg, "srv.sigma.scale")[1]["lo_open"] is True
    assert lookup(SolveGraspJobCfg, "task.contacts")[0] is Free
    assert lookup(SolveGraspJobCfg, "solver.nope") is None


def test_open_lower_bound():
    @dataclasses.dataclass
    class C:
        x: float = setting(1.0, lo=0.0, lo_open=True)

    assert build(C, {"x": 1e-9}).x == 1e-9
    with pytest.raises(gt.ConfigError, match=r"x=0: expected a number > 0"):
        build(C, {"x": 0})


def test_messages_quote_a_short_prefix_of_huge_values():
    huge = [[list(range(1000))] * 1000] * 10
    assert len(short(huge)) <= 60
    with pytest.raises(gt.ConfigError) as info:
        build(gt.SolverCfg, {"threshold": huge}, "solver")
    assert len(str(info.value)) < 200


def test_memory_estimate_grows_with_trials_iterations_and_history():
    base = estimate_solve_memory(1000, 100, 5)
    assert estimate_solve_memory(2000, 100, 5) > base > estimate_solve_memory(1000, 100, 5, history=False)
    assert estimate_solve_memory(1000, 200, 5) > base
    # 200 M trials x 2000 iterations is far beyond any machine
    assert estimate_solve_memory(200_000_000, 2000, 3) > 1 << 40
