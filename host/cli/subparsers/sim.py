"""``odocan sim``: the motor controller, the SIM truth and the scenario driver in real time.

One process, one bus handle on any python-can interface (``-i/-c/-b`` or python-can's config
file), paced by the wall clock every 10 ms (``sim.realtime``): receive MOTOR_CMD, drive the
scenario (every 20 ms), sample and send WHEEL_ENCODERS, SIM_TRUTH every 100 ms. Run
``odocan firmware`` on the same bus to close the loop. The motor controller takes MOTOR_CMD
only; on an interface that hands a node its own frames back (``udp_multicast``) the driver's
own commands return once more and its E2E check discards them as REPEATED. Without
``--duration`` it runs until Ctrl-C or SIGTERM; either way it closes the bus, prints a one-line
summary on stderr and exits 0.
"""

from __future__ import annotations

import argparse
import sys
import time

from odocan.host.cli.options import (
    add_duration_argument,
    add_robot_argument,
    add_seed_argument,
    check_duration,
)
from odocan.host.io.buses import add_bus_arguments, add_fault_argument, open_bus
from odocan.host.stopped import early_stop
from odocan.sim import errors, robot
from odocan.sim.motor_controller import SimNode
from odocan.sim.realtime import PeriodicLoop, ReleaseClock, paced_sim_tick, stop_on_signals
from odocan.sim.scenarios import SCENARIOS


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan sim``."""
    parser = subparsers.add_parser(
        "sim",
        help="run the motor controller, ground truth and scenario driver in real time",
        description="The simulated robot as a real-time CAN node: WHEEL_ENCODERS every 10 ms, "
        "SIM_TRUTH every 100 ms, the scenario's MOTOR_CMD every 20 ms, on a python-can bus.",
    )
    parser.add_argument(
        "--scenario", choices=SCENARIOS, default="random", help="driving scenario (default: random)"
    )
    add_robot_argument(parser)
    add_seed_argument(parser)
    parser.add_argument(
        "--errors",
        default="",
        metavar="ed=..,eb=..,slip=..",
        help="the robot's real errors: E_d, E_b, slip std (default: none)",
    )
    add_duration_argument(parser)
    add_bus_arguments(parser)
    add_fault_argument(parser)
    parser.set_defaults(func=_do_sim)


def _do_sim(args: argparse.Namespace) -> int:
    profile = robot.load(args.robot)
    error_model = errors.parse(args.errors)
    check_duration(args.duration)
    bus = open_bus(args)
    try:
        loop = PeriodicLoop()
        release = ReleaseClock()  # the node samples at its tick's release, not when it ran
        node = SimNode.build(
            bus, profile, release, scenario=args.scenario, seed=args.seed, errors=error_model
        )
        started_s = time.monotonic()
        with stop_on_signals(loop):
            stats = loop.run(paced_sim_tick(node, release, loop.period_s), args.duration)
    finally:
        bus.shutdown()
    print(
        f"odocan sim: {node.frames_sent} frames sent ({node.tx_errors} refused), {stats.summary()}",
        file=sys.stderr,
    )
    stopped = early_stop(loop.signum, started_s, args.duration)
    if stopped is None:
        return 0
    print(f"odocan sim: {stopped.text()}", file=sys.stderr)
    return stopped.exit_code
