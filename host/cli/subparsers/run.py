"""``odocan run``: the lockstep rig on in-process python-can buses, then the analysis.

The rig's buses are the ``odocan`` transport (``sim.transport``) unless ``--transport virtual``
asks for python-can's own ``virtual`` interface: the same frames, byte for byte, only slower.
``-b/--bitrate`` makes the rig's bus bit-timed (arbitration, exact frame lengths, delivery at the
end of frame, in simulated time); without it the bus is instant.

The firmware is ``--firmware auto`` unless asked: the C port when its library builds and loads
(bit-exact, about twice as fast), else the Python one; the summary's title and the report's
``inputs.firmware`` say which and why (``host.cli.firmware_choice``).

The motor controller, the ground truth, the scenario driver and the firmware run in simulated
time (about 100x faster than real time on one core); every frame goes to a ``FrameCollector``
and, with ``--log``, to python-can's ``can.Logger`` (``.log`` candump, ``.asc``, ``.blf``). The
on-board pose is then compared with the float64 reference and the ground truth
(``host.analysis.analyze``); exit 0 within tolerance, 1 not, 2 on bad usage. Ctrl-C or SIGTERM
stops the rig after the tick under way and checks what ran so far: the summary, the report and
the log (``.asc`` footer, ``.blf`` header and object count) are all finished as after a full run.

With ``-i/--interface`` or ``-c/--channel`` (python-can's bus options) every frame is also sent
to that bus, paced to the wall clock so the copy keeps the DBC's cycle times (e.g.
``-i socketcan -c vcan0`` for ``candump vcan0``, or ``odocan monitor`` on the same bus).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import can
import numpy as np

from odocan.host.cli.firmware_choice import resolve_firmware
from odocan.host.cli.inputs import explained, require_frames
from odocan.host.cli.options import (
    SIM_DURATION_MAX_S,
    SIM_DURATION_MIN_S,
    add_firmware_arguments,
    add_seed_argument,
    check_log_path,
    float_in,
)
from odocan.host.cli.rigrun import rare_collections, run_rig, start_rig, stop_before_analysis
from odocan.host.io.buses import add_bus_arguments, add_fault_argument, open_bus, parse_faults
from odocan.host.io.export import add_export_arguments, check_export_paths, write_exports
from odocan.host.io.listeners import Isolated
from odocan.host.io.logs import FrameCollector
from odocan.host.io.recording import Recording
from odocan.host.judge.analysis import Analysis, analyze
from odocan.host.outputs import OutputError, check_distinct, check_writable, replaced
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.report import provenance
from odocan.host.report.ci import (
    add_junit_argument,
    analysis_checks,
    check_junit_path,
    write_checks,
)
from odocan.host.report.foxglove_options import add_foxglove_arguments, foxglove_session
from odocan.host.report.progress import progress
from odocan.host.report.summary import (
    PLOT_SUFFIXES,
    add_check_arguments,
    check_output_paths,
    finish,
)
from odocan.host.stopped import Stopped
from odocan.sim import errors, robot
from odocan.sim.board import TICK_S
from odocan.sim.cboard import board_maker
from odocan.sim.contract import database, read_as
from odocan.sim.e2efacts import require_firmware_follows
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.faults import FaultSpec
from odocan.sim.faultspec import two_handles
from odocan.sim.mcufaults import check_within
from odocan.sim.realtime import StopRequest, stop_on_signals
from odocan.sim.rig import TRANSPORTS, LockstepRig, RigConfig, firmware_params
from odocan.sim.scenarios import SCENARIOS, get_scenario

TRUTH_TRACE_MAX = 100_000  # poses kept for the plot's truth (17 simulated minutes at 100 Hz)


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan run``."""
    parser = subparsers.add_parser(
        "run",
        help="run the firmware in the lockstep rig and check its odometry",
        description="Run the motor controller, ground truth, scenario driver and firmware in "
        "lockstep on in-process python-can buses, then compare the on-board pose (decoded from the "
        "bus) with the float64 reference and the ground truth. Exit 0 within tolerance, 1 not, "
        "2 on bad usage. Ctrl-C or SIGTERM stops early and checks what ran.",
        epilog="With -b/--bitrate the rig's own bus is bit-timed (e.g. -b 500000: arbitration, "
        "exact frame lengths with stuffing, delivery at the end of frame). With -i/-c every frame "
        "is also sent to that bus, paced to the wall clock (e.g. -i socketcan -c vcan0, then "
        "candump vcan0).",
    )
    parser.add_argument(
        "--scenario", choices=SCENARIOS, default="random", help="driving scenario (default: random)"
    )
    add_firmware_arguments(parser)
    parser.add_argument(
        "--duration",
        type=float_in(SIM_DURATION_MIN_S, SIM_DURATION_MAX_S),
        metavar="SECONDS",
        help=f"SIMULATED seconds, {SIM_DURATION_MIN_S:g} .. {SIM_DURATION_MAX_S:g} (default: "
        "the scenario's own, 61 s for random; random drives until 1 s before the end of a "
        "longer run)",
    )
    add_seed_argument(parser)
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
        "--log",
        type=Path,
        metavar="PATH",
        help="log every frame (.log candump, .asc, .blf) (default: no log)",
    )
    parser.add_argument(
        "--secoc-key",
        type=Path,
        metavar="PATH",
        help="provision the firmware with this SecOC key (16 raw bytes or 32 hex digits; "
        "docs/secoc.md): its commands then need an ODOM_AUTH (default: no SecOC)",
    )
    add_check_arguments(parser)
    parser.add_argument(
        "--latency-plot",
        type=Path,
        metavar="PATH",
        help="with -b: plot each message's measured latency (p99, max) against the analysis' "
        "worst case and its deadline (.png, .svg) (default: none)",
    )
    add_export_arguments(parser)
    add_foxglove_arguments(parser)
    add_junit_argument(parser)
    add_fault_argument(parser)
    add_bus_arguments(parser)
    parser.set_defaults(func=_do_run)


