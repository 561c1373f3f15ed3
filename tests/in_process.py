"""Running a script of scripts/ inside the test process, as ``python scripts/<name> ARGS`` would.

A fresh interpreter costs 3-5 s (python, torch and Hydra imports) before the script checks
anything; a refusal itself takes milliseconds. :func:`run_script` executes the script's file as
``__main__`` (``runpy``) with ``sys.argv`` set, so the same entry point runs (``run_cli`` with the
script's settings class, config name and checks), and turns its ``sys.exit`` into an exit code.
What the script changes in the process (the argument list, torch's thread count, Hydra's error
variable) is put back afterwards. Tests of what only a fresh process shows (start-up time, peak
memory, import side effects) run the script in a subprocess instead (:mod:`tests.processes`).
"""

from __future__ import annotations

import contextlib
import io
import os
import runpy
import sys
import warnings
from dataclasses import dataclass

import torch

from graspnet_torch.paths import repo_root


@dataclass
class ScriptRun:
    """The outcome of a script: its exit code (0 when it returned), its stdout and stderr text,
    and the warnings it raised."""

    returncode: int
    stdout: str
    stderr: str
    warnings: list[str]


def run_script(script: str, *args: str) -> ScriptRun:
    """Run ``scripts/<script>`` with the command-line arguments ``args`` in this process."""
    path = str(repo_root() / "scripts" / script)
    argv, threads = sys.argv, torch.get_num_threads()
    hydra_error = os.environ.get("HYDRA_FULL_ERROR")
    out, err = io.StringIO(), io.StringIO()
    code = 0
    try:
        sys.argv = [path, *args]
        with (warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(out),
              contextlib.redirect_stderr(err)):
            warnings.simplefilter("default")
            try:
                runpy.run_path(path, run_name="__main__")
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if not isinstance(exc.code, int | None):
                    print(exc.code, file=sys.stderr)
    finally:
        sys.argv = argv
        torch.set_num_threads(threads)
        if hydra_error is None:
            os.environ.pop("HYDRA_FULL_ERROR", None)
        else:
            os.environ["HYDRA_FULL_ERROR"] = hydra_error
    return ScriptRun(code, out.getvalue(), err.getvalue(), [str(w.message) for w in caught])
