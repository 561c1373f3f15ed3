"""Running a program in a fresh process and measuring its own peak memory.

``ru_maxrss`` of a child on Linux starts at its parent's resident size when it was forked (the
high-water mark survives ``exec``), so a child of a large test process (pytest after the mesh
tests holds over 1 GB) would look as large as its parent. A small launcher process in between
(a bare interpreter, ~10 MB) makes the measured peak the program's own.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

LAUNCHER = (
    "import json, resource, subprocess, sys\n"
    "res = subprocess.run(sys.argv[2:])\n"
    "peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024\n"
    "open(sys.argv[1], 'w').write(json.dumps(peak))\n"
    "sys.exit(res.returncode)\n"
)


def run_measured(args: list[str], report: Path, **kwargs) -> tuple[subprocess.CompletedProcess, int]:
    """Run ``args`` (a command line) through the launcher; its outcome and its peak resident memory
    in bytes. ``report`` is a scratch file for the launcher's figure; ``kwargs`` go to
    :func:`subprocess.run` (``capture_output``, ``text``, ``cwd``, ``timeout``...)."""
    res = subprocess.run([sys.executable, "-c", LAUNCHER, str(report), *args], **kwargs)
    peak = json.loads(Path(report).read_text())
    Path(report).unlink()
    return res, int(peak)