def _do_run(args: argparse.Namespace) -> int:
    faults = parse_faults(args, mcu=True)
    profile = robot.load(args.robot)
    secoc_key = None
    if args.secoc_key is not None:  # cryptography (AES-CMAC) only for a SecOC run
        from odocan.host.protocol.secoc import load_secoc_key

        secoc_key = load_secoc_key(args.secoc_key)
    choice = resolve_firmware(args.firmware, secoc_key is not None,
                              firmware_params(profile, args.integrator))
    config = RigConfig(
        robot=profile,
        integrator=args.integrator,
        scenario=args.scenario,
        seed=args.seed,
        errors=errors.parse(args.errors),
        faults=None if faults is None else two_handles(faults)[0],
        fw_faults=None if faults is None else two_handles(faults)[1],
        duration_s=args.duration,
        transport=args.transport,
        bitrate=args.bitrate,
        firmware=choice.firmware,
        secoc_key=secoc_key,
        # flat out: the drive may run ahead (not when frames are paced onto a live bus)
        lookahead=args.interface is None and args.channel is None,
    )
    check_within(faults, args.duration if args.duration is not None  # the rig's own length
                 else get_scenario(args.scenario, profile, args.seed).default_duration_s)
    with read_as(default_plan()):  # the firmware speaks the DBC the sim and judges read
        require_firmware_follows()
    check_log_path(args.log)
    check_output_paths(args)
    check_latency_plot(args.latency_plot, config.bitrate)
    check_bus_args(args)
    check_export_paths(args.parquet, args.mcap)
    check_junit_path(args)
    check_distinct([("--log", args.log), ("--report", args.report), ("--plot", args.plot),
                    ("--junit", args.junit), ("--mcap", args.mcap),
                    ("--latency-plot", args.latency_plot)])
    board_maker(config.firmware, secoc=config.secoc_key is not None,  # refusals before any file
                params=firmware_params(config.robot, config.integrator))
    title = f"odocan run: {config.scenario} on {config.robot.name}, {config.integrator} integrator"
    if choice.auto or choice.firmware != "python":  # the Python one asked by name: unsaid
        title += f", {choice.words}"
    with foxglove_session(args, config.robot, config.integrator) as live:
        extra: list[can.Listener] = [] if live is None else [Isolated(live)]
        with rare_collections():
            analysis, log_error, stopped = _run_and_analyze(config, args, extra)
        analysis.report["inputs"] = run_inputs(config, args.errors, faults)
        analysis.report["inputs"]["firmware"] = choice.as_dict()
        try:
            code = finish(analysis, args, title=title)
        except OutputError as exc:
            raise _after_log_error(log_error, exc) from None
    try:
        injected = analysis.report["inputs"].get("faults")  # as the summary's "injected" line
        write_checks(args, "run", analysis_checks(analysis.report),
                     {"faults": injected} if injected else None)
        _write_latency_plot(args, analysis.report)
    except OutputError as exc:
        raise _after_log_error(log_error, exc) from None
    if log_error is not None:
        raise log_error
    return code if stopped is None else stopped.exit_code


