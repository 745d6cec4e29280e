"""``odocan analyze LOG``: the same check as ``odocan run``, offline, on a log file.

The log (``.log`` candump, ``.asc``, ``.blf``, as ``odocan run --log`` or any python-can or
can-utils tool writes them) is read with ``host.logio.read_log``, decoded with the DBC and the
on-board pose compared with the float64 reference computed from the logged encoder counts, and
with the ground truth when ``SIM_TRUTH`` frames are present. The integrator defaults to the one
the firmware reports in ``ODOM_STATUS``; the robot, without ``--robot``, is the shipped one whose
parameters the log's PROFILE page gives, when exactly one does (said on stderr in one line,
recorded in the report: ``host.cli.robotchoice``), else pmir; a page that is not pmir's is
refused (exit 2: give --robot), never judged as pmir.
Same ``--report``, ``--plot``, ``--tolerance``, summary and exit codes as ``odocan run``.

A ``--dbc`` that does not match the log (a message the analysis needs is missing, or none of its
frames is in the log under the DBC's ID, or none passes its E2E check with the DBC's data IDs)
is a one-line error. Frames the DBC does not know are counted (``unknown_frames`` in the report,
a row of the summary) but are no error: a real bus carries other traffic too.

odocan's DBC is read through a plan of it (``host.protocol.dbcplan``) that cantools derives on
the first run and that is cached, keyed by the DBC's content, in ``$ODOCAN_CACHE_DIR`` (default
``~/.cache/odocan``): later runs import neither cantools nor python-can. ``--dbc`` is read by
cantools every time.

``-b/--bitrate`` adds the measured bus load (``host.judge.busstats.from_frames``: each frame's
exact stuffed length plus the interframe space, over the log's span); a log cannot say when a
frame was queued, so there is no latency to measure.

Memory: a log whose whole judge would pass its 300 MB max-RSS budget by its size
(``stream_choice.auto_budget``: an hour of any shipped robot; ``--stream always`` or ``never``
forces either) and without ``--plot``, ``--parquet``, ``--mcap`` or ``-b`` is
analysed as a stream (``host.judge.stream_analysis``: passes over the file ``--chunk-frames``
frames at a time, the report bit for bit the whole log's, at about 3x the CPU), in bounded
memory whatever its size; those four read the whole log (their series and frames), and so does
a log the analysis refuses (to explain why in the log's terms) or fails (to look for a wrong
``--robot``), or that the stream cannot judge exactly (``stream_analysis.NotStreamable``: frame
times going back around a stall, frames let out in a burst after a busy bus, a stall before
a life's first pose, an APPLY that cut the first pose after a stall off the life before it; an
applied config's PROFILE pages are read from the stream's spill: ``configs.ConfigPages``).
``odocan analyze LOG…`` chooses the same way for each log (``host.cli.batch.analyze_one``).
Under ``--stream always`` such a refusal is said on stderr, one line per log naming its reason
(``refused_line``: the bounded memory asked for is not kept; stdout, ``--report -`` included,
is untouched); under ``auto`` the streamed path is the CLI's choice and falls back quietly.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from odocan.host.cli.options import add_judge_arguments, add_robot_argument, float_in, int_in
from odocan.host.io.export import add_export_arguments, check_export_paths, write_exports
from odocan.host.judge.schedulability import BITRATES
from odocan.host.report.ci import add_junit_argument, check_junit_path
from odocan.host.report.summary import add_check_arguments, check_output_paths
from odocan.sim.exceptions import ConfigurationError

if TYPE_CHECKING:  # imported where used: a command pays only for what it runs
    import cantools

    from odocan.host.cli.batch import LogResult
    from odocan.host.io.logs import FrameArrays
    from odocan.host.judge.analysis import Analysis
    from odocan.host.judge.configs import ConfigPages
    from odocan.host.judge.diagnosis import Judged
    from odocan.sim import robot

MAX_JOBS = 1024


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan analyze``."""
    from odocan.host.judge.stream_choice import auto_budget  # pathlib only

    parser = subparsers.add_parser(
        "analyze",
        help="check the odometry recorded in CAN logs",
        description="Decode a CAN log with the DBC and compare the on-board pose with the "
        "float64 reference (and the ground truth when SIM_TRUTH frames are logged). Several "
        "logs or directories (searched for .log, .asc, .blf) are analysed in parallel, one "
        "summary row and one JSON report (--report-dir) per log. Without --robot, each log "
        "is judged as the shipped robot its PROFILE page names, when exactly one fits (one "
        "line on stderr; the report's inputs.robot.source says where the robot came from). "
        "Exit 0 within tolerance, 1 not (any log), 2 on bad usage or input (any log "
        "unreadable).",
    )
    parser.add_argument(
        "log", type=Path, nargs="+", metavar="LOG",
        help="CAN log: .log (candump), .asc, .blf; or a directory of them (recursively)",
    )
    add_robot_argument(parser, from_log=True)
    add_judge_arguments(parser)
    parser.add_argument(
        "-b",
        "--bitrate",
        type=can_bitrate,
        metavar="BIT/S",
        help="the bus's bitrate: report the measured bus load (exact frame lengths over the "
        "log's span) (default: no bus section)",
    )
    add_check_arguments(parser)
    add_export_arguments(parser)
    add_junit_argument(parser)
    _add_batch_arguments(parser)
    parser.add_argument(
        "--chunk-frames", type=int_in(1, 1 << 30), default=None, metavar="N",
        help="frames per chunk of the streamed analysis, a developer knob: the report is the "
        "same at any size (default: 262144; --plot, --parquet, --mcap and -b read the whole "
        "log)",
    )
    parser.add_argument(
        "--stream", choices=("auto", "always", "never"), default="auto",
        help="analyse the log as a stream in bounded memory (about 180 MB on an hour, 4-5x "
        "the CPU) or read it whole: auto streams a log whose whole judge would take more "
        f"than {auto_budget()}; the report is the same either way. A log the stream cannot judge "
        "exactly (frame times going back, a burst after a busy bus, a stall before a first "
        "pose, an APPLY just after a re-primed stall, a pose naming a frame not heard before "
        "it, a lone pose half) is read whole: quietly under auto, with "
        "one line on stderr under always (default: %(default)s)",
    )
    parser.set_defaults(func=_do_analyze)


