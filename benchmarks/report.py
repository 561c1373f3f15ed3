"""Run benchmarks in fresh processes and keep what each printed as a report the docs can quote.

    python benchmarks/report.py calls bench_manus     # -> reports/bench_calls.md, reports/bench_manus.md
    python benchmarks/report.py calls --out DIR       # into DIR
    python benchmarks/report.py any_hand --args="--robot examples/schunk_svh/schunk_svh_right.yaml --fingers 2 5" \
        --as any_hand_schunk                          # one benchmark with options -> reports/bench_any_hand_schunk.md

Each NAME runs as ``python benchmarks/NAME.py --check`` (one torch thread, its own defaults) in a
new process, and ``reports/bench_NAME.md`` (NAME without a leading ``bench_``) gets its whole
standard output (its tables, its ratios against the peer measured in the same run and its targets,
met or MISSED), the command, the date, the wall time, the exit status and the machine with the
commit (``graspnet_torch.experiments.report.machine``). A report is written atomically, also when
a target is missed; a benchmark that crashed writes none. Exit status: 0 when every benchmark met
its targets, 1 when one missed a target, 2 for an unknown name or a crash (one line on stderr each).
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _report(name: str, command: list[str], done: subprocess.CompletedProcess[str], wall: float) -> str:
    from graspnet_torch.experiments.report import machine

    status = "every target met" if done.returncode == 0 else "a target MISSED"
    head = (f"Written by `python benchmarks/report.py` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}: "
            f"`{' '.join(command)}` in a fresh process, {wall:.0f} s, exit status {done.returncode} ({status}). "
            "Below, everything it printed; the machine and the commit at the end.")
    here = {**machine(), "torch threads": "the benchmark's --threads (default 1)"}  # not this process's
    return "\n".join([f"# Benchmark `{name}`", "", head, "", "```text", done.stdout.rstrip(), "```", "",
                      "| machine | |", "|---|---|", *(f"| {k} | {v} |" for k, v in here.items()), ""])


def run(name: str, out: Path, args: Sequence[str] = (), title: str | None = None) -> int:
    """Run ``benchmarks/<name>.py --check [args]`` and write ``out/bench_<title>.md`` (``title``:
    default ``name`` without a leading ``bench_``); its exit status (2 when it crashed: no report)."""
    from graspnet_torch.io import atomic_write_text

    script = HERE / f"{name}.py"
    if name == "report" or not script.is_file():
        print(f"report: no benchmark '{name}' (benchmarks/{name}.py)", file=sys.stderr)
        return 2
    command = [sys.executable, str(script.relative_to(HERE.parent)), "--check", *args]
    t0 = time.perf_counter()
    done = subprocess.run(command, cwd=HERE.parent, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if done.returncode not in (0, 1):
        last = (done.stderr.strip().splitlines() or [f"exit status {done.returncode}"])[-1]
        print(f"report: {name} failed: {last}", file=sys.stderr)
        return 2
    title = title or name.removeprefix("bench_")
    path = atomic_write_text(out / f"bench_{title}.md", _report(name, command[1:], done, wall))
    print(f"wrote {path} ({wall:.0f} s, {'targets met' if done.returncode == 0 else 'a target missed'})")
    return done.returncode


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="+", help="benchmarks/NAME.py to run")
    ap.add_argument("--out", default=str(HERE.parent / "reports"), help="folder of the reports (default reports/)")
    ap.add_argument("--args", default="", help="options for the one benchmark named (quoted: one string)")
    ap.add_argument("--as", dest="title", default=None, help="its report's name: reports/bench_TITLE.md")
    args = ap.parse_args(argv)
    if (args.args or args.title) and len(args.names) != 1:
        print("report: --args and --as take one benchmark", file=sys.stderr)
        return 2
    return max(run(name, Path(args.out), shlex.split(args.args), args.title) for name in args.names)


if __name__ == "__main__":
    sys.exit(main())
