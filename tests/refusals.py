"""What a refusal must look like, for the bad-input tests: exit 2, one line ``error: ...`` on
stderr naming what and where, no traceback, nothing written (not even Hydra's run folder).

- :func:`refused`: the script's own entry point inside the test process (milliseconds).
- :func:`refused_in_a_fresh_process`: the script as a real command; also quick and small.
- :func:`check_refusal`: the assertions on an exit code and stderr already in hand.
- :func:`interrupted_command`: a real command stopped by Ctrl-C once it is under way.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from graspnet_torch.paths import repo_root
from tests.in_process import run_script
from tests.processes import run_measured

__all__ = ["check_refusal", "interrupted_command", "refused", "refused_in_a_fresh_process", "run_command",
           "run_command_measured", "write_problem"]


def run_command(script: str, *args: str, timeout: float = 120) -> tuple[subprocess.CompletedProcess, float]:
    """``python scripts/<script> ARGS`` in a fresh process from the repository root: the process and
    its wall time (s)."""
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, str(repo_root() / "scripts" / script), *args], capture_output=True,
                         text=True, cwd=repo_root(), timeout=timeout)
    return res, time.perf_counter() - t0


def run_command_measured(tmp_path: Path, script: str, *args: str, timeout: float = 120
                         ) -> tuple[subprocess.CompletedProcess, float, int]:
    """:func:`run_command` through a small launcher: also the script's own peak memory (bytes)."""
    t0 = time.perf_counter()
    res, peak = run_measured([sys.executable, str(repo_root() / "scripts" / script), *args], tmp_path / "peak.json",
                             capture_output=True, text=True, cwd=repo_root(), timeout=timeout)
    return res, time.perf_counter() - t0, peak


def interrupted_command(script: str, *args: str, ready: Path, wait_s: float = 0.2, start_s: float = 120,
                        group: bool = False) -> subprocess.CompletedProcess:
    """``python scripts/<script> ARGS`` as a real command from the repository root, sent SIGINT
    (Ctrl-C) ``wait_s`` after ``ready`` appears (at most ``start_s`` after its start: imports take
    seconds on a busy machine); its outcome (asserted still running when interrupted). ``group``:
    the signal goes to the command's process group, its workers too, as a terminal's Ctrl-C does."""
    proc = subprocess.Popen([sys.executable, str(repo_root() / "scripts" / script), *args], cwd=repo_root(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=group)
    try:
        deadline = time.monotonic() + start_s
        while not ready.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert proc.poll() is None, proc.communicate()[1][-2000:]
        time.sleep(wait_s)
        if group:
            os.killpg(proc.pid, signal.SIGINT)
        else:
            proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def check_refusal(tmp_path: Path, returncode: int, stderr: str, message: str) -> str:
    """Exit 2, one ``error:`` line holding ``message``, no traceback, no ``tmp_path/run``; the line."""
    lines = stderr.strip().splitlines()
    assert returncode == 2, stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in stderr, stderr[-2000:]
    assert message in lines[0], lines[0]
    assert not (tmp_path / "run").exists(), "a refused run wrote its run folder"
    return lines[0]


def refused(tmp_path: Path, script: str, *args: str, message: str) -> str:
    """Run ``script`` (in this process) with its outputs under tmp_path/run; assert a clean
    refusal; return the line."""
    res = run_script(script, *args, f"hydra.run.dir={tmp_path / 'run'}", f"hydra.sweep.dir={tmp_path / 'run'}")
    line = check_refusal(tmp_path, res.returncode, res.stderr, message)
    assert res.stdout == "" and res.warnings == [], (res.stdout[-2000:], res.warnings)
    return line


def refused_in_a_fresh_process(tmp_path: Path, script: str, *args: str, message: str,
                               max_bytes: int = 1 << 30) -> str:
    """:func:`refused` as a real command: also quick (< 30 s with the interpreter's start) and
    small (< ``max_bytes`` peak, 1 GiB by default)."""
    res, seconds, peak = run_command_measured(tmp_path, script, *args, f"hydra.run.dir={tmp_path / 'run'}",
                                              f"hydra.sweep.dir={tmp_path / 'run'}")
    line = check_refusal(tmp_path, res.returncode, res.stderr, message)
    assert seconds < 30
    assert peak < max_bytes, f"a refusal peaked at {peak / 2**20:.0f} MiB"
    return line


def write_problem(tmp_path: Path, text: str, name: str = "p.yaml") -> Path:
    """``text`` written to ``tmp_path/name``; its path."""
    path = tmp_path / name
    path.write_text(text)
    return path