def _add_batch_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("many logs")
    group.add_argument(
        "--jobs", type=int_in(1, MAX_JOBS), default=os.cpu_count() or 1, metavar="N",
        help="worker processes for several logs (default: the cores, %(default)s here)",
    )
    group.add_argument(
        "--report-dir", type=Path, metavar="DIR",
        help="write one JSON report per log here (LOG's path below the logs' common folder, "
        "/ as __, .json appended)",
    )
    group.add_argument(
        "--dask", metavar="ADDRESS",
        help="run the analyses on this Dask distributed scheduler (tcp://HOST:PORT) instead "
        "of local processes; its workers must import odocan and see the logs' paths",
    )
    group.add_argument(
        "--dask-timeout", type=float_in(0.0, 3600.0, lo_open=True), default=10.0, metavar="SECONDS",
        help="give up on an unreachable --dask scheduler after this long",
    )


def _do_analyze(args: argparse.Namespace) -> int:
    logs: list[Path] = args.log
    if len(logs) == 1 and not logs[0].is_dir() and args.report_dir is None and args.dask is None:
        args.log = logs[0]
        return _analyze_single(args)
    return _analyze_many(args)


def _analyze_single(args: argparse.Namespace) -> int:
    """One log: the full summary, ``--report``, ``--plot``, exports and ``--junit``."""
    from odocan.host.cli.inputs import explained, require_frames
    from odocan.host.cli.robotchoice import choose_robot, say
    from odocan.host.io.logs import read_log
    from odocan.host.judge.analysis import analyze
    from odocan.host.judge.configs import ConfigPages, running_before_configs
    from odocan.host.judge.diagnosis import judged_before
    from odocan.host.judge.profilepage import head_profile, profile_mismatch, with_bus_speed
    from odocan.host.outputs import check_distinct
    from odocan.host.report.ci import analysis_checks, write_checks
    from odocan.host.report.progress import wall_clock_progress
    from odocan.host.report.summary import finish

    choice = choose_robot(args.robot, args.log, from_log=args.dbc is None)
    profile = choice.profile
    check_output_paths(args)
    check_export_paths(args.parquet, args.mcap)
    check_junit_path(args)
    check_distinct([("--report", args.report), ("--plot", args.plot), ("--junit", args.junit),
                    ("--mcap", args.mcap)], [("LOG", args.log), ("--dbc", args.dbc)])
    db = load_judges_dbc(args.dbc) if args.dbc is not None else None
    say(choice.said("analyze", args.log))
    with wall_clock_progress(f"analysing {args.log}", None):
        streams = _streams(args)
        running = head_profile(args.log) if streams and db is None else None
        pages = ConfigPages(profile)  # an applied config's pages, read as the log streams
        analysis = (_streamed(args, with_bus_speed(profile, running), db, pages) if streams
                    else None)
        running = pages.running(running)  # the page before a first config (the whole: below)
        frames: FrameArrays | None = None
        judged: Judged | None = None  # the whole log's verdict, for the pose fit (diagnosis)
        if analysis is None:
            frames = whole = read_log(args.log)
            if db is not None:  # another DBC: its own checks say whether it matches the log
                analysis = analyze(whole, profile, args.integrator, tolerance=args.tolerance,
                                   db=db)
            else:  # odocan's DBC: say plainly when the log holds none of its frames
                require_frames(whole, str(args.log))
                running = running_before_configs(whole, profile.counter_bits)  # its own bound
                judged_as = with_bus_speed(profile, running)
                with explained(lambda: whole, str(args.log)):
                    analysis = analyze(whole, judged_as, args.integrator,
                                       tolerance=args.tolerance)
                if not analysis.passed:  # the pose fit need not judge judged_as again
                    judged = judged_before(whole, judged_as, args.integrator, args.tolerance,
                                           analysis)
    assert analysis is not None
    say(choice.defaulted("analyze", args.log))  # judged: why the default, if it was taken
    whole_log = frames  # --parquet/--mcap read the whole log: written after the summary
    if args.bitrate is not None:
        from odocan.host.judge import busstats

        assert frames is not None  # -b reads the whole log
        analysis.report["bus"] = busstats.from_frames(frames, args.bitrate).as_dict()
    analysis.report["inputs"] = choice.recorded(
        log_inputs(args.log, profile, analysis.report["integrator"], args.dbc))
    wrong = _wrong_integrator(analysis, frames, args.log, own_dbc=db is None)
    said = profile_mismatch(running, profile, analysis.report["integrator"], choice.given_as)
    hints: list[str] = [] if said is None else [said]  # the firmware's PROFILE page names it
    if db is None:  # the pages after an applied config: its robot's
        hints += _later(frames, pages, profile, analysis.report)
    if not analysis.passed and db is None:  # a wrong --robot must not read as a firmware fault
        from odocan.host.judge.diagnosis import mismatches

        frames = frames if frames is not None else read_log(args.log)  # a failed verdict only
        report = analysis.report
        hints += mismatches(frames, with_bus_speed(profile, running), report["integrator"],
                            report["integrator_source"], args.tolerance, choice.given_as,
                            judged)
    if hints:
        analysis.report["diagnosis"] = hints
    code = finish(analysis, args, title=f"odocan analyze: {args.log}")
    for hint in [hint for hint in hints if hint != wrong]:  # (the verdict said that one)
        print(f"  - {hint}")
    write_checks(args, "analyze", analysis_checks(analysis.report), choice.properties())
    if whole_log is not None:
        write_exports(args, whole_log, analysis, db)
    return code


