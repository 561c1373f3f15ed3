from __future__ import annotations

import os
import stat

import pytest

from graspnet_torch.io import atomic_path, atomic_write_text


def test_atomic_write_replaces_and_has_normal_permissions(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old")
    atomic_write_text(target, "new")
    assert target.read_text() == "new"
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_failed_write_leaves_previous_file_and_no_temporary(tmp_path):
    target = tmp_path / "ckpt.pt"
    target.write_text("good")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "good"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ckpt.pt"]


@pytest.mark.slow
def test_sigkill_during_a_write_leaves_the_previous_file_whole(tmp_path):
    """A writer killed with SIGKILL in the middle of writing 20 MB leaves the old file as it was
    (only a stray temporary, never a half-written target)."""
    import signal
    import subprocess
    import sys
    import time

    target = tmp_path / "result.json"
    target.write_text("previous\n")
    code = ("import sys, time; from graspnet_torch.io import atomic_path\n"
            "with atomic_path(sys.argv[1]) as tmp:\n"
            "    with open(tmp, 'w') as fh:\n"
            "        for _ in range(2000):\n"
            "            fh.write('x' * 10000); fh.flush(); time.sleep(0.001)\n")
    proc = subprocess.Popen([sys.executable, "-c", code, str(target)])
    deadline = time.time() + 30
    while time.time() < deadline and not [p for p in tmp_path.iterdir() if p.name.startswith(".result.json.")]:
        time.sleep(0.01)
    time.sleep(0.2)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert target.read_text() == "previous\n"