def check_bus_args(args: argparse.Namespace) -> None:
    """``--bus-arg`` configures the -i/-c bus the frames are mirrored to; without one it did
    nothing, silently (``run --bus-arg port=N`` ran on the in-process bus, port unused)."""
    if args.bus_arg and args.interface is None and args.channel is None:
        raise ConfigurationError(
            f"--bus-arg {args.bus_arg[0]}: only for the -i/-c bus the frames are copied to "
            "(the rig's own bus is in-process; -b makes it bit-timed): give -i/-c"
        )


def check_latency_plot(path: Path | None, bitrate: int | None) -> None:
    """``--latency-plot`` needs a bit-timed bus and a .png/.svg path that can be written."""
    if path is None:
        return
    if bitrate is None:
        raise ConfigurationError("--latency-plot needs a bit-timed bus: give -b/--bitrate")
    if path.suffix.lower() not in PLOT_SUFFIXES:
        raise ConfigurationError(
            f"--latency-plot {path}: unknown format {path.suffix or '(none)'!r} (use .png or .svg)"
        )
    check_writable(path, "--latency-plot")


def _run_and_analyze(
    config: RigConfig, args: argparse.Namespace, extra: list[can.Listener]
) -> tuple[Analysis, OutputError | None, Stopped | None]:
    """Run the rig with its listeners (and ``extra``; the wall time measured around the run
    only) and analyse what the host heard. A log or an export that could not be finished is
    returned, not raised, so that the summary is still printed; so is the stop of a run a
    signal ended early (in the report too: ``stopped``)."""
    collector = FrameCollector()
    listeners: list[can.Listener] = [collector, *extra]
    wants_mirror = args.interface is not None or args.channel is not None
    mirror = open_bus(args, with_faults=False) if wants_mirror else None
    log_error: OutputError | None = None
    recorded: dict[str, Any] | None = None  # a --log a write error stopped (the report's)
    stop = StopRequest()
    try:
        with stop_on_signals(stop):  # from the log's opening to its end: a signal only asks
            args.log_opened = True  # every interruption from here says what became of --log
            rig = start_rig(config, listeners, args.log, stop)
            total_ticks = round(rig.default_duration_s / TICK_S)
            trace = TruthTrace(rig, total_ticks) if args.plot is not None else None
            if mirror is not None:
                rig.listeners.append(PacedRedirect(mirror))
            wire = getattr(rig.host_bus, "timing", None)  # bit-timed: the wire's own records
            if wire is not None:  # -b only: busstats (cantools, the schedulability) costs 0.1 s
                from odocan.host.judge import busstats
            try:
                start = time.perf_counter()
                stopped = run_rig(rig, stop, rig.default_duration_s,
                                  None if trace is None else trace.record)
                wall_s = time.perf_counter() - start
                still_queued = None if wire is None else busstats.pending_by_id(wire)
            finally:
                try:
                    rig.close()
                except OSError as exc:
                    log_error = OutputError(f"--log {args.log}: {exc.strerror or exc}")
                    recorded = failed_recording(listeners, args.log)
    finally:
        if mirror is not None:
            mirror.shutdown()
    if (unanalysed := stop_before_analysis(stopped, stop, args.log, listeners)) is not None:
        raise log_error or unanalysed
    frames = collector.arrays()
    cause = _why_no_frames(config.faults, config.bitrate, still_queued)
    require_frames(frames, "the run", cause)
    with explained(lambda: frames, "the run", cause), progress(f"analysing {len(frames)}", None):
        analysis = analyze(
            frames,
            config.robot,
            config.integrator,
            tolerance=args.tolerance,
            scenario=config.scenario,
            seed=config.seed,
            wall_seconds=wall_s,
        )
    analysis.report.update(_ended_early(stopped, recorded))
    if trace is not None and len(frames):
        analysis.series.update(trace.series(float(frames.timestamp_s[0])))
    if wire is not None:
        bus = busstats.from_wire(wire, database(), still_queued=still_queued)
        analysis.report["bus"] = bus.as_dict()
    try:
        write_exports(args, frames, analysis)
    except OutputError as exc:  # as a log: raised once the summary is out
        log_error = log_error or exc
    return analysis, log_error, stopped