def _wrong_integrator(analysis: Analysis, frames: FrameArrays | None, log: Path, *,
                      own_dbc: bool) -> str | None:
    """An ``--integrator`` other than the one the log's ODOM_STATUS reports: the analysis
    FAILed (``diagnosis.mark_integrator``, as a wrong ``--robot``) and its line. A streamed
    analysis reads it from the log's head (``head_read``): the whole log stays unread."""
    if not own_dbc or analysis.report["integrator_source"] != "argument":
        return None
    from odocan.host.judge.diagnosis import logged_integrator, mark_integrator
    from odocan.host.judge.profilepage import head_read

    logged = logged_integrator(frames) if frames is not None else head_read(
        log, logged_integrator)
    wrong = mark_integrator(analysis.report, logged)
    analysis.passed = analysis.passed and wrong is None
    return wrong


def _later(frames: FrameArrays | None, pages: ConfigPages, profile: robot.RobotProfile,
           report: dict[str, Any]) -> list[str]:
    """The pages after each applied config against its robot (``configs.later_mismatches``):
    the whole log's, which also adds its two senders' events (#11), or the stream's."""
    from odocan.host.judge.configs import later_mismatches
    from odocan.host.judge.twosenders import log_events
    from odocan.host.protocol.dbcplan import default_plan

    if frames is None:  # streamed: the same pages, read from its spill
        return pages.mismatches(report["integrator"])
    report["events"] += log_events(frames, default_plan())
    return later_mismatches(frames, profile, report["integrator"])


