"""``--foxglove [PORT]`` and ``--realtime`` of ``odocan run``, without the Foxglove SDK.

The options are registered on every ``odocan run``; the server (``host.report.foxglove``, which
imports ``foxglove-sdk``, the live monitor model and MQTT's fleet view) only when ``--foxglove``
asks for it: a run without it pays nothing for it at start-up.
"""

from __future__ import annotations

import argparse
from contextlib import AbstractContextManager, nullcontext
from typing import TYPE_CHECKING, Any

from odocan.host.io.export import FOXGLOVE_PORT
from odocan.sim.exceptions import BusSetupError

if TYPE_CHECKING:
    from foxglove.websocket import WebSocketServer

    from odocan.host.report.foxglove import FoxgloveLive
    from odocan.sim.robot import RobotProfile

HOST = "127.0.0.1"  # the live server listens on this machine only


def port_number(text: str) -> int:
    """argparse type: a TCP port, 0 (any free port) to 65535."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected a TCP port 0..65535, got {text!r}")
    return port


def add_foxglove_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--foxglove [PORT]`` and ``--realtime`` (``odocan run``)."""
    group = parser.add_argument_group("live Foxglove")
    group.add_argument(
        "--foxglove", nargs="?", type=port_number, const=FOXGLOVE_PORT, metavar="PORT",
        help=f"serve the drive live to Foxglove on {HOST}:PORT (default {FOXGLOVE_PORT}); the "
        "drive starts when a client subscribes, and the server stays until it disconnects",
    )
    group.add_argument(
        "--realtime", action="store_true",
        help="with --foxglove: pace the drive to the wall clock, to watch it as it happens",
    )


def foxglove_session(
    args: argparse.Namespace, robot: RobotProfile, integrator: str | None
) -> AbstractContextManager[FoxgloveLive | None]:
    """``host.report.foxglove.serve_foxglove`` when ``--foxglove`` or ``--realtime`` is given
    (it serves, or refuses ``--realtime`` alone); else a context that yields None and imports
    nothing."""
    if args.foxglove is None and not args.realtime:
        return nullcontext(None)
    from odocan.host.report.foxglove import serve_foxglove

    return serve_foxglove(args, robot, integrator)


class Served:
    """What a live Foxglove server (``self.server``, from ``start_server``) tells a user."""

    server: WebSocketServer

    @property
    def port(self) -> int:
        """The TCP port served."""
        return int(self.server.port)

    @property
    def url(self) -> str:
        """What to type in Foxglove's Open connection."""
        return f"ws://localhost:{self.port}"


def start_server(name: str, port: int, **kwargs: Any) -> WebSocketServer:
    """``foxglove.start_server`` on ``HOST``:``port`` (0: any free one); a port in use or
    refused is a ``BusSetupError`` naming it (the CLI's one line, exit 2)."""
    import foxglove

    try:
        return foxglove.start_server(name=name, host=HOST, port=port, **kwargs)
    except Exception as exc:  # the SDK raises RuntimeError (port in use, ...)
        raise BusSetupError(f"--foxglove {port}: cannot serve on {HOST}:{port}: {exc}") from None
