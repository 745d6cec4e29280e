"""``odocan monitor``: a live terminal view of a CAN bus, or of a fleet over MQTT.

On any python-can bus (``-i/-c/-b``, or python-can's configuration) every frame is fed to
``host.monitor.BusMonitor``: decoded signals per message with units, rate and period jitter, E2E
counts, the firmware's status, and the on-board pose against the float64 reference (and SIM_TRUTH
when present). A ``rich.live.Live`` screen redraws it a few times a second until Ctrl-C (exit 0)
or ``--duration``. With ``--json`` there is no screen: at the end (``--duration`` or Ctrl-C) the
model is printed as one JSON object, for scripts.

``--broker [URL]`` (alias ``--mqtt``, the name it had) shows the fleet instead: one row per
robot that ``odocan bridge``/``odocan fleet`` publish (``host.mqtt.fleetview.fleet_states``),
reconnecting when the broker goes away.
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import aiomqtt
import can
from rich.console import Console
from rich.live import Live

from odocan.host.cli.options import add_duration_argument, add_robot_argument
from odocan.host.cli.subparsers.analyze import load_dbc
from odocan.host.io.buses import add_bus_arguments, open_bus
from odocan.host.judge.monitor import BusMonitor, fleet_snapshot, render, render_fleet, to_json
from odocan.host.mqtt.broker import BrokerError, BrokerURL, connect_failure, tls_diagnosis
from odocan.host.mqtt.fleetview import RobotState, fleet_states
from odocan.host.mqtt.options import add_broker_credentials, monitor_broker_url
from odocan.sim import robot
from odocan.sim.exceptions import ConfigurationError, OdocanError
from odocan.sim.rig import INTEGRATORS

DEFAULT_BROKER = "mqtt://127.0.0.1:1883"
REFRESH_S = 0.25  # screen redraws
RECONNECT_S = 1.0  # wait before reconnecting to the broker
TLS_CHECK_S = 5.0  # the TLS handshake checked before watching an mqtts:// broker


class BrokerUnreachable(OdocanError):
    """The MQTT broker could not be reached during the whole watch."""


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan monitor``."""
    parser = subparsers.add_parser(
        "monitor",
        help="watch a live CAN bus (or an MQTT fleet) in the terminal",
        description="Decode a live CAN bus with the DBC: per message the latest signal values, "
        "rate, period jitter and E2E counts; the firmware's status; the on-board pose against "
        "the float64 reference and the ground truth. Ctrl-C quits (exit 0).",
        epilog="Example: odocan monitor -i socketcan -c vcan0; "
        "odocan monitor -i virtual -c vcan0 --duration 5 --json; "
        "odocan monitor --broker mqtt://127.0.0.1:1883",
    )
    add_duration_argument(parser)
    parser.add_argument(
        "--json",
        action="store_true",
        help="no live view: print one JSON object of the model at the end",
    )
    add_robot_argument(parser, role="profile for the reference")
    parser.add_argument(
        "--integrator",
        choices=INTEGRATORS,
        help="reference integrator (default: the one ODOM_STATUS reports)",
    )
    parser.add_argument(
        "--dbc", type=Path, metavar="PATH", help="DBC to decode with (default: odocan's own)"
    )
    parser.add_argument(
        "--broker",
        "--mqtt",
        dest="mqtt",
        nargs="?",
        const=DEFAULT_BROKER,
        metavar="URL",
        help="show the fleet published on this MQTT broker instead of a CAN bus; without URL "
        f"{DEFAULT_BROKER} (--mqtt: alias) (default: a CAN bus)",
    )
    add_broker_credentials(parser.add_argument_group("MQTT credentials (with --broker)"))
    add_bus_arguments(parser)
    parser.set_defaults(func=_do_monitor)


def _do_monitor(args: argparse.Namespace) -> int:
    if args.mqtt is not None:
        if args.interface is not None or args.channel is not None:
            raise ConfigurationError("--broker watches MQTT: give no -i/--interface or -c")
        return _watch_fleet(monitor_broker_url(args), args)
    if args.ca or args.cert or args.key or args.password_file:
        raise ConfigurationError("--ca/--cert/--key/--password-file go with --broker URL")
    model = BusMonitor(
        robot.load(args.robot),
        args.integrator,
        load_dbc(args.dbc) if args.dbc is not None else None,
    )
    bus = open_bus(args)
    try:
        _watch_bus(bus, model, args, _source(args))
    finally:
        bus.shutdown()
    if args.json:
        print(to_json(model.snapshot()))
    return 0


def _source(args: argparse.Namespace) -> str:
    return ":".join(str(v) for v in (args.interface or "python-can default", args.channel) if v)


