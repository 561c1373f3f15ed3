"""Every default is defined once: the settings dataclasses. The YAML files under configs/ that list
defaults (configs/solver/srv.yaml, the job files, configs/experiment/...) have their values written
from the dataclasses (scripts/sync_defaults.py) and cannot drift from them; trials' default is one
constant."""

from __future__ import annotations

import dataclasses
import inspect
import runpy
from dataclasses import replace

import pytest

import graspnet_torch as gt
from graspnet_torch.errors import ConfigError
from graspnet_torch.experiments import ObjectsCfg, ProposalExperimentCfg, SolversCfg
from graspnet_torch.jobs.configs import DEFAULTS_FILES, SolveGraspJobCfg
from graspnet_torch.paths import configs_dir, repo_root
from graspnet_torch.settings import DefaultsFile, sync_defaults
from graspnet_torch.solver.config import DEFAULT_TRIALS

SCRIPT = runpy.run_path(str(repo_root() / "scripts" / "sync_defaults.py"))
SRV = next(spec for spec in DEFAULTS_FILES if spec.path == "solver/srv.yaml")


def test_no_yaml_file_differs_from_its_dataclass():
    """The check `make sync-defaults` fixes: every listed value equals its dataclass default (the
    declared exceptions aside), and each group file lists every setting (so `solver.x=...` works)."""
    assert len(SCRIPT["FILES"]) >= 20
    assert [(spec.path, missing) for spec, _, missing in SCRIPT["stale"]()] == []


def test_a_value_changed_by_hand_is_found_and_written_back():
    text = (configs_dir() / SRV.path).read_text(encoding="utf-8")
    edited = text.replace("max_iterations: 2000    #", "max_iterations: 1999    #", 1)
    edited = edited.replace("  step_size: 0.25       #", "  step_size: 0.5        #", 1)
    assert edited != text
    written, missing = sync_defaults(edited, SRV)
    assert written == text and missing == []  # keys, order, comments and alignment kept; the values the dataclass's


def test_the_dataclass_changing_changes_what_the_file_must_say():
    """A new default in the dataclass makes the shipped file stale (the first test then fails)."""
    text = (configs_dir() / SRV.path).read_text(encoding="utf-8")
    written, _ = sync_defaults(text, replace(SRV, cls=_with_default(gt.SolverCfg, "threshold", 0.95)))
    assert "threshold: 0.95         #" in written and written != text


def _with_default(cls: type, name: str, value: object) -> type:
    fields = [(f.name, f.type, dataclasses.field(default=value, metadata=f.metadata) if f.name == name else f)
              for f in dataclasses.fields(cls)]
    return dataclasses.make_dataclass(cls.__name__, fields, frozen=True)


def test_missing_and_unknown_keys():
    text = (configs_dir() / SRV.path).read_text(encoding="utf-8")
    dropped = "".join(line for line in text.splitlines(keepends=True) if not line.startswith("report:"))
    assert sync_defaults(dropped, SRV)[1] == ["report"]
    with pytest.raises(ConfigError, match=r"'polish\.nope' is not a setting of SolverCfg"):
        sync_defaults(text.replace("  iterations: 30", "  nope: 30"), SRV)


def test_unset_flow_collections_and_exceptions():
    spec = DefaultsFile("x.yaml", gt.RewardCfg, unset=True)
    assert sync_defaults("kind: null  # the robot's\na: 2\n", spec)[0] == "kind: null  # the robot's\na: 1.0\n"
    spec = DefaultsFile("x.yaml", SolversCfg, under=("experiments", "solvers"), skip=("quick",), differs=("seeds",))
    text = ("experiments:\n  solvers:\n    seeds: 9\n    trials: 3   # t\n"
            "    quick: {trials: 4,\n            trials: 5}\n")
    written, _ = sync_defaults(text, spec)
    assert written == text.replace("trials: 3   #", f"trials: {DEFAULT_TRIALS}  #")


def test_trials_default_is_one_constant():
    assert inspect.signature(gt.solve).parameters["trials"].default == DEFAULT_TRIALS
    assert inspect.signature(gt.solve_many).parameters["trials"].default == DEFAULT_TRIALS
    assert inspect.signature(gt.Solver).parameters["trials"].default == DEFAULT_TRIALS
    assert SolveGraspJobCfg().trials == DEFAULT_TRIALS
    assert SolversCfg().trials == SolversCfg().noise_trials == ObjectsCfg().trials == DEFAULT_TRIALS
    assert ProposalExperimentCfg().noise_trials == DEFAULT_TRIALS
    assert DEFAULT_TRIALS == 20  # the value results were measured with


def test_max_iterations_has_one_default():
    """The job's max_iterations is an override of solver.max_iterations, not a second default."""
    assert SolveGraspJobCfg().max_iterations is None
    assert inspect.signature(gt.solve).parameters["max_iterations"].default is None
    assert gt.SolverCfg().max_iterations == 2000
