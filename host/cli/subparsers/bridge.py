"""``odocan bridge``: one robot's CAN bus <-> MQTT (telemetry out, validated commands in).

The bus (python-can's ``-i/-c/-b`` options) is read in a thread (``host.mqtt.busfeed``: what
this process lost of it is ``status``'s ``receive`` and said when the bridge stops); frames are
E2E-checked, decoded with the DBC, compared with the float64 reference and published under
``odocan/<name>/`` (see ``host.mqtt.topics``); ``odocan/<name>/cmd/*`` commands are validated
against the DBC before a frame is sent. Without ``--broker`` an embedded amqtt broker is
started on a free loopback port. Runs until Ctrl-C or SIGTERM, or ``--duration``: a signal
before that ends it with 130/143, never 0 (it did not bridge for the time it was asked).
At its end, the watch ended (``RobotTelemetry.end_watch``), the robot's verdict is one line on
stderr (``host.mqtt.endverdict``: ``bridge robot001: FAIL: the on-board pose was wrong ...``,
``PASS: ...`` or ``UNJUDGED: ...``; a ``STOPPED by ...`` line, when a signal came before
``--duration``, stays the last) and the exit code is 1 when it FAILs: the pose wrong at any
time of the watch, DISTANCE or the twist speeds wrong, or (``--require-firmware``) nothing
judged; else 0 (130/143 stay when a signal ended it before ``--duration``). The retained
``offline`` status carries the same verdict (``watch_verdict``: judged once, by the bridge).
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import can

from odocan.host.cli.options import add_duration_argument, add_robot_argument
from odocan.host.io.buses import add_bus_arguments, open_bus
from odocan.host.io.busreader import lost_here_text
from odocan.host.judge.reference import Geometry
from odocan.host.judge.robotsource import DEFAULT_ROBOT
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.busfeed import BusFeed
from odocan.host.mqtt.endverdict import EndRule, EndVerdict
from odocan.host.mqtt.options import (
    add_mqtt_arguments,
    bridge_options,
    broker_for,
    broker_url,
    configure_logging,
)
from odocan.host.mqtt.topics import check_robot_name
from odocan.host.protocol.secoc import SecocSigner, load_secoc_key
from odocan.host.stopped import early_stop
from odocan.sim import interrupts, robot
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.rig import INTEGRATORS


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan bridge``."""
    parser = subparsers.add_parser(
        "bridge",
        help="bridge one robot's CAN bus to MQTT",
        description="Publish a robot's telemetry (pose, float64 reference, truth, error, status, "
        "rates) to MQTT and send validated commands from MQTT to its bus. At its end the "
        "robot's verdict is one line on stderr: exit 1 when the on-board pose, DISTANCE or "
        "the twist speeds were wrong at any time, else 0.",
    )
    _add_arguments(parser)
    parser.set_defaults(func=_do_bridge)


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--name", default="robot001", help="robot name in the topics odocan/NAME/..."
    )
    add_robot_argument(parser, role="profile for the reference", live=True)
    parser.add_argument(
        "--integrator",
        choices=INTEGRATORS,
        default="exact",
        help="the firmware's integrator (for the reference; default: exact)",
    )
    add_duration_argument(parser)
    parser.add_argument(
        "--require-firmware",
        action="store_true",
        help="exit 1 when the bridge heard no firmware (no cyclic ODOM_MCU message) or compared "
        "no on-board pose with the reference (or, without --robot, the firmware's PROFILE page is "
        "not the default robot's): a CI run that judged nothing fails (default: off; "
        "UNJUDGED exits 0)",
    )
    parser.add_argument(
        "--secoc-key",
        type=Path,
        metavar="PATH",
        help="sign commands for a firmware provisioned with this SecOC key (16 raw bytes or 32 "
        "hex digits, docs/secoc.md; not the TLS --key): an ODOM_AUTH follows each command frame "
        "(default: commands unsigned)",
    )
    add_mqtt_arguments(parser)
    add_bus_arguments(parser)


