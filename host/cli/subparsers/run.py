"""``odocan run``: the lockstep rig on in-process python-can buses, then the analysis.

The rig's buses are the ``odocan`` transport (``sim.transport``) unless ``--transport virtual``
asks for python-can's own ``virtual`` interface: the same frames, byte for byte, only slower.
``-b/--bitrate`` makes the rig's bus bit-timed (arbitration, exact frame lengths, delivery at the
end of frame, in simulated time); without it the bus is instant.

The motor controller, the ground truth, the scenario driver and the firmware run in simulated
time (about 100x faster than real time on one core); every frame goes to a ``FrameCollector``
and, with ``--log``, to python-can's ``can.Logger`` (``.log`` candump, ``.asc``, ``.blf``). The
on-board pose is then compared with the float64 reference and the ground truth
(``host.analysis.analyze``); exit 0 within tolerance, 1 not, 2 on bad usage. Ctrl-C stops the
rig early and checks what ran so far.

With ``-i/--interface`` or ``-c/--channel`` (python-can's bus options) every frame is also sent
to that bus, paced to the wall clock so the copy keeps the DBC's cycle times (e.g.
``-i socketcan -c vcan0`` for ``candump vcan0``, or ``odocan monitor`` on the same bus).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import can

from odocan.host.cli.options import add_robot_argument, check_duration, check_log_path
from odocan.host.io.buses import add_bus_arguments, add_fault_argument, open_bus, parse_faults
from odocan.host.io.logs import FrameCollector
from odocan.host.judge.analysis import Analysis, analyze
from odocan.host.report.summary import add_check_arguments, check_output_paths, finish
from odocan.sim import errors, robot
from odocan.sim.board import TICK_S
from odocan.sim.rig import INTEGRATORS, TRANSPORTS, LockstepRig, RigConfig
from odocan.sim.scenarios import SCENARIOS

PROGRESS_MIN_S = 300.0  # simulated seconds from which a progress bar is worth showing


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan run``."""
    parser = subparsers.add_parser(
        "run",
        help="run the firmware in the lockstep rig and check its odometry",
        description="Run the motor controller, ground truth, scenario driver and firmware in "
        "lockstep on in-process python-can buses, then compare the on-board pose (decoded from the "
        "bus) with the float64 reference and the ground truth. Exit 0 within tolerance, 1 not, "
        "2 on bad usage.",
        epilog="With -b/--bitrate the rig's own bus is bit-timed (e.g. -b 500000: arbitration, "
        "exact frame lengths with stuffing, delivery at the end of frame). With -i/-c every frame "
        "is also sent to that bus, paced to the wall clock (e.g. -i socketcan -c vcan0, then "
        "candump vcan0).",
    )
    parser.add_argument(
        "--scenario", choices=SCENARIOS, default="random", help="driving scenario (default: random)"
    )
    add_robot_argument(parser)
    parser.add_argument(
        "--integrator",
        choices=INTEGRATORS,
        default="exact",
        help="on-board integrator (default: exact)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="SECONDS",
        help="simulated seconds (default: the scenario's own, 61 s for random; random drives "
        "until 1 s before the end of a longer run)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    parser.add_argument(
        "--transport",
        choices=TRANSPORTS,
        default="odocan",
        help="python-can interface of the rig's own buses (default: odocan, the lean in-process "
        "transport; virtual: python-can's, same frames)",
    )
    parser.add_argument(
        "--errors",
        default="",
        metavar="ed=..,eb=..,slip=..",
        help="the robot's real errors: E_d, E_b, slip std (default: none)",
    )
    parser.add_argument(
        "--log", type=Path, metavar="PATH", help="log every frame (.log candump, .asc, .blf)"
    )
    add_check_arguments(parser)
    add_fault_argument(parser)
    add_bus_arguments(parser)
    parser.set_defaults(func=_do_run)


def _do_run(args: argparse.Namespace) -> int:
    check_duration(args.duration)
    faults = parse_faults(args)
    config = RigConfig(
        robot=robot.load(args.robot),
        integrator=args.integrator,
        scenario=args.scenario,
        seed=args.seed,
        errors=errors.parse(args.errors),
        faults=faults,
        fw_faults=None if faults is None else replace(faults, seed=faults.seed + 1),
        duration_s=args.duration,
        transport=args.transport,
        bitrate=args.bitrate,
    )
    check_log_path(args.log)
    check_output_paths(args)
    analysis = _run_and_analyze(config, args)
    title = f"odocan run: {config.scenario} on {config.robot.name}, {config.integrator} integrator"
    return finish(analysis, args, title=title)


def _run_and_analyze(config: RigConfig, args: argparse.Namespace) -> Analysis:
    """Run the rig with its listeners; the wall time is measured around the run only."""
    collector = FrameCollector()
    listeners: list[can.Listener] = [collector]
    wants_mirror = args.interface is not None or args.channel is not None
    mirror = open_bus(args, with_faults=False) if wants_mirror else None
    if mirror is not None:
        listeners.append(PacedRedirect(mirror))
    if args.log is not None:
        listeners.append(can.Logger(args.log))
    try:
        rig = LockstepRig(config, listeners=listeners)
        duration_s = rig.default_duration_s
        with rig, _progress(duration_s) as progress:
            start = time.perf_counter()
            try:
                rig.run(duration_s, progress=progress)
            except KeyboardInterrupt:  # Ctrl-C: check what ran so far
                print(f"interrupted after {rig.ticks * TICK_S:g} s simulated", file=sys.stderr)
            wall_s = time.perf_counter() - start
    finally:
        if mirror is not None:
            mirror.shutdown()
    frames = collector.arrays()
    with _status(f"analysing {len(frames)} frames"):
        return analyze(
            frames,
            config.robot,
            config.integrator,
            tolerance=args.tolerance,
            scenario=config.scenario,
            seed=config.seed,
            wall_seconds=wall_s,
        )


class PacedRedirect(can.Listener):
    """Send every frame to another bus, no earlier than its simulated time on the wall clock."""

    def __init__(self, bus: can.BusABC) -> None:
        """``bus``: where the copies go (opened and shut down by the caller)."""
        self.bus = bus
        self._start: float | None = None

    def on_message_received(self, msg: can.Message) -> None:
        """Wait until ``msg.timestamp`` seconds after the first frame, then send a copy."""
        now = time.monotonic()
        if self._start is None:
            self._start = now - msg.timestamp
        delay = self._start + msg.timestamp - now
        if delay > 0:
            time.sleep(delay)
        self.bus.send(msg)


@contextmanager
def _progress(duration_s: float) -> Iterator[Callable[[int, int], None] | None]:
    """A rich progress bar on stderr for long runs, only when stderr is a terminal."""
    if duration_s < PROGRESS_MIN_S or not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TimeRemainingColumn

    with Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        "[progress.percentage]{task.percentage:>3.0f}%",
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        task = bar.add_task(f"simulating {duration_s:g} s", total=round(duration_s / TICK_S))

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


@contextmanager
def _status(text: str) -> Iterator[None]:
    """A rich spinner on stderr while the analysis runs, only when stderr is a terminal."""
    if not sys.stderr.isatty():
        yield
        return
    from rich.console import Console

    with Console(stderr=True).status(text):
        yield
