"""scripts/reproduce.py: one experiment end to end, refusals that write nothing, and the report's
completeness check that CI's `make reproduce-quick` relies on."""

from __future__ import annotations

import json

import pytest

from graspnet_torch.errors import InternalError
from graspnet_torch.experiments.report import ExperimentReport, Figure
from graspnet_torch.jobs.reproduce import REPORT, check_complete, compare_numbers, missed_targets, render
from tests.in_process import ScriptRun, run_script


def _run(*args: str) -> ScriptRun:
    """scripts/reproduce.py's entry point, in this process (:func:`run_script`)."""
    return run_script("reproduce.py", *args)


@pytest.mark.slow
def test_one_experiment_writes_the_report_numbers_and_figure(tmp_path):
    out = tmp_path / "out"
    res = _run("+experiment=fig10", "experiments.fig10.trials=2", f"out={out}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 0, res.stderr
    text = (out / REPORT).read_text()
    assert "## Fig. 10" in text and "![Fig. 10" in text and "## Machine, settings and seeds" in text
    assert "## Table 2" not in text and "## Fig. 3" not in text  # only the experiment asked for
    data = json.loads((out / "reproduction.json").read_text())
    assert list(data["experiments"]) == ["fig10"] and data["experiments"]["fig10"]["settings"]["trials"] == 2
    assert (out / "fig10_posture.png").read_bytes()[:4] == b"\x89PNG"
    assert compare_numbers(out / "reproduction.json", out / "reproduction.json") == []


@pytest.mark.parametrize("args, message", [
    (["+experiment=table9"], "unknown experiment 'table9'"),
    (["+experiment=fig10", "experiments.fig10.trials=0"], "experiments.fig10.trials"),
    (["+experiment=fig10", "experiments.fig10.trialz=2"], "experiments.fig10.trialz"),
    (["quick=maybe"], "quick"),
    (["+experiment=table2", "experiments.table2.tasks=[glass9]"], "experiments.table2.tasks"),
    (["+experiment=table3", "experiments.table3.environments=[]"], "experiments.table3.environments"),
    (["+experiment=solvers", "experiments.solvers.noise_levels=[0.3]"], "noise preset"),
    (["+experiment=fig3", "experiments.fig3.quick.steps=10"], "experiments.fig3.quick.steps"),
])
def test_bad_settings_are_one_line_exit_2_and_nothing_written(tmp_path, args, message):
    out = tmp_path / "out"
    res = _run(*args, f"out={out}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2, res.stderr
    assert message in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not out.exists() and not (tmp_path / "run").exists()


def test_an_output_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "taken").write_text("x")
    res = _run("+experiment=fig10", f"out={tmp_path / 'taken'}", f"hydra.run.dir={tmp_path / 'run'}")
    assert res.returncode == 2 and "is a file" in res.stderr
    assert (tmp_path / "taken").read_text() == "x"


def _report(tmp_path, body: str, figure: bool = True) -> ExperimentReport:
    if figure:
        (tmp_path / "f.png").write_bytes(b"\x89PNG....")
    return ExperimentReport("x", "Table 9: something", body, figures=[Figure("f.png", "a caption")], tables=["Table 9"])


def test_the_completeness_check_finds_a_missing_table_or_figure(tmp_path):
    good = _report(tmp_path, "### Table 9\n\n| a | b |\n|---|---|\n| 1 | 2 |")
    (tmp_path / REPORT).write_text(render([good], {"cpu": "x"}, 1.0, quick=False))
    check_complete(tmp_path, [good])  # complete: no error
    no_table = _report(tmp_path, "no table here")
    (tmp_path / REPORT).write_text(render([no_table], {"cpu": "x"}, 1.0, quick=False))
    with pytest.raises(InternalError, match="Table 9 is missing"):
        check_complete(tmp_path, [no_table])
    (tmp_path / "f.png").unlink()
    (tmp_path / REPORT).write_text(render([good], {"cpu": "x"}, 1.0, quick=False))
    with pytest.raises(InternalError, match=r"figure f\.png"):
        check_complete(tmp_path, [good])


def test_compare_numbers_names_what_differs(tmp_path):
    def write(name, numbers):
        (tmp_path / name).write_text(json.dumps({"experiments": {"fig3": {"numbers": numbers, "timings": {"t": 1}}}}))

    write("a.json", {"x": 1.0, "y": float("nan")})
    write("b.json", {"x": 1.5, "y": float("nan")})
    assert compare_numbers(tmp_path / "a.json", tmp_path / "b.json") == ["fig3: x: 1.0 vs 1.5"]


def test_missed_targets_lists_each_missed_check_of_every_experiment(tmp_path):
    (tmp_path / "r.json").write_text(json.dumps({"experiments": {
        "manus": {"checks": [["mean d < 2 mm", True], ["random 30/40 >= 95 %", False]]},
        "arm": {"checks": [["env1 29/30", False]]}, "fig10": {"checks": []}}}))
    assert missed_targets(tmp_path / "r.json") == ["manus: random 30/40 >= 95 %", "arm: env1 29/30"]
    (tmp_path / "ok.json").write_text(json.dumps({"experiments": {"manus": {"checks": [["mean d < 2 mm", True]]}}}))
    assert missed_targets(tmp_path / "ok.json") == []