def _do_bridge(args: argparse.Namespace) -> int:
    try:
        name = check_robot_name(args.name)
    except ValueError as exc:
        raise ConfigurationError(str(exc)) from None
    url = broker_url(args)
    configure_logging(getattr(args, "debug", False))
    profile = robot.load(args.robot or DEFAULT_ROBOT)
    geometry = Geometry.of(profile)
    signer = None if args.secoc_key is None else SecocSigner(load_secoc_key(args.secoc_key))
    bus = open_bus(args)
    started_s = time.monotonic()
    try:
        signum, verdicts = asyncio.run(_bridge(args, name, url, bus, geometry, profile, signer))
    finally:
        bus.shutdown()
    for robot_name, verdict in verdicts:  # the watch's verdict (issue #11)
        print(f"bridge {robot_name}: {verdict.text}", file=sys.stderr)
    failed = any(v.failed for _, v in verdicts)
    stopped = early_stop(signum, started_s, args.duration)
    if stopped is None:
        return 1 if failed else 0
    print(f"bridge {name}: {stopped.text()}", file=sys.stderr)  # last, as before
    return stopped.exit_code


async def _bridge(
    args: argparse.Namespace,
    name: str,
    url: BrokerURL | None,
    bus: can.BusABC,
    geometry: Geometry,
    profile: robot.RobotProfile,
    signer: SecocSigner | None = None,
) -> tuple[int | None, list[tuple[str, EndVerdict]]]:
    """Bridge until ``--duration`` or Ctrl-C/SIGTERM; the signal that stopped it, if one did,
    and each robot's verdict, its watch ended (``Bridge.run``'s end)."""
    signals: list[int] = []
    stop = asyncio.Event()

    def on_signal(signum: int) -> None:
        signals.append(signum)
        stop.set()

    handlers = ExitStack()  # the loop's from the bridge's start to its broker's end, then the CLI's
    with handlers:
        async with broker_for(url) as (broker, embedded):
            config = BridgeConfig(broker=broker, **bridge_options(args))
            endpoint = RobotEndpoint(name, bus, geometry, args.integrator,
                                     counter_bits=profile.counter_bits, signer=signer,
                                     profile_name=profile.name, from_page=args.robot is None)
            bridge = Bridge([endpoint], config=config,
                            end_rule=EndRule(require_firmware=args.require_firmware))
            loop = asyncio.get_running_loop()
            handlers.enter_context(interrupts.loop_handlers_installed(loop, on_signal))
            reader = BusFeed(bus, bridge, loop)
            reader.start()
            if args.duration is not None:
                _stop_after(args.duration, stop)
            banner = f"bridge {name}: {broker}{' (embedded)' if embedded else ''}"
            announced = asyncio.create_task(_announce_when_connected(bridge, banner))
            try:
                await bridge.run(stop=stop)
            finally:
                announced.cancel()
                reader.stop()
            print(f"bridge {name}: {counters_line(bridge.counters())}", file=sys.stderr)
            if said := bridge.robots[0].telemetry.robot.said(f"bridge {name}"):  # page chose
                print(said, file=sys.stderr)
            if lost := lost_here_text(reader.reader.stats()):
                print(f"bridge {name}: lost here: {lost}", file=sys.stderr)
    # judged once, when the watch ended: the verdicts the retained ``offline`` statuses carry
    return (signals[0] if signals else None), bridge.end_verdicts()


def counters_line(c: dict[str, Any]) -> str:
    """The bridge's counters as one line: what was dropped, refused or expired (said when the
    bridge stops)."""
    return (f"{c['frames_in']} frames in ({c['frames_dropped']} dropped), telemetry "
            f"dropped {c['telemetry_dropped']} (queue full) + {c['telemetry_offline']} "
            f"(broker away), QoS-1 dropped {c['reliable_dropped']}, refused by the broker "
            f"{c['refused']}, commands expired {c['commands_expired']}, commands timed out "
            f"{c['commands_timeout']}, aborted {c['commands_aborted']}, "
            f"{c['reconnects']} reconnects")


def _stop_after(duration_s: float, stop: asyncio.Event) -> None:
    """``--duration``: ``stop`` set ``duration_s`` from now (on the running loop)."""
    asyncio.get_running_loop().call_later(duration_s, stop.set)


async def _announce_when_connected(bridge: Bridge, banner: str) -> None:
    """Print the banner once the broker took the connection (an unreachable broker gets only
    its ``error:`` line)."""
    await bridge.links[0].connected.wait()
    print(banner, file=sys.stderr)
