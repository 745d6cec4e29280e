"""``odocan replay LOG``: re-run a recorded drive against the current firmware build.

**Lockstep** (the default) is the engine of ``host.judge.replay`` (its docstring says how the log's
frames are fed, tick by tick, and what PASS needs); this module is its command line: the options,
the summary, ``--report``/``--plot``/``--junit``, and the verdict's reasons.

**Real time** (``--realtime -i ... -c ...``): play the log's frames (``--only`` some messages)
onto a live bus with their original timing relative to the first frame, ``--speed`` times
faster (``host.io.player``); error frames are not sent. Ctrl-C stops cleanly (exit 0).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from rich.console import Console

from odocan.host.cli.options import add_robot_argument, check_log_path, float_in
from odocan.host.cli.robotchoice import choose_robot
from odocan.host.cli.subparsers.analyze import log_inputs
from odocan.host.io.buses import add_bus_arguments, open_bus
from odocan.host.io.logs import FrameArrays, read_log, warn_on_stderr
from odocan.host.io.player import play
from odocan.host.jsonutil import write_report
from odocan.host.judge.posestreams import pose_streams
from odocan.host.judge.profilepage import profile_mismatch, running_profile, with_bus_speed
from odocan.host.judge.replay import (
    ReplayInput,
    diagnose,
    logged_integrator,
    replay_and_analyze,
)
from odocan.host.judge.replay_compare import compared, departures, not_comparable, unjudged
from odocan.host.judge.stream_stallfirst import logged_first_wrong
from odocan.host.outputs import check_distinct
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.report.ci import (
    add_junit_argument,
    analysis_checks,
    check_junit_path,
    write_checks,
)
from odocan.host.report.progress import progress
from odocan.host.report.summary import add_check_arguments, check_output_paths, finish
from odocan.host.stopped import EXIT_SIGNAL_BASE, stop_code
from odocan.sim import contract
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.rig import INTEGRATORS

POLL_S = 0.1  # --realtime: a stop request is seen within this while waiting for a frame's time
SPEED_MAX = 1000.0  # --speed: faster than that, the timing is no longer worth keeping
IntArray = npt.NDArray[np.int64]



def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan replay``."""
    parser = subparsers.add_parser(
        "replay",
        help="re-run a recorded drive against the current firmware (or play a log onto a bus)",
        description="Feed a log's WHEEL_ENCODERS frames to the current firmware in lockstep "
        "(one tick per 10 ms encoder period, gaps kept) and check its odometry as odocan run "
        "does; or, with --realtime, play the log onto a live bus with its original timing. "
        "Without --robot, the log is replayed on the shipped robot its PROFILE page names, "
        "when exactly one fits (one line on stderr; the report's inputs.robot.source says "
        "where the robot came from).",
        epilog="Examples: odocan replay drive.log --integrator rk2 --report r.json; "
        "odocan replay drive.log --realtime -i socketcan -c vcan0 --speed 2",
    )
    parser.add_argument("log", type=Path, metavar="LOG", help="CAN log: .log (candump), .asc, .blf")
    add_robot_argument(parser, from_log=True)
    parser.add_argument(
        "--integrator", choices=INTEGRATORS,
        help="on-board integrator (default: the one the log's ODOM_STATUS reports, else exact)",
    )
    parser.add_argument("--log", dest="log_out", type=Path, metavar="OUT",
                        help="write the replayed bus (.log candump, .asc, .blf) (default: none)")
    add_check_arguments(parser)
    live = parser.add_argument_group("real time (--realtime)")
    live.add_argument("--realtime", action="store_true",
                      help="play the log onto the bus given by -i/-c/-b with its timing")
    live.add_argument("--speed", type=float_in(0.0, SPEED_MAX, lo_open=True), default=1.0,
                      metavar="X", help=f"play X times faster than recorded, at most "
                      f"{SPEED_MAX:g} (default: 1)")
    live.add_argument("--only", metavar="NAME[,NAME]",
                      help="play only these DBC messages (e.g. WHEEL_ENCODERS,SIM_TRUTH) "
                      "(default: every frame)")
    add_bus_arguments(parser)
    add_junit_argument(parser)
    parser.set_defaults(func=_do_replay)


