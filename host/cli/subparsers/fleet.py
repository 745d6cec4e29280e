"""``odocan fleet``: N independent robots in real time, bridged to MQTT.

Each robot is the lockstep rig's set of nodes on its own python-can ``virtual`` channel (scenario
``random`` with seed ``--seed + i``); one timer loop steps them all every 10 ms and accounts its
deadlines; the bridge publishes every robot under ``odocan/robotNNN/`` (``host.mqtt.topics``).
``--report`` writes the JSON contract of ``host.mqtt.fleetrun``. Exit 0, or 1 when
``deadline_miss_ratio`` exceeds ``--max-miss-ratio``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from pathlib import Path

from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.host.mqtt.options import (
    add_mqtt_arguments,
    bridge_options,
    broker_url,
    configure_logging,
)
from odocan.sim import robot
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.fleet import FleetConfig
from odocan.sim.rig import INTEGRATORS
from odocan.sim.scenarios import SCENARIOS


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
    parser.add_argument("--robots", type=int, default=3, metavar="N", help="robots (default: 3)")
    parser.add_argument(
        "--duration",
        type=float,
        default=10.0,
        metavar="SECONDS",
        help="wall-clock seconds to run (default: 10)",
    )
    parser.add_argument("--report", type=Path, metavar="PATH", help="write the JSON report")
    parser.add_argument("--robot", default="pmir", help="profile of every robot (default: pmir)")
    parser.add_argument("--integrator", choices=INTEGRATORS, default="exact")
    parser.add_argument("--scenario", choices=SCENARIOS, default="random")
    parser.add_argument("--seed", type=int, default=0, help="robot i drives with seed SEED + i")
    parser.add_argument(
        "--max-miss-ratio",
        type=float,
        default=0.001,
        help="exit 1 above this deadline_miss_ratio (default: 0.001)",
    )
    add_mqtt_arguments(parser)


def _do_fleet(args: argparse.Namespace) -> int:
    if args.robots < 1:
        raise ConfigurationError(f"--robots must be at least 1, got {args.robots}")
    if args.duration <= 0:
        raise ConfigurationError(f"--duration must be positive, got {args.duration}")
    run = FleetRun(
        fleet=FleetConfig(
            robots=args.robots,
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
    report = asyncio.run(run_fleet(run))
    text = json.dumps(report, indent=2)
    if args.report is not None:
        args.report.write_text(text + "\n")
    print(
        f"fleet: {report['robots']} robots, {report['ticks']} ticks, "
        f"deadline_miss_ratio {report['deadline_miss_ratio']:.4f} "
        f"(worst {report['max_lateness_ms']:.1f} ms), broker {report['broker']}"
    )
    return 0 if report["deadline_miss_ratio"] <= args.max_miss_ratio else 1


def main(argv: list[str] | None = None) -> int:
    """``odocan fleet`` on its own (until the subcommand is registered in host.cli)."""
    from odocan.host.cli.app import _Parser

    parser = _Parser(prog="odocan fleet")
    _add_arguments(parser)
    return _do_fleet(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
