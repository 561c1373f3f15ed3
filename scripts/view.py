"""A result in the browser: the robot, object, obstacles and contacts in 3D, any trial, the reach motion.

    python scripts/view.py outputs/demo                 # a run folder (its result.json)
    python scripts/view.py result.json --port 8081      # a result JSON; --host 0.0.0.0 to serve other machines

It binds to localhost by default, prints the address and runs until stopped (Ctrl-C). Exit status 2
with one line on stderr for a missing or bad file or setting; Ctrl-C stops it with one line.
"""

from __future__ import annotations

import sys

from graspnet_torch.errors import say
from graspnet_torch.jobs.cli import user_errors_exit_2
from graspnet_torch.jobs.view_result import view_result


@user_errors_exit_2
def main() -> None:
    try:
        view_result()
    except KeyboardInterrupt:  # Ctrl-C before the page is served (while the result loads)
        say("interrupted (Ctrl-C): nothing served")
        sys.exit(130)


if __name__ == "__main__":
    main()
