"""The job behind ``scripts/view.py``: a result in the browser (:mod:`graspnet_torch.viz.viewer`)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence

from graspnet_torch.errors import ConfigError

__all__ = ["view_result"]


def view_result(argv: Sequence[str] | None = None, *, block: bool = True):
    """Parse ``PATH [--host H] [--port P]``, load the result (refusals: :class:`ProblemError`,
    before any server starts), serve it and print its address; with ``block``, run until Ctrl-C.
    Returns the server (stop it with ``server.stop()``)."""
    parser = argparse.ArgumentParser(prog="view.py", description="A result in the browser (viser).")
    parser.add_argument("path", help="a run folder (with result.json) or a result JSON file")
    parser.add_argument("--host", default="127.0.0.1", help="the address to bind (default: this machine only)")
    parser.add_argument("--port", default="8080", help="the port (default 8080)")
    args = parser.parse_args(argv)
    port = int(args.port) if args.port.isdigit() else -1
    if not 0 < port < 65536:
        raise ConfigError(f"--port: '{args.port}' is not a port (1-65535)")
    from graspnet_torch.viz.viewer import load_view, serve

    t0 = time.perf_counter()
    view = load_view(args.path)
    server = serve(view, args.host, port)
    print(f"viewing {view.path} ({view.robot.name}, {len(view.postures)} trials"
          f"{', a reach motion' if view.motion is not None else ''}) at http://{args.host}:{server.get_port()} "
          f"(ready in {time.perf_counter() - t0:.1f} s; Ctrl-C stops)", flush=True)
    if block:
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            server.stop()
    return server