def _do_replay(args: argparse.Namespace) -> int:
    _check_options(args)
    if args.realtime:
        return _play_realtime(read_log(args.log), args)
    choice = choose_robot(args.robot, args.log)
    profile = choice.profile
    check_output_paths(args)
    check_junit_path(args)
    check_log_path(args.log_out)
    check_distinct([("--log", args.log_out), ("--report", args.report), ("--plot", args.plot),
                    ("--junit", args.junit)], [("LOG", args.log)])
    frames = read_log(args.log)
    if (line := choice.said("replay", args.log)) is not None:
        print(line, file=sys.stderr)
    feed = ReplayInput.from_log(frames)
    logged = logged_integrator(frames, feed.accepted)
    integrator = args.integrator or logged or "exact"
    running = running_profile(frames)  # ODOM_STATUS PROFILE: what the recording firmware ran
    _warn_integrator(args.log, logged, integrator)
    said = profile_mismatch(running, profile, logged or integrator, choice.given_as)
    if said is not None:
        warn_on_stderr(said)
    analysis = replay_and_analyze(
        frames, feed, with_bus_speed(profile, running), integrator, tolerance=args.tolerance,
        log=args.log, log_out=args.log_out,
    )
    if (line := choice.defaulted("replay", args.log)) is not None:  # judged: say why pmir
        print(line, file=sys.stderr)
    section = analysis.report["replay"]
    _print_versus_log(section)
    analysis.report["inputs"] = choice.recorded(log_inputs(args.log, profile, integrator, None))
    reasons, blind = _judged(section, args.tolerance)
    reasons += [why] if (why := logged_first_wrong(  # never compared otherwise: stallfirst
        frames, profile, integrator, (args.tolerance.position_m, args.tolerance.heading_rad))
    ) else []
    if (told := pose_streams(frames, default_plan()).told()) is not None:  # whose poses?
        blind = f"{blind}; {told[2]}" if blind else f"UNJUDGED: {told[2]}"
        reasons = []  # two robots' frames were fed (all the log's encoder frames): no FAIL
    if reasons:  # the firmware's own word on its profile first, then the poses' fit
        reasons += ([] if said is None else [said]) + diagnose(
            frames, feed.accepted, with_bus_speed(profile, running), integrator, args.tolerance,
            source=str(args.log), robot_arg=args.robot, given_as=choice.given_as)
    section.update(passed=not reasons and blind is None, faults=reasons,
                   unjudged=blind)
    title = f"odocan replay: {args.log} on {profile.name}, {integrator} integrator"
    analysis.passed = analysis.passed and _integrator_kept(analysis.report, logged)
    ran_passed = analysis.passed
    code = finish(analysis, args, title=title)  # prints the run's verdict (vs the reference)
    verdict = ([f"{'FAIL' if ran_passed else 'and'}: the replayed firmware departs from the log's",
                *(f"  - {reason}" for reason in reasons)] if reasons
               else [] if blind is None else [blind])
    if verdict:  # a departure, or nothing compared (UNJUDGED): never a PASS
        analysis.report["passed"] = analysis.passed = False
        if args.report is not None:
            write_report(args.report, analysis.report)
        print("\n".join(verdict))
        code = 1
    write_checks(args, "replay", analysis_checks(analysis.report), choice.properties())
    stopped = analysis.report.get("stopped")
    return code if stopped is None else stop_code(stopped)


def _warn_integrator(log: Path, logged: str | None, integrator: str) -> None:
    """The warning up front when ``integrator`` is not the ``logged`` one (the verdict FAILs
    it too: ``_integrator_kept``)."""
    if logged is not None and logged != integrator:  # a replay of another firmware: say so
        warn_on_stderr(f"integrator mismatch: {log}'s ODOM_STATUS reports {logged}, "
                       f"--integrator asks {integrator}: this replays a firmware other than "
                       "the one that recorded it")


def _integrator_kept(report: dict[str, Any], logged: str | None) -> bool:
    """False, ``report`` FAILed (``diagnosis.mark_integrator``, as a wrong ``--robot``), when
    ``--integrator`` is not the one the log's ODOM_STATUS reports: a replay of another
    firmware says nothing of the one recorded, even when its poses stay within tolerance."""
    from odocan.host.judge.diagnosis import mark_integrator  # (the pose fit: when needed)

    return mark_integrator(report, logged) is None


