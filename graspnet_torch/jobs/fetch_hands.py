"""The example hands whose URDF is fetched, not shipped (``scripts/fetch_hands.py``): a clone of
dexsuite/dex-urdf at ``COMMIT`` beside each config that names ``dex-urdf/...`` (git-ignored:
``examples/schunk_svh`` (GPL-3.0), ``examples/ability_hand``, ``examples/inspire_hand`` (licences that
grant no redistribution)). Needs only git and the network (or a local repository as ``source``)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import yaml

from graspnet_torch.errors import ConfigError
from graspnet_torch.paths import repo_root
from graspnet_torch.settings import clip

__all__ = ["COMMIT", "DEX_URDF", "fetch_hands", "fetched_folders"]

DEX_URDF = "https://github.com/dexsuite/dex-urdf"
COMMIT = "93505db"  # the commit every example hand from dex-urdf was taken at (examples/README.md)
CLONE = "dex-urdf"  # the clone's folder beside the config, named by the config's `urdf: dex-urdf/...`


def fetched_folders(examples: Path | None = None) -> list[Path]:
    """The example folders whose config names a URDF in a dex-urdf clone beside it."""
    folders = set()
    for path in sorted((examples or repo_root() / "examples").glob("*/*.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        if isinstance(data, dict) and str(data.get("urdf", "")).startswith(f"{CLONE}/"):
            folders.add(path.parent)
    return sorted(folders)


def _git(*args: str) -> None:
    """One git command; its last line of error as a :class:`ConfigError` where it fails."""
    try:
        done = subprocess.run(["git", *args], capture_output=True, text=True, timeout=1800, check=False)
    except (OSError, subprocess.SubprocessError) as exc:
        raise ConfigError(f"fetch_hands: git {args[0]}: {clip(str(exc), 200)}") from None
    if done.returncode:
        last = (done.stderr.strip().splitlines() or ["exit status " + str(done.returncode)])[-1]
        raise ConfigError(f"fetch_hands: git {args[0]} failed: {clip(last, 200)}")


def fetch_hands(source: str = DEX_URDF, commit: str = COMMIT, examples: Path | None = None) -> list[Path]:
    """Clone ``source`` (dex-urdf: a URL or a local repository) at ``commit`` into each
    ``<folder>/dex-urdf`` of :func:`fetched_folders` that lacks it (the first from ``source``, the
    others from that clone); the clones made, in order. Each is made as ``dex-urdf.part`` and
    renamed once all are made: on any failure every part is removed and nothing is written."""
    todo = [folder / CLONE for folder in fetched_folders(examples) if not (folder / CLONE).exists()]
    parts = [target.with_name(f"{CLONE}.part") for target in todo]
    try:
        for k, part in enumerate(parts):
            shutil.rmtree(part, ignore_errors=True)
            _git("clone", "--quiet", "--no-checkout", source if k == 0 else str(parts[0]), str(part))
            _git("-C", str(part), "checkout", "--quiet", commit)
            _git("-C", str(part), "remote", "set-url", "origin", source)
    except ConfigError:
        for part in parts:
            shutil.rmtree(part, ignore_errors=True)
        raise
    for part, target in zip(parts, todo, strict=True):
        part.rename(target)
    return todo
