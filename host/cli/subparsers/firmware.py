"""``odocan firmware``: the odometry firmware on its board, ticking every 10 ms in real time.

The unchanged firmware (``--firmware auto``, the default: the C port in ``firmware/c``
through ``sim.cboard`` when its library builds and loads, else ``firmware.ecu.OdomEcu``; the
summary line says which; ``--firmware python|c`` asks for one) on a
``sim.board.FirmwareBoard`` whose CAN controller is a python-can bus (``-i/-c/-b`` or
python-can's config file); ``sim.realtime`` plays its timer. The board's acceptance filter
passes only the frames ODOM_MCU receives in the DBC: interfaces such as ``udp_multicast`` hand
a node its own frames back, a CAN controller does not. Without ``--duration`` it runs until
Ctrl-C or SIGTERM; either way it closes the bus, prints a one-line summary on stderr and exits 0.

SecOC (docs/secoc.md): ``--secoc-key PATH`` provisions the firmware (Python or C) with the key;
its EPOCH lives in RAM for the process, or with ``--nvm PATH`` in a file (``sim.board.FileNvm``:
atomic writes), so a restarted process is a reboot and keeps refusing the commands of the
previous run. A corrupt NVM file, or one that cannot be written, is one line and exit 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from odocan.host.cli.firmware_choice import resolve_firmware
from odocan.host.cli.options import (
    add_duration_argument,
    add_firmware_arguments,
    add_seed_argument,
    check_duration,
)
from odocan.host.io.buses import add_bus_arguments, add_fault_argument, open_bus
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.stopped import early_stop
from odocan.sim import robot
from odocan.sim.board import FileNvm, NvmCell
from odocan.sim.cboard import board_maker
from odocan.sim.contract import read_as
from odocan.sim.e2efacts import require_firmware_follows
from odocan.sim.exceptions import ConfigurationError
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
    parser.add_argument(
        "--secoc-key",
        type=Path,
        metavar="PATH",
        help="provision the firmware with this SecOC key (16 raw bytes or 32 hex digits, "
        "docs/secoc.md): its commands then need an ODOM_AUTH (default: no SecOC)",
    )
    parser.add_argument(
        "--nvm",
        type=Path,
        metavar="PATH",
        help="the firmware's non-volatile memory (the SecOC EPOCH) in this file, created on "
        "first use; needs --secoc-key (default: in RAM, lost when the process ends)",
    )
    add_duration_argument(parser)
    add_seed_argument(parser, "seed of the --faults streams unless the spec sets seed=")
    add_bus_arguments(parser)
    add_fault_argument(parser)
    parser.set_defaults(func=_do_firmware)


def _secoc_key(path: Path) -> bytes:
    """The key file read by the host's loader (cryptography only for a SecOC firmware)."""
    from odocan.host.protocol.secoc import load_secoc_key

    return load_secoc_key(path)


def _do_firmware(args: argparse.Namespace) -> int:
    params = firmware_params(robot.load(args.robot), args.integrator)
    check_duration(args.duration)
    with read_as(default_plan()):  # the DBC the firmware is asked to speak: its build's?
        require_firmware_follows()
    key = None if args.secoc_key is None else _secoc_key(args.secoc_key)
    nvm = _nvm(args.nvm, key)
    # builds the C library (and checks its ABI takes a key) before the bus opens
    choice = resolve_firmware(args.firmware, key is not None, params)
    make_board = board_maker(choice.firmware, secoc=key is not None, params=params)
    bus = open_bus(args)
    try:
        loop = PeriodicLoop()
        board = make_board(bus, params, loop.clock, accepted_ids("ODOM_MCU"), secoc_key=key,
                           nvm=nvm)
        if isinstance(nvm, FileNvm) and nvm.error is not None:  # the boot's EPOCH write
            raise ConfigurationError(f"--nvm: {nvm.error}")
        board.join_bus()
        started_s = time.monotonic()
        with stop_on_signals(loop):
            stats = loop.run(lambda _k: board.run_tick(), args.duration)
    finally:
        bus.shutdown()
    ecu = board.ecu
    print(
        f"odocan firmware: {choice.words}, {board.frames_sent} frames sent "
        f"({board.tx_errors} refused), "
        f"state {ecu.state.name}, {stats.summary()}",
        file=sys.stderr,
    )
    stopped = early_stop(loop.signum, started_s, args.duration)
    if stopped is None:
        return 0
    print(f"odocan firmware: {stopped.text()}", file=sys.stderr)
    return stopped.exit_code


def _nvm(path: Path | None, key: bytes | None) -> NvmCell | None:
    """The EPOCH cell: ``path``'s file, or None (the board's RAM cell); refused without a key."""
    if path is None:
        return None
    if key is None:
        raise ConfigurationError("--nvm holds the SecOC EPOCH: it needs --secoc-key")
    try:
        return FileNvm(path)
    except ConfigurationError as exc:
        raise ConfigurationError(f"--nvm: {exc}") from None
