"""The paper's experiments: their configs, their statistics against independent recomputations,
and the same seeds giving the same numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from graspnet_torch.errors import ConfigError
from graspnet_torch.experiments import EXPERIMENTS, Fig10Cfg, ObstaclesCfg, run_fig10, run_tables
from graspnet_torch.experiments.obstacles import REWARDS, anova, posthoc_rows
from graspnet_torch.experiments.report import ExperimentReport, Figure, mean_std, quick_settings
from graspnet_torch.jobs.reproduce import shipped_experiments
from graspnet_torch.paths import configs_dir
from graspnet_torch.table import markdown_table


def test_every_experiment_has_a_config_and_both_protocols_build():
    files = sorted(p.stem for p in (configs_dir() / "experiment").glob("*.yaml"))
    assert files == sorted(EXPERIMENTS)
    shipped = shipped_experiments()
    for name, experiment in EXPERIMENTS.items():
        full = quick_settings(experiment.cfg, shipped[name], quick=False)
        reduced = quick_settings(experiment.cfg, shipped[name], quick=True)
        assert full != reduced, f"{name}: the quick block changes nothing"
        assert full == experiment.cfg(), f"{name}: the shipped config differs from the defaults in code"


def test_plus_experiment_selects_that_experiment_only():
    with initialize_config_dir(config_dir=str(configs_dir()), version_base="1.3"):
        cfg = compose("reproduce", overrides=["+experiment=table3", "experiments.table3.runs=7"])
    assert list(cfg.experiments) == ["table3"] and cfg.experiments.table3.runs == 7


def test_a_bad_setting_or_quick_block_is_refused_with_its_key():
    with pytest.raises(ConfigError, match=r"experiments\.table3\.runs"):
        quick_settings(ObstaclesCfg, {"runs": 0}, False, "experiments.table3")
    with pytest.raises(ConfigError, match=r"experiments\.table3\.quick\.runz"):
        quick_settings(ObstaclesCfg, {"runs": 30, "quick": {"runz": 3}}, False, "experiments.table3")


def _rows(groups: dict[str, list[int]]) -> dict:
    return {("env1", k): {"iters": v} for k, v in groups.items()}


def test_anova_and_bonferroni_agree_with_a_recomputation_by_hand():
    rng = np.random.default_rng(3)
    groups = {k: rng.integers(50, 600, size=n).tolist() for k, n in zip(REWARDS, (9, 7, 8, 6), strict=True)}
    _, stats = anova(_rows(groups), ("env1",))
    data = [np.asarray(groups[k], float) for k in REWARDS]
    grand = np.concatenate(data).mean()
    between = sum(len(g) * (g.mean() - grand) ** 2 for g in data) / 3
    within = sum(((g - g.mean()) ** 2).sum() for g in data) / (sum(map(len, data)) - 4)
    assert stats["F"] == pytest.approx(between / within, rel=1e-12)
    assert stats["df"] == sum(map(len, data)) - 4
    # pooled two-sample t of R1 vs R2, and Bonferroni's x6 on its two-sided p
    from scipy import stats as sps

    a, b = data[0], data[1]
    sp = math.sqrt(((len(a) - 1) * a.var(ddof=1) + (len(b) - 1) * b.var(ddof=1)) / (len(a) + len(b) - 2))
    t = (a.mean() - b.mean()) / (sp * math.sqrt(1 / len(a) + 1 / len(b)))
    p = 2 * sps.t.sf(abs(t), len(a) + len(b) - 2)
    assert stats["tests"]["r1", "r2"][0] == pytest.approx(t, rel=1e-10)
    assert stats["tests"]["r1", "r2"][1] == pytest.approx(min(1.0, 6 * p), rel=1e-10)


def test_the_posthoc_table_reads_the_papers_findings_in_the_data():
    """Groups built to show the paper's pattern (R1 fastest, R2 slowest, R3 ~ R4) agree on every row;
    reversed, R2 vs R1 is named as a difference."""
    paper_like = {"r1": [100 + i for i in range(30)], "r2": [600 + i for i in range(30)],
                  "r3": [300 + i for i in range(30)], "r4": [302 + i for i in range(30)]}
    rows, differ = posthoc_rows(anova(_rows(paper_like), ("env1",))[1])
    assert [r[2] for r in rows] == ["yes"] * 6 and differ == []
    reversed_ = {**paper_like, "r1": paper_like["r2"], "r2": paper_like["r1"]}
    _, differ = posthoc_rows(anova(_rows(reversed_), ("env1",))[1])
    assert any(d.startswith("R2 vs R1") for d in differ)


def test_markdown_tables_and_mean_std():
    text = markdown_table(["name", "value"], [["a|b", 1.23456], ["c", 2.0]])
    lines = text.splitlines()
    assert lines[0] == "| name | value |" and lines[1] == "|---|---:|"
    assert lines[2] == "| a\\|b | 1.23 |"
    assert mean_std([1.0, 3.0]) == f"2.00 +- {np.std([1.0, 3.0], ddof=1):.2f}" and mean_std([5.0]) == "5.00 +- 0.00"


@pytest.mark.slow
def test_the_same_seeds_give_the_same_numbers(tmp_path):
    """Two runs of an experiment with the same settings: every number identical; another seed differs."""
    cfg = ObstaclesCfg(runs=2, environments=("env1",), cmaes=False)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = run_tables(cfg, tmp_path / "a")
    second = run_tables(cfg, tmp_path / "b")
    assert first.numbers == second.numbers and len(first.numbers) > 10
    assert (tmp_path / "a" / "fig8_learning.png").read_bytes()[:4] == b"\x89PNG"
    one, other = run_fig10(Fig10Cfg(trials=2, seed=0), tmp_path), run_fig10(Fig10Cfg(trials=2, seed=5), tmp_path)
    again = run_fig10(Fig10Cfg(trials=2, seed=0), tmp_path)
    assert one.numbers == again.numbers and one.numbers != other.numbers


def test_a_report_renders_its_figures_targets_and_mismatches():
    r = ExperimentReport("x", "Title X", "body text", figures=[Figure("f.png", "the caption")],
                         checks=[("a target", False)], mismatches=["one thing differs."])
    text = r.markdown("python run.py", "##")
    assert text.startswith("## Title X") and "![the caption](f.png)" in text and "- MISSED: a target" in text
    assert "### What does not match the paper\n\n- one thing differs." in text