def _streams(args: argparse.Namespace) -> bool:
    """Whether the analysis streams (the module docstring): nothing asks for the whole log,
    and ``--stream`` (auto: the log's size) says so."""
    from odocan.host.judge.stream_choice import streams  # not the streamed judge itself

    return (args.plot is None and args.parquet is None and args.mcap is None
            and args.bitrate is None and streams(args.log, args.stream))


def _streamed(
    args: argparse.Namespace, profile: robot.RobotProfile,
    db: cantools.database.can.Database | None, pages: ConfigPages,
) -> Analysis | None:
    """The streamed analysis of ``args.log``; None when it refuses the log (the whole log's
    path then says why, in the log's terms) or cannot judge it exactly (``NotStreamable``:
    said on stderr under ``--stream always``, ``refused_line``); ``pages``: an applied
    config's PROFILE pages read as it streams (odocan's DBC)."""
    from odocan.host.io.logs import CHUNK_FRAMES, warn_on_stderr
    from odocan.host.judge.analysis import Analysis
    from odocan.host.judge.samples import AnalysisError
    from odocan.host.judge.stream_analysis import NotStreamable, analyze_file

    warnings: list[str] = []  # said once the stream is taken (else the whole log's read says)
    try:
        report = analyze_file(args.log, profile, args.integrator, tolerance=args.tolerance,
                              db=db, chunk_frames=args.chunk_frames or CHUNK_FRAMES,
                              warn=warnings.append, whole_on_config=db is None,
                              config_pages=pages if db is None else None, whole_on_ahead=False)
    except AnalysisError:
        return None
    except NotStreamable as refusal:
        if args.stream == "always":  # bounded memory was asked for: say it is not kept
            print(refused_line(args.log, str(refusal)), file=sys.stderr)
        return None
    for message in warnings:
        warn_on_stderr(message)
    return Analysis(report=report, passed=report["passed"])


def refused_line(log: Path | str, reason: str) -> str:
    """The one stderr line for a log ``--stream always`` could not stream: a user who asked
    for bounded memory learns it was not kept, and why; the verdict is the whole log's, the
    same report, and the most memory the process then takes (``refused_rss_mb``: the stream's
    attempt, then the whole log's judge; not the stream's bound: up to about 5 MB per MB of
    candump log plus 65 MB). Under ``auto`` (the CLI's choice, not the user's) a refusal is
    quiet."""
    from odocan.host.judge.stream_choice import RSS_TARGET_MB, refused_rss_mb

    rss_mb = refused_rss_mb(log)
    memory = "" if rss_mb is None else (f", in up to about {rss_mb:.0f} MB of memory (the stream "
                                        f"aims under {RSS_TARGET_MB:.0f} MB)")
    return f"odocan analyze: {log}: not streamable ({reason}): judged whole{memory}"


def can_bitrate(text: str) -> int:
    """``--bitrate``: one of the standard CAN bitrates, in bit/s."""
    value = int(text) if text.strip().isdigit() else -1
    if value not in BITRATES:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a CAN bitrate (use one of {', '.join(map(str, BITRATES))})"
        )
    return value


def _analyze_many(args: argparse.Namespace) -> int:
    """Several logs (or a directory): one summary row and one JSON report per log, in parallel.

    Exit 2 when any log is unreadable or names nothing (the others are analysed all the same),
    else 1 when any log fails its check, else 0; the logs at fault are named on stderr."""
    from odocan.host.cli import batch
    from odocan.sim import robot

    single_only = [
        option for option, value in (
            ("--report", args.report), ("--plot", args.plot), ("--parquet", args.parquet),
            ("--mcap", args.mcap), ("--junit", args.junit),
        ) if value is not None
    ]
    if single_only:
        raise ConfigurationError(
            f"{', '.join(single_only)} {'takes' if len(single_only) == 1 else 'take'} a single "
            "LOG; for several logs use --report-dir DIR"
        )
    if args.robot is not None:
        robot.load(args.robot)  # a bad profile is a usage error before any work
    if args.dbc is not None:
        load_judges_dbc(args.dbc)
    if args.report_dir is not None:
        check_report_dir(args.report_dir)
    logs, problems = batch.find_logs(args.log)
    if not logs:
        raise ConfigurationError("; ".join(problems) or "no log given")
    job = batch.Job(
        robot=args.robot, integrator=args.integrator,
        tolerance_position_m=args.tolerance.position_m,
        tolerance_heading_rad=args.tolerance.heading_rad,
        dbc=None if args.dbc is None else str(args.dbc.resolve()),
        stream=args.stream,
    )
    if args.dask is not None:
        results = batch.analyze_logs_dask(
            logs, job, address=args.dask, timeout_s=args.dask_timeout
        )
    else:
        results = batch.analyze_logs(logs, job, jobs=args.jobs)
    if args.report_dir is not None:
        write_reports(results, args.report_dir)
    _say_choices(results)
    from odocan.host.cli.batchout import batch_exit, print_batch_summary

    print_batch_summary(results)
    return batch_exit(results, problems)


