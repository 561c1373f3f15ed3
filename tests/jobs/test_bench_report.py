"""benchmarks/report.py: an unknown benchmark is refused in one line, exit 2, no report written."""

from __future__ import annotations

import runpy

from graspnet_torch.paths import repo_root


def test_an_unknown_benchmark_is_refused_and_writes_no_report(tmp_path, capsys):
    main = runpy.run_path(str(repo_root() / "benchmarks" / "report.py"))["main"]
    assert main(["no_such_bench", "report", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == ["report: no benchmark 'no_such_bench' (benchmarks/no_such_bench.py)",
                                "report: no benchmark 'report' (benchmarks/report.py)"]
    assert list(tmp_path.iterdir()) == []


def test_options_for_several_benchmarks_at_once_are_refused(tmp_path, capsys):
    main = runpy.run_path(str(repo_root() / "benchmarks" / "report.py"))["main"]
    assert main(["calls", "quality", "--args=--long", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == "report: --args and --as take one benchmark\n"
    assert list(tmp_path.iterdir()) == []