def _judged(section: dict[str, Any], tolerance: Any) -> tuple[list[str], str | None]:
    """The departures that FAIL the replay and why it is UNJUDGED (None: it is not): of the
    whole log, or life by life where the replay lived the log's power-ups, reboots and stalls
    (``host.judge.replay_lives``: a life that departs only after a stall is UNJUDGED there)."""
    lives = section.get("lives")
    if lives is None:
        return departures(section["onboard_vs_log"], tolerance), unjudged(section["onboard_vs_log"])
    reasons, blind = [], []
    for life in lives:
        if life["unjudged"] is not None:
            blind.append(life["unjudged"])
            continue
        reasons += [f"life {life['life']} (from t={life['t_s']:.2f} s): {r}"
                    for r in departures(life["onboard_vs_log"], tolerance)]
        if (none := unjudged(life["onboard_vs_log"])) is not None:
            blind.append(f"life {life['life']} (from t={life['t_s']:.2f} s): {none}")
    return reasons, ("UNJUDGED: " + "; ".join(blind) if blind else None)


def _check_options(args: argparse.Namespace) -> None:
    """Refuse options of the other mode, and a bad ``--speed``."""
    if args.realtime:
        given = [o for o, v in (("--report", args.report), ("--plot", args.plot),
                                ("--log", args.log_out), ("--junit", args.junit))
                 if v is not None]
        if given:
            raise ConfigurationError(f"{', '.join(given)}: not with --realtime (a player only)")
        if not (math.isfinite(args.speed) and args.speed > 0):
            raise ConfigurationError(f"--speed must be a positive factor, got {args.speed}")
        return
    given = [o for o, v in (("-i/--interface", args.interface), ("-c/--channel", args.channel),
                            ("--only", args.only)) if v is not None]
    if args.speed != 1.0:
        given.append("--speed")
    if given:
        raise ConfigurationError(f"{', '.join(given)}: only with --realtime")


def _print_versus_log(section: dict[str, Any]) -> None:
    """How the replayed firmware's poses compare with the log's: one line, then one for a log
    that starts mid-drive and one for each hole of the log (what is not comparable there)."""
    vs = section["onboard_vs_log"]
    console = Console(file=sys.stdout, highlight=False)
    if not vs["samples"]:
        console.print("replay: the log has no on-board pose to compare with" if not vs["logged"]
                      else f"replay: none of the log's {vs['logged']} on-board poses could be "
                      "paired with the replayed firmware's: nothing compared",
                      soft_wrap=True)
        return
    console.print(
        f"replay: {section['encoder_frames_fed']} encoder frames fed in {section['ticks']} "
        f"ticks; on-board vs the log's at {vs['samples']} encoder frames: {compared(vs)}",
        soft_wrap=True)
    for line in not_comparable(vs):
        console.print(f"replay: {line}", soft_wrap=True)
    for life in section.get("lives") or []:
        own = life["onboard_vs_log"]
        said = compared(own) if own["samples"] else "nothing compared"
        console.print(f"replay: life {life['life']} from t={life['t_s']:.2f} s"
                      f"{' (a fresh firmware)' if life['from_power_up'] else ''}, "
                      f"{len(life['stalls'])} stalls replayed as halts: {said}", soft_wrap=True)
    if not section["truth_compared"]:
        console.print("replay: the truth is not compared: the replayed firmware starts from "
                      "(0, 0, 0) mid-drive, the log's SIM_TRUTH from where the drive was",
                      soft_wrap=True)


# --- real time ---------------------------------------------------------------------------------


def _play_realtime(frames: FrameArrays, args: argparse.Namespace) -> int:
    """Play the selected frames onto the bus with their timing; Ctrl-C stops cleanly."""
    selection = _selection(frames, args.only)
    bus = open_bus(args)
    start = time.monotonic()
    try:
        with progress(f"playing {len(selection)} frames", len(selection)) as bar:
            sent, stopped_by = play(bus, frames, selection, args.speed, bar.update)
    finally:
        bus.shutdown()
    wall_s = time.monotonic() - start
    print(f"replay: {'interrupted, ' if stopped_by else ''}{sent} of {len(selection)} frames "
          f"played in {wall_s:.2f} s ({args.speed:g}x the recorded timing)")
    return 0 if stopped_by is None else EXIT_SIGNAL_BASE + stopped_by


def _selection(frames: FrameArrays, only: str | None) -> IntArray:
    """Positions of the frames to play: all, or those of the ``--only`` messages."""
    if only is None:
        return np.arange(len(frames), dtype=np.int64)
    decoder = BulkDecoder(contract.database())
    picked = []
    for name in (n.strip() for n in only.split(",") if n.strip()):
        try:
            picked.append(decoder.select(frames, name))
        except DecodeError as exc:
            raise ConfigurationError(f"--only: {exc}") from None
    return np.sort(np.concatenate(picked)).astype(np.int64) if picked else np.zeros(0, np.int64)
