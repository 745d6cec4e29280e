"""``odocan analyze LOG``: the same check as ``odocan run``, offline, on a log file.

The log (``.log`` candump, ``.asc``, ``.blf``, as ``odocan run --log`` or any python-can or
can-utils tool writes them) is read with ``host.logio.read_log``, decoded with the DBC and the
on-board pose compared with the float64 reference computed from the logged encoder counts, and
with the ground truth when ``SIM_TRUTH`` frames are present. The integrator defaults to the one
the firmware reports in ``ODOM_STATUS``; the robot cannot be read from the bus and defaults to
pmir. Same ``--report``, ``--plot``, ``--tolerance``, summary and exit codes as ``odocan run``.

A ``--dbc`` that does not match the log (a message the analysis needs is missing, or none of its
frames is in the log under the DBC's ID, or none passes its E2E check with the DBC's data IDs)
is a one-line error. Frames the DBC does not know are counted (``unknown_frames`` in the report,
a row of the summary) but are no error: a real bus carries other traffic too.

``-b/--bitrate`` adds the measured bus load (``host.judge.busstats.from_frames``: each frame's
exact stuffed length plus the interframe space, over the log's span); a log cannot say when a
frame was queued, so there is no latency to measure.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cantools

from odocan.host.cli.inputs import explained, require_frames
from odocan.host.cli.options import add_robot_argument
from odocan.host.io.export import add_export_arguments, check_export_paths, write_exports
from odocan.host.io.logs import read_log
from odocan.host.judge import busstats
from odocan.host.judge.analysis import analyze
from odocan.host.judge.schedulability import BITRATES
from odocan.host.report import provenance
from odocan.host.report.ci import (
    add_junit_argument,
    analysis_checks,
    check_junit_path,
    write_checks,
)
from odocan.host.report.progress import wall_clock_progress
from odocan.host.report.summary import add_check_arguments, check_output_paths, finish
from odocan.sim import robot
from odocan.sim.contract import DBC_PATH
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.rig import INTEGRATORS


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan analyze``."""
    parser = subparsers.add_parser(
        "analyze",
        help="check the odometry recorded in a CAN log",
        description="Decode a CAN log with the DBC and compare the on-board pose with the "
        "float64 reference (and the ground truth when SIM_TRUTH frames are logged). Exit 0 "
        "within tolerance, 1 not, 2 on bad usage or input.",
    )
    parser.add_argument("log", type=Path, metavar="LOG", help="CAN log: .log (candump), .asc, .blf")
    add_robot_argument(parser)
    parser.add_argument(
        "--integrator",
        choices=INTEGRATORS,
        help="reference integrator (default: the one ODOM_STATUS reports)",
    )
    parser.add_argument(
        "--dbc", type=Path, metavar="PATH", help="DBC to decode with (default: odocan's own)"
    )
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
    parser.set_defaults(func=_do_analyze)


def _do_analyze(args: argparse.Namespace) -> int:
    profile = robot.load(args.robot)
    check_output_paths(args)
    check_export_paths(args.parquet, args.mcap)
    check_junit_path(args)
    db = load_dbc(args.dbc) if args.dbc is not None else None
    with wall_clock_progress(f"analysing {args.log}", None):
        frames = read_log(args.log)
        if db is not None:  # another DBC: its own checks say whether it matches the log
            analysis = analyze(frames, profile, args.integrator, tolerance=args.tolerance, db=db)
        else:  # odocan's DBC: say plainly when the log holds none of its frames
            require_frames(frames, str(args.log))
            with explained(lambda: frames, str(args.log)):
                analysis = analyze(frames, profile, args.integrator, tolerance=args.tolerance)
    write_exports(args, frames, analysis, db)
    if args.bitrate is not None:
        analysis.report["bus"] = busstats.from_frames(frames, args.bitrate).as_dict()
    analysis.report["inputs"] = log_inputs(args.log, profile, analysis.report["integrator"],
                                           args.dbc)
    code = finish(analysis, args, title=f"odocan analyze: {args.log}")
    write_checks(args, "analyze", analysis_checks(analysis.report))
    return code


def can_bitrate(text: str) -> int:
    """``--bitrate``: one of the standard CAN bitrates, in bit/s."""
    value = int(text) if text.strip().isdigit() else -1
    if value not in BITRATES:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a CAN bitrate (use one of {', '.join(map(str, BITRATES))})"
        )
    return value


def log_inputs(
    log: Path, profile: robot.RobotProfile, integrator: str, dbc: Path | None
) -> dict[str, object]:
    """The report's ``inputs`` for a log: the log itself (path, SHA-256) instead of seeds; the
    errors and faults the robot had are unknown (None), not "none"."""
    section = provenance.inputs(profile, integrator=integrator, dbc_path=dbc or DBC_PATH)
    section.update(errors=None, faults=None,
                   log={"path": str(log), "sha256": provenance.file_sha256(log)})
    return section


def load_dbc(path: Path) -> cantools.database.can.Database:
    """Load a DBC strictly; any problem is a one-line ``ConfigurationError``."""
    try:
        db = cantools.database.load_file(path, database_format="dbc", strict=True)
    except OSError as exc:
        raise ConfigurationError(f"cannot read DBC {path}: {exc.strerror or exc}") from None
    except Exception as exc:  # cantools raises ParseError, UnsupportedDatabaseFormatError, ...
        raise ConfigurationError(f"malformed DBC {path}: {_first_line(exc)}") from None
    if not isinstance(db, cantools.database.can.Database):
        raise ConfigurationError(f"{path} is not a CAN database")
    return db


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]
