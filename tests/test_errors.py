"""``say``: a line on stderr written whole, even when parallel jobs share the stream."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from graspnet_torch.errors import say


def test_say_writes_one_line_on_stderr(capsys):
    say("error: robot.yaml: bad key")
    assert capsys.readouterr().err == "error: robot.yaml: bad key\n"


@pytest.mark.slow
def test_lines_said_by_parallel_processes_on_one_pipe_stay_whole():
    """Four processes say 3000 lines each on one shared pipe (a parallel sweep's jobs on the
    terminal's stderr): every line read back is one process's line, whole. ``print(line,
    file=sys.stderr)`` fails this: it writes the text and the newline apart, and 5127 of 12000 lines
    came back run together on this machine."""
    code = "from graspnet_torch.errors import say\nfor _ in range(3000):\n    say({!r})"
    read, write = os.pipe()
    procs = [subprocess.Popen([sys.executable, "-c", code.format(ch * 300 + ".")], stderr=write) for ch in "abcd"]
    os.close(write)
    with os.fdopen(read, "rb") as stream:
        lines = stream.read().decode().split("\n")
    assert [p.wait(timeout=120) for p in procs] == [0, 0, 0, 0]
    assert lines[-1] == ""
    lines = lines[:-1]
    assert len(lines) == 12000
    broken = [line for line in lines if len(line) != 301 or len(set(line[:300])) != 1 or line[-1] != "."]
    assert not broken, f"{len(broken)} of {len(lines)} lines run together, e.g. {broken[0][:80]!r}"
