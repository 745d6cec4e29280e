"""``odocan fleet``: N independent robots in real time, bridged to MQTT.

Each robot is the lockstep rig's set of nodes on its own python-can ``virtual`` channel
(scenario ``random`` with seed ``--seed + i``; ``-n/--count`` robots, ``--robot`` their
profile); one timer loop steps them all every 10 ms and accounts its deadlines; the bridge
publishes every robot under ``odocan/robotNNN/`` (``host.mqtt.topics``). ``--report`` writes the
JSON contract of ``host.mqtt.fleetrun``. Exit 0, or 1 when ``deadline_miss_ratio`` exceeds
``--max-miss-ratio``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from pathlib import Path

from odocan.host.cli.options import SEED_LIMIT, add_seed_argument, float_in, int_in
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.host.mqtt.options import (
    add_mqtt_arguments,
    bridge_options,
    broker_url,
    configure_logging,
)
from odocan.host.report.outputs import check_writable, write_text
from odocan.host.report.progress import wall_clock_progress
from odocan.sim import robot
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.fleet import FleetConfig
from odocan.sim.rig import INTEGRATORS
from odocan.sim.scenarios import SCENARIOS

FLEET_MAX_ROBOTS = 500  # one 2-core machine holds about 45 in real time (README, bench/fleet.py)
FLEET_MAX_DURATION_S = 86400.0


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan fleet``."""
    parser = subparsers.add_parser(
        "fleet",
        help="run N robots in real time, bridged to MQTT",
        description="Run N independent robots (motor controller, truth, scenario, firmware on "
        "their own virtual CAN channels) in real time in one process, bridged to MQTT.",
    )
    _add_arguments(parser)
    parser.set_defaults(func=_do_fleet)


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "-n",
        "--count",
        "--robots",
        dest="count",
        type=int_in(1, FLEET_MAX_ROBOTS),
        default=3,
        metavar="N",
        help=f"how many robots, 1 .. {FLEET_MAX_ROBOTS} (--robots: deprecated alias) "
        "(default: %(default)s)",
    )
    parser.add_argument(
        "--duration",
        type=float_in(0.0, FLEET_MAX_DURATION_S, lo_open=True),
        default=10.0,
        metavar="SECONDS",
        help=f"WALL-CLOCK seconds to run, at most {FLEET_MAX_DURATION_S:g} (default: %(default)s)",
    )
    parser.add_argument(
        "--report", type=Path, metavar="PATH", help="write the JSON report (default: none)"
    )
    parser.add_argument(
        "--robot", default="pmir", help="profile of every robot, name or TOML path (default: pmir)"
    )
    parser.add_argument(
        "--integrator", choices=INTEGRATORS, default="exact", help="on-board integrator"
    )
    parser.add_argument("--scenario", choices=SCENARIOS, default="random", help="driving scenario")
    add_seed_argument(parser, "robot i drives with seed SEED + i")
    parser.add_argument(
        "--max-miss-ratio",
        type=float_in(0.0, 1.0),
        default=0.001,
        metavar="RATIO",
        help="exit 1 above this deadline_miss_ratio, 0 .. 1 (default: %(default)s)",
    )
    add_mqtt_arguments(parser)


def _do_fleet(args: argparse.Namespace) -> int:
    if args.seed + args.count > SEED_LIMIT:
        raise ConfigurationError(
            f"--seed {args.seed} + --count {args.count}: the last robot's seed must be < 2^32"
        )
    check_writable(args.report, "--report")
    run = FleetRun(
        fleet=FleetConfig(
            robots=args.count,
            robot=robot.load(args.robot),
            integrator=args.integrator,
            scenario=args.scenario,
            seed=args.seed,
        ),
        duration_s=args.duration,
        broker=broker_url(args),
        **bridge_options(args),
    )
    configure_logging(getattr(args, "debug", False))
    with wall_clock_progress(f"fleet of {args.count}", args.duration):
        report = asyncio.run(run_fleet(run, on_start=_say_started))
    print(
        f"fleet: {report['robots']} robots, {report['ticks']} ticks, "
        f"deadline_miss_ratio {report['deadline_miss_ratio']:.4f} "
        f"(worst {report['max_lateness_ms']:.1f} ms), broker {report['broker']}"
    )
    sys.stdout.flush()
    if args.report is not None:
        write_text(args.report, json.dumps(report, indent=2) + "\n", "--report")
    return 0 if report["deadline_miss_ratio"] <= args.max_miss_ratio else 1


def _say_started(robots: int, url: BrokerURL | None) -> None:
    """One line on stderr when the clock starts: how many robots, and where to watch them
    (``odocan monitor --broker URL``)."""
    where = f", telemetry on {url}" if url is not None else ""
    print(f"fleet: {robots} robots running{where}; Ctrl-C or SIGTERM stops and reports",
          file=sys.stderr, flush=True)