def _deadline(duration_s: float | None) -> float:
    return math.inf if duration_s is None else time.monotonic() + duration_s


def _watch_bus(bus: can.BusABC, model: BusMonitor, args: argparse.Namespace, source: str) -> None:
    """Feed the model until the deadline or Ctrl-C, redrawing the screen unless ``--json``."""
    deadline = _deadline(args.duration)
    if args.json:
        _receive(bus, model, deadline, None)
        return
    console = Console(file=sys.stdout)
    with Live(console=console, auto_refresh=False, redirect_stderr=False) as live:

        def redraw() -> None:
            now = time.monotonic()
            heard = {n: now - s.heard_monotonic_s for n, s in model.messages.items()}
            live.update(render(model.snapshot(), source=source, heard=heard), refresh=True)

        _receive(bus, model, deadline, redraw)


def _receive(
    bus: can.BusABC, model: BusMonitor, deadline: float, redraw: Callable[[], None] | None
) -> None:
    """Receive and feed frames; ``redraw`` every ``REFRESH_S``; Ctrl-C ends it quietly."""
    next_draw = 0.0
    try:
        while (now := time.monotonic()) < deadline:
            if redraw is not None and now >= next_draw:
                redraw()
                next_draw = now + REFRESH_S
            msg = bus.recv(timeout=max(0.0, min(REFRESH_S, deadline - now)))
            if msg is not None:
                model.feed(msg)
    except KeyboardInterrupt:
        pass
    if redraw is not None:
        redraw()


# --- the fleet over MQTT ----------------------------------------------------------------------


def _watch_fleet(url: BrokerURL, args: argparse.Namespace) -> int:
    """The fleet table until the deadline or Ctrl-C; ``--json``: one object at the end."""
    watch = _FleetWatch(url, args.duration)
    try:
        if args.json:
            asyncio.run(watch.run(None))
        else:
            with Live(console=Console(file=sys.stdout), auto_refresh=False) as live:
                asyncio.run(watch.run(lambda: live.update(watch.render(), refresh=True)))
    except KeyboardInterrupt:
        pass
    if not watch.connected_once:
        raise BrokerUnreachable(f"cannot reach the MQTT broker {url}: {watch.last_error}")
    if args.json:
        print(to_json(watch.snapshot()))
    return 0


class _FleetWatch:
    """The latest fleet table, kept across reconnections."""

    def __init__(self, url: BrokerURL, duration_s: float | None) -> None:
        self.url, self.duration_s = url, duration_s
        self.table: dict[str, RobotState] = {}
        self.connected_once = False
        self.last_error = ""
        self.started = time.monotonic()

    async def run(self, redraw: Callable[[], None] | None) -> None:
        """Follow the broker until the duration has passed (forever without one); a TLS or
        credentials problem at the first connection is a ``BrokerError`` at once (no retry
        mends it)."""
        if self.url.tls and (found := await tls_diagnosis(self.url, TLS_CHECK_S)) is not None:
            raise BrokerError(f"cannot connect to {self.url}: TLS: {found}")
        try:
            async with asyncio.timeout(self.duration_s):
                await self._follow(redraw)
        except TimeoutError:
            pass

    async def _follow(self, redraw: Callable[[], None] | None) -> None:
        while True:
            if redraw is not None:
                redraw()
            try:
                async for table in fleet_states(broker=self.url, min_interval_s=REFRESH_S):
                    self.connected_once, self.last_error = True, ""
                    self.table = table
                    if redraw is not None:
                        redraw()
            except aiomqtt.MqttError as exc:
                self.last_error = str(exc) or type(exc).__name__
                reason = connect_failure(exc, TLS_CHECK_S, tls=self.url.tls,
                                         client_cert=self.url.cert is not None)
                if not self.connected_once and reason.startswith(("not authorized", "TLS:")):
                    raise BrokerError(f"cannot connect to {self.url}: {reason}") from None
            await asyncio.sleep(RECONNECT_S)

    def snapshot(self) -> dict[str, Any]:
        """``broker``, ``duration_s`` and ``robots`` (``host.monitor.fleet_snapshot``)."""
        return {
            "broker": str(self.url),
            "duration_s": time.monotonic() - self.started,
            "robots": fleet_snapshot(self.table),
        }

    def render(self) -> Any:
        """The screen (with the connection problem, if any)."""
        note = f"broker: {self.last_error} (reconnecting)" if self.last_error else ""
        return render_fleet(
            fleet_snapshot(self.table),
            source=str(self.url),
            elapsed_s=time.monotonic() - self.started,
            note=note,
        )