def _ended_early(stopped: Stopped | None, recorded: dict[str, Any] | None) -> dict[str, Any]:
    """The report's ``stopped`` (a signal ended the drive) and ``recording`` (a write error
    ended the log), for those that did."""
    ended: dict[str, Any] = {} if stopped is None else {"stopped": stopped.as_dict()}
    return ended if recorded is None else {**ended, "recording": recorded}


def failed_recording(listeners: list[can.Listener], log: Path) -> dict[str, Any] | None:
    """The report's ``recording`` for a ``--log`` a write error stopped: its path, the frames
    the file holds, the error (the report is then no pass: ``host.report.summary.finish``);
    None when the error that closed the rig was not the recording's."""
    failed = [li for li in listeners if isinstance(li, Recording) and li.failure is not None]
    if not failed:
        return None
    return {"path": str(log), "stopped_after_frames": failed[0].kept_frames,
            "error": failed[0].reason}


def _after_log_error(log_error: OutputError | None, error: OutputError) -> OutputError:
    """``error`` (a report, plot or JUnit file not written), after the recording's own failure
    when it failed first: the one line names both, so a stopped ``--log`` is never unsaid."""
    return error if log_error is None else OutputError(f"{log_error}; {error}")


def _write_latency_plot(args: argparse.Namespace, report: dict[str, Any]) -> None:
    """``--latency-plot`` when asked; an I/O error is one ``OutputError`` naming the path."""
    if args.latency_plot is None:
        return
    from odocan.host.report.plots import plot_latency  # matplotlib only when asked

    with replaced(args.latency_plot, "--latency-plot") as target:  # a full disk: no part left
        plot_latency(report, target)


def _why_no_frames(
    faults: FaultSpec | None,
    bitrate: int | None,
    still_queued: dict[tuple[int, bool], int] | None,
) -> str:
    """Why a message the check needs has no frame: the faults asked for, a bit-timed bus too
    slow for the rig's traffic (frames left in its transmit buffers), else a bug."""
    if faults is not None and faults.active:
        return f"under --faults {faults}"
    queued = sum((still_queued or {}).values())
    if bitrate is not None and queued:
        return (
            f"at {bitrate} bit/s the bus cannot carry the rig's traffic: {queued} frames still "
            f"queued at the end; see odocan busload -b {bitrate}, use a higher -b/--bitrate"
        )
    return "the rig sent none: a bug, please report it"


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


def run_inputs(
    config: RigConfig, errors_text: str, faults: FaultSpec | None
) -> dict[str, object]:
    """The report's ``inputs``: profile (hash), integrator, errors, the ``--faults`` given,
    seeds, version, DBC."""
    seeds = {"rig": config.seed}
    if faults is not None and faults.active:
        seeds["faults"], seeds["firmware_faults"] = faults.seed, faults.seed + 1
    return provenance.inputs(
        config.robot, integrator=config.integrator, errors=errors_text,
        faults=str(faults) if faults is not None and faults.active else "", seeds=seeds,
    )


class TruthTrace:
    """The simulator's true pose after every tick (100 Hz), for a smooth truth in the plot; a
    run longer than ``TRUTH_TRACE_MAX`` ticks is sampled every k-th tick so that at most that
    many poses are kept (the legend then gives the lower rate). Reading the truth does not
    change the run (same frames, same report)."""

    def __init__(self, rig: LockstepRig, total_ticks: int = 0) -> None:
        """Record from ``rig`` (its vehicle's ``truth()``, read-only) over ``total_ticks``."""
        self.rig = rig
        self.every = max(1, -(-total_ticks // TRUTH_TRACE_MAX))
        self.rows: list[tuple[float, float, float]] = []
        self._calls = 0

    def record(self) -> None:
        """Called after each tick: append the true (t s, x m, y m) on every ``every``-th."""
        self._calls += 1
        if self._calls % self.every:
            return
        pose = self.rig.vehicle.truth()
        self.rows.append((pose.t_s, pose.x_m, pose.y_m))

    def series(self, t_first_s: float) -> dict[str, np.ndarray]:
        """``truth_full_{t_s,x_m,y_m}``, times since ``t_first_s`` (the log's first frame)."""
        data = np.array(self.rows, dtype=np.float64).reshape(-1, 3)
        return {"truth_full_t_s": data[:, 0] - t_first_s, "truth_full_x_m": data[:, 1],
                "truth_full_y_m": data[:, 2]}
