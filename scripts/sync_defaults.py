"""Write the defaults the YAML files under configs/ list from the settings dataclasses (their one source).

    python scripts/sync_defaults.py           # rewrite every value that differs from its dataclass's default
    python scripts/sync_defaults.py --check   # exit 1 (naming them) where a file differs; nothing written

A file keeps its keys, order and comments; only values are written (graspnet_torch.settings.sync_defaults).
The files: graspnet_torch.jobs.configs.DEFAULTS_FILES, graspnet_torch.experiments.DEFAULTS_FILES and
configs/reproduce.yaml. `make sync-defaults` runs it; tests/test_defaults_files.py runs the check.
"""

from __future__ import annotations

import argparse
import sys

from graspnet_torch.experiments import DEFAULTS_FILES as EXPERIMENT_FILES
from graspnet_torch.jobs.configs import DEFAULTS_FILES as JOB_FILES
from graspnet_torch.jobs.reproduce import ReproduceJobCfg
from graspnet_torch.paths import configs_dir
from graspnet_torch.settings import DefaultsFile, sync_defaults

FILES = (*JOB_FILES, DefaultsFile("reproduce.yaml", ReproduceJobCfg, skip=("defaults", "hydra"), complete=False),
         *EXPERIMENT_FILES)


def stale() -> list[tuple[DefaultsFile, str, list[str]]]:
    """Each file whose text differs from its values written from the dataclass, or that misses a
    setting it must list: (its spec, the text it should have, the settings it misses)."""
    out = []
    for spec in FILES:
        text = (configs_dir() / spec.path).read_text(encoding="utf-8")
        written, missing = sync_defaults(text, spec)
        missing = missing if spec.complete else []
        if written != text or missing:
            out.append((spec, written, missing))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 where a file differs; write nothing")
    args = ap.parse_args(argv)
    bad = stale()
    for spec, written, missing in bad:
        if missing:
            print(f"configs/{spec.path}: add {', '.join(missing)} (settings of {spec.cls.__name__}), with a comment")
        if args.check and written != (configs_dir() / spec.path).read_text(encoding="utf-8"):
            print(f"configs/{spec.path}: values differ from {spec.cls.__name__}'s defaults (python {sys.argv[0]})")
        elif written != (configs_dir() / spec.path).read_text(encoding="utf-8"):
            (configs_dir() / spec.path).write_text(written, encoding="utf-8")
            print(f"configs/{spec.path}: written from {spec.cls.__name__}")
    return 1 if (args.check and bad) or any(missing for _, _, missing in bad) else 0


if __name__ == "__main__":
    sys.exit(main())
