"""The example hands whose URDF is fetched, not shipped (``scripts/fetch_hands.py``):

- a clone of dexsuite/dex-urdf at ``COMMIT`` beside each config that names ``dex-urdf/...``
  (``examples/schunk_svh`` (GPL-3.0), ``examples/ability_hand``, ``examples/inspire_hand`` (licences
  that grant no redistribution)); needs git and the network (or a local repository as ``source``);
- a copy of an iCub model from the installed Python package ``icub-models`` (CC BY-SA 4.0;
  ``pip install icub-models``) beside each config that names ``iCub/robots/<model>/model.urdf``
  (``examples/icub_hand``): the URDF, the meshes it names and the package's licence.

Every fetched folder is git-ignored."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
import shutil
import subprocess
from pathlib import Path

import yaml

from graspnet_torch.errors import ConfigError
from graspnet_torch.paths import repo_root
from graspnet_torch.settings import clip

__all__ = ["CLONE", "COMMIT", "DEX_URDF", "ICUB", "ICUB_DIST", "fetch_hands", "fetched_folders"]

DEX_URDF = "https://github.com/dexsuite/dex-urdf"
COMMIT = "93505db"  # the commit every example hand from dex-urdf was taken at (examples/README.md)
CLONE = "dex-urdf"  # the clone's folder beside the config, named by the config's `urdf: dex-urdf/...`
ICUB = "iCub"  # the copy's folder beside the config, named by the config's `urdf: iCub/...`
ICUB_DIST = "icub-models"  # the PyPI distribution it is copied from (module icub_models)
_MESH = re.compile(r'filename="package://iCub/([^"]+)"')


def _configs(examples: Path | None, kind: str) -> dict[Path, Path]:
    """Example folder -> its (first) config that names a URDF under ``<folder>/<kind>/``."""
    out: dict[Path, Path] = {}
    for path in sorted((examples or repo_root() / "examples").glob("*/*.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        if isinstance(data, dict) and str(data.get("urdf", "")).startswith(f"{kind}/"):
            out.setdefault(path.parent, path)
    return out


def fetched_folders(examples: Path | None = None, kind: str = CLONE) -> list[Path]:
    """The example folders whose config names a URDF under ``<folder>/<kind>/`` (``kind``:
    ``dex-urdf`` or ``iCub``)."""
    return sorted(_configs(examples, kind))


def _git(*args: str) -> None:
    """One git command; its last line of error as a :class:`ConfigError` where it fails."""
    try:
        done = subprocess.run(["git", *args], capture_output=True, text=True, timeout=1800, check=False)
    except (OSError, subprocess.SubprocessError) as exc:
        raise ConfigError(f"fetch_hands: git {args[0]}: {clip(str(exc), 200)}") from None
    if done.returncode:
        last = (done.stderr.strip().splitlines() or ["exit status " + str(done.returncode)])[-1]
        raise ConfigError(f"fetch_hands: git {args[0]} failed: {clip(last, 200)}")


def _icub_share() -> Path:
    """The installed icub-models' ``share/iCub`` folder (its ``robots/`` and ``meshes/``)."""
    if importlib.util.find_spec("icub_models") is None:
        raise ConfigError(f"fetch_hands: {ICUB}: the Python package {ICUB_DIST} is not installed "
                          f"(pip install {ICUB_DIST}, or pip install -e '.[hands]')")
    from icub_models import get_models_path  # an optional dependency, imported only here

    return Path(get_models_path()).parent


def _icub_licence() -> Path | None:
    """The installed icub-models' licence file, None where the package or the file is missing."""
    try:
        dist = importlib.metadata.distribution(ICUB_DIST)
    except importlib.metadata.PackageNotFoundError:
        return None
    found = [f for f in dist.files or () if f.name.upper().startswith("LICENSE")]
    return Path(str(dist.locate_file(found[0]))) if found else None


def _copy_icub(share: Path, config: Path, part: Path) -> None:
    """Copy the model the config names (``iCub/robots/<model>/model.urdf``), the meshes it names
    (``package://iCub/...``) and the licence (``share``'s, else the installed package's) from
    ``share`` into ``part`` (laid out as ``share``)."""
    rel = str(yaml.safe_load(config.read_text(encoding="utf-8"))["urdf"]).removeprefix(f"{ICUB}/")
    urdf = share / rel
    if ".." in Path(rel).parts or not urdf.is_file():
        raise ConfigError(f"fetch_hands: {config.name}: {ICUB_DIST} has no {rel}")
    for name in (rel, *dict.fromkeys(_MESH.findall(urdf.read_text(encoding="utf-8")))):
        if Path(name).is_absolute() or ".." in Path(name).parts:  # nothing from or to outside the model's folders
            raise ConfigError(f"fetch_hands: {config.name}: {clip(name, 120)} leads out of {ICUB}/")
        (part / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(share / name, part / name)
    licence = share / "LICENSE" if (share / "LICENSE").is_file() else _icub_licence()
    if licence is not None:
        shutil.copyfile(licence, part / "LICENSE")


def fetch_hands(source: str = DEX_URDF, commit: str = COMMIT, examples: Path | None = None,
                icub: Path | None = None) -> list[Path]:
    """Fetch every example hand not there yet: clone ``source`` (dex-urdf: a URL or a local
    repository) at ``commit`` into each ``<folder>/dex-urdf`` of :func:`fetched_folders` that lacks
    it (the first from ``source``, the others from that clone), and copy the iCub model into each
    ``<folder>/iCub`` that lacks it from ``icub`` (a folder laid out as icub-models'
    ``share/iCub``: ``robots/``, ``meshes/``; default: the installed package's); the folders made,
    in order. Each is made as ``<name>.part`` and
    renamed once all are made: on any failure (git, icub-models not installed) every part is removed
    and nothing is written."""
    clones = [folder / CLONE for folder in fetched_folders(examples) if not (folder / CLONE).exists()]
    named = _configs(examples, ICUB)
    copies = [folder / ICUB for folder in sorted(named) if not (folder / ICUB).exists()]
    share = icub or (_icub_share() if copies else Path())
    parts = [target.with_name(f"{target.name}.part") for target in (*clones, *copies)]
    try:
        for k, part in enumerate(parts[:len(clones)]):
            shutil.rmtree(part, ignore_errors=True)
            _git("clone", "--quiet", "--no-checkout", source if k == 0 else str(parts[0]), str(part))
            _git("-C", str(part), "checkout", "--quiet", commit)
            _git("-C", str(part), "remote", "set-url", "origin", source)
        for target, part in zip(copies, parts[len(clones):], strict=True):
            shutil.rmtree(part, ignore_errors=True)
            _copy_icub(share, named[target.parent], part)
    except (ConfigError, OSError) as exc:
        for part in parts:
            shutil.rmtree(part, ignore_errors=True)
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"fetch_hands: {ICUB}: {clip(str(exc), 200)}") from None
    for part, target in zip(parts, (*clones, *copies), strict=True):
        part.rename(target)
    return [*clones, *copies]
