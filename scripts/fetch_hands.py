"""Fetch the example hands whose URDF is not shipped: dexsuite/dex-urdf at commit 93505db, cloned
into each git-ignored examples/<hand>/dex-urdf (schunk_svh, ability_hand, inspire_hand), and the
iCub hand copied from the installed Python package icub-models into examples/icub_hand/iCub.

    python scripts/fetch_hands.py                          # from GitHub (git and the network)
    python scripts/fetch_hands.py --from /path/to/dex-urdf # from a local clone or another URL

Exit status: 0 when every such folder is there, 2 when git failed or icub-models is not installed
(one line on stderr; nothing written).
"""

from __future__ import annotations

import argparse
import sys

from graspnet_torch.errors import GraspnetError, say
from graspnet_torch.jobs.fetch_hands import CLONE, COMMIT, DEX_URDF, ICUB_DIST, fetch_hands


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="source", default=DEX_URDF, help=f"dex-urdf's repository (default {DEX_URDF})")
    args = ap.parse_args(argv)
    try:
        made = fetch_hands(args.source)
    except GraspnetError as exc:
        say(str(exc))
        return 2
    for path in made:
        print(f"fetched {path} ({f'dex-urdf at {COMMIT}' if path.name == CLONE else f'from {ICUB_DIST}'})")
    if not made:
        print("every fetched hand is there already")
    return 0


if __name__ == "__main__":
    sys.exit(main())