def _say_choices(results: list[LogResult]) -> None:
    """On stderr, per log: the robot its PROFILE page chose (``host.cli.robotchoice``), and
    under ``--stream always`` why it was read whole after all."""
    from odocan.host.cli.robotchoice import said_of_report

    for result in results:
        if (line := said_of_report("analyze", result.path, result.report)) is not None:
            print(line, file=sys.stderr)
        if result.refused is not None:
            print(refused_line(result.path, result.refused), file=sys.stderr)


def check_report_dir(directory: Path) -> None:
    """Make ``--report-dir`` (and its parents) when missing and prove a file can be written in
    it, before any log is read; else one-line ``ConfigurationError``."""
    import tempfile

    where = f"--report-dir {directory}"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=directory):
            pass
    except FileExistsError:
        raise ConfigurationError(f"{where}: exists and is not a directory") from None
    except OSError as exc:
        raise ConfigurationError(f"{where}: {exc.strerror or exc}") from None


def write_reports(results: list[LogResult], directory: Path) -> None:
    """One JSON report per analysed log in ``directory`` (names from ``batch.report_names``)."""
    from odocan.host.cli.batch import report_names
    from odocan.host.jsonutil import write_report
    from odocan.host.outputs import OutputError

    names = report_names([Path(r.path) for r in results])
    for result in results:
        if result.report is None:
            continue
        path = directory / names[Path(result.path)]
        try:
            write_report(path, result.report)
        except OSError as exc:
            raise OutputError(f"--report-dir {path}: {exc.strerror or exc}") from None


def log_inputs(
    log: Path, profile: robot.RobotProfile, integrator: str, dbc: Path | None
) -> dict[str, object]:
    """The report's ``inputs`` for a log: the log itself (path, SHA-256) instead of seeds; the
    errors and faults the robot had are unknown (None), not "none"."""
    from odocan.host.report import provenance
    from odocan.sim.contract import DBC_PATH

    section = provenance.inputs(profile, integrator=integrator, dbc_path=dbc or DBC_PATH)
    section.update(errors=None, faults=None,
                   log={"path": str(log), "sha256": provenance.file_sha256(log)})
    return section


def load_judges_dbc(path: Path) -> cantools.database.can.Database:
    """``load_dbc``, refused (one line) when the judges of this process hold another DBC's bus
    facts (``host.cli.dbcfirst``)."""
    from odocan.host.cli.dbcfirst import require_judges_follow
    from odocan.host.protocol.dbcfacts import DbcFactError, missing_signals
    from odocan.sim import SHIPPED_DBC
    from odocan.sim.contract import database

    db = load_dbc(path)
    require_judges_follow(db, path)  # a fact the judges read, named first
    lacking = missing_signals(db, database(SHIPPED_DBC))
    if lacking is not None:
        raise DbcFactError(f"--dbc {path}: {lacking}, which odocan's judges read (its DBC: "
                           f"{SHIPPED_DBC})")
    return db


def load_dbc(path: Path) -> cantools.database.can.Database:
    """Load a DBC strictly; any problem is a one-line ``ConfigurationError``."""
    import stat

    import cantools

    try:
        regular = stat.S_ISREG(path.stat().st_mode)
        if regular:  # else cantools would read /dev/zero until memory ends
            db = cantools.database.load_file(path, database_format="dbc", strict=True)
    except OSError as exc:
        raise ConfigurationError(f"cannot read DBC {path}: {exc.strerror or exc}") from None
    except Exception as exc:  # cantools raises ParseError, UnsupportedDatabaseFormatError, ...
        raise ConfigurationError(f"malformed DBC {path}: {_one_line(exc)}") from None
    if not regular:
        raise ConfigurationError(f"cannot read DBC {path}: not a regular file")
    if not isinstance(db, cantools.database.can.Database):
        raise ConfigurationError(f"{path} is not a CAN database")
    return db


def _one_line(exc: BaseException) -> str:
    """cantools' message on one line: its detail is on the lines after the first ("unused VAL_
    entries in DBC:" then which)."""
    return " ".join(str(exc).split()) or type(exc).__name__
