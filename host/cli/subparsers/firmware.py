"""``odocan firmware``: the odometry firmware on its board, ticking every 10 ms in real time.

The unchanged firmware (``firmware.ecu.OdomEcu``, or with ``--firmware c`` the C port in
``firmware/c`` through ``sim.cboard``) on a ``sim.board.FirmwareBoard`` whose CAN
controller is a python-can bus (``-i/-c/-b`` or python-can's config file); ``sim.realtime`` plays
its timer. The board's acceptance filter passes only the frames ODOM_MCU receives in the DBC:
interfaces such as ``udp_multicast`` hand a node its own frames back, a CAN controller does
not. Without ``--duration`` it runs until Ctrl-C or SIGTERM; either way it closes the bus,
prints a one-line summary on stderr and exits 0.
"""

from __future__ import annotations

import argparse
import sys

from odocan.host.cli.options import (
    add_duration_argument,
    add_firmware_arguments,
    check_duration,
)
from odocan.host.io.buses import add_bus_arguments, add_fault_argument, open_bus
from odocan.sim import robot
from odocan.sim.cboard import board_maker
from odocan.sim.realtime import PeriodicLoop, accepted_ids, stop_on_signals
from odocan.sim.rig import firmware_params


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan firmware``."""
    parser = subparsers.add_parser(
        "firmware",
        help="run the odometry firmware in real time on a CAN bus",
        description="The odometry ECU as a real-time CAN node: integrates WHEEL_ENCODERS, sends "
        "ODOM_POSE_X/Y and ODOM_TWIST every 20 ms and ODOM_STATUS every 100 ms.",
    )
    add_firmware_arguments(parser)
    add_duration_argument(parser)
    add_bus_arguments(parser)
    add_fault_argument(parser)
    parser.set_defaults(func=_do_firmware)


def _do_firmware(args: argparse.Namespace) -> int:
    params = firmware_params(robot.load(args.robot), args.integrator)
    check_duration(args.duration)
    make_board = board_maker(args.firmware)  # builds the C library before the bus opens
    bus = open_bus(args)
    try:
        loop = PeriodicLoop()
        board = make_board(bus, params, loop.clock, accepted_ids("ODOM_MCU"))
        with stop_on_signals(loop):
            stats = loop.run(lambda _k: board.run_tick(), args.duration)
    finally:
        bus.shutdown()
    ecu = board.ecu
    print(
        f"odocan firmware: {args.firmware} firmware, {board.frames_sent} frames sent "
        f"({board.tx_errors} refused), "
        f"state {ecu.state.name}, {stats.summary()}",
        file=sys.stderr,
    )
    return 0
