"""The job behind ``scripts/view.py``: a result in the browser (:mod:`graspnet_torch.viz.viewer`)."""

from __future__ import annotations

import argparse
import ipaddress
import socket
import time
from collections.abc import Sequence

from graspnet_torch.errors import ConfigError, say
from graspnet_torch.settings import clip
from graspnet_torch.viz.viewer import load_view, serve

__all__ = ["check_host", "check_port", "view_result"]


class _Parser(argparse.ArgumentParser):
    """argparse whose mistakes are one :class:`ConfigError` line, not its usage text and exit 2."""

    def error(self, message: str):
        raise ConfigError(f"{clip(message, 200)} (see --help)")


def check_port(text: str) -> int:
    """``--port``: a decimal number 1-65535 written in ASCII digits, else a :class:`ConfigError`."""
    if not (text.isascii() and text.isdigit() and 0 < int(text) < 65536):
        raise ConfigError(f"--port: '{clip(text, 40)}' is not a port (1-65535)")
    return int(text)


def check_host(text: str) -> bool:
    """``--host``: an IP address of this machine (``localhost`` is 127.0.0.1; 0.0.0.0 or ``::`` for
    every interface), checked by binding a socket to it: no name is looked up, so a mistyped host
    cannot hang on a name server. Returns whether other machines can reach it (not a loopback
    address); anything else is a :class:`ConfigError`."""
    name = "127.0.0.1" if text == "localhost" else text
    try:
        address = ipaddress.ip_address(name)
    except ValueError:
        raise ConfigError(f"--host: '{clip(text, 60)}' is not an IP address (127.0.0.1, the default, serves this "
                          f"machine only; 0.0.0.0 every interface)") from None
    family = socket.AF_INET6 if address.version == 6 else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind((name, 0))
    except OSError as exc:
        raise ConfigError(f"--host: cannot serve on {clip(text, 60)} ({exc.strerror}): not an address of this "
                          f"machine") from None
    return not address.is_loopback


def view_result(argv: Sequence[str] | None = None, *, block: bool = True):
    """Parse ``PATH [--host H] [--port P]``, load the result (refusals: :class:`ProblemError`,
    before any server starts), serve it and print its address; with ``block``, run until Ctrl-C.
    Returns the server (stop it with ``server.stop()``). A host other machines can reach is said
    on stderr in one line (``warning: ...``)."""
    parser = _Parser(prog="view.py", description="A result in the browser (viser).")
    parser.add_argument("path", help="a run folder (with result.json) or a result JSON file")
    parser.add_argument("--host", default="127.0.0.1", help="the address to bind (default: this machine only)")
    parser.add_argument("--port", default="8080", help="the port (default 8080)")
    args = parser.parse_args(argv)
    port = check_port(args.port)
    public = check_host(args.host)

    t0 = time.perf_counter()
    view = load_view(args.path)
    server = serve(view, args.host, port)
    try:  # from here Ctrl-C stops the server: one line, exit 0
        if public:
            say(f"warning: serving on {args.host}: other machines that reach this one can open the page "
                f"(the default, 127.0.0.1, serves this machine only)")
        print(f"viewing {view.path} ({view.robot.name}, {len(view.postures)} trials"
              f"{', a reach motion' if view.motion is not None else ''}) at http://{args.host}:{server.get_port()} "
              f"(ready in {time.perf_counter() - t0:.1f} s; Ctrl-C stops)", flush=True)
        while block:
            time.sleep(1.0)
    except KeyboardInterrupt:
        say("stopped (Ctrl-C)")
        server.stop()
    except BaseException:
        server.stop()
        raise
    return server
