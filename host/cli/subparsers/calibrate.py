"""``odocan calibrate``: UMBmark, E_d and E_b estimated, the firmware corrected over CAN, UMBmark
again.

Borenstein & Feng's estimate from the centres of gravity and a model-based one (the logged
encoder counts dead-reckoned to the true end positions) are both computed
(``host.experiments.umbmark``); ``--method`` picks the one applied (default: model, the more
accurate). The corrected radii and wheelbase are written at each power-up of the second UMBmark
with ODOM_CONFIG staged writes + APPLY, waiting for ODOM_ACK. Verdict: PASS when both benchmarks
are valid, the estimate is plausible and E_max,syst falls at least ``--min-improvement`` times
(``umbmark.calibration_faults``). Exit 0 PASS, 1 FAIL (the reasons printed), 2 on bad usage.
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from odocan.host.cli.subparsers.umbmark import add_arguments, header
from odocan.host.experiments import render, umbmark
from odocan.host.experiments.calreport import calibration_report, refused_report
from odocan.host.experiments.keep import (
    check_robot_path,
    corrected_profile,
    ros2_multipliers,
    ros2_yaml,
    write_robot,
)
from odocan.host.experiments.options import check_report_path, verdict, write_report
from odocan.host.experiments.outputs import check_outputs, experiment_inputs, write_scatter
from odocan.host.report.ci import calibration_checks, write_checks
from odocan.host.report.progress import counted_progress
from odocan.sim import errors, robot
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import profile_sha256


def check_command(args: argparse.Namespace) -> str:
    """The umbmark that re-runs the 'after' squares with the written profile on the firmware
    only: ``--robot`` the written file would also make the simulated robot the corrected one,
    its ``--errors`` applied on top (kobuki ed=1.002,eb=1.01: E_max 574 mm, not 0.1 mm)."""
    argv = ["odocan", "umbmark", "--robot", args.robot, "--firmware-robot", str(args.write_robot),
            "--side", f"{args.side:g}", "--runs", str(args.runs), "--seed", str(args.seed)]
    if args.errors:
        argv += ["--errors", args.errors]
    return shlex.join(argv)


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan calibrate``."""
    parser = subparsers.add_parser(
        "calibrate",
        help="UMBmark, estimate E_d and E_b, correct the firmware over CAN, re-run",
        description="Run UMBmark, estimate E_d and E_b (Borenstein & Feng from the centres of "
        "gravity, and a model fit of the logged encoder counts), write the corrected wheel "
        "radii and wheelbase into the firmware over CAN (ODOM_CONFIG + APPLY, ODOM_ACK awaited) "
        "and run UMBmark again.",
    )
    _add_arguments(parser)
    parser.set_defaults(func=_do_calibrate)


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    add_arguments(parser)
    parser.add_argument(
        "--method",
        choices=umbmark.METHODS,
        default="model",
        help="the estimate written to the firmware (default: model)",
    )
    parser.add_argument(
        "--write-robot", type=Path, metavar="PATH",
        help="write the corrected profile as TOML (.toml) that --robot PATH loads; the ROS 2 "
        "diff_drive_controller multipliers are printed either way (default: none)",
    )
    parser.add_argument(
        "--min-improvement",
        type=float,
        default=umbmark.MIN_IMPROVEMENT,
        metavar="FACTOR",
        help="fail unless E_max,syst falls at least this many times, >= 1 "
        f"(default: {umbmark.MIN_IMPROVEMENT:g})",
    )


def _do_calibrate(args: argparse.Namespace) -> int:
    check_report_path(args.report)
    check_outputs(args)
    check_robot_path(args.write_robot)
    if not args.min_improvement >= 1.0:
        raise ConfigurationError(f"--min-improvement must be >= 1, got {args.min_improvement}")
    profile, model = robot.load(args.robot), errors.parse(args.errors)
    squares = 4 * args.runs
    with counted_progress(f"calibrate: 2 x UMBmark of 2 x {args.runs} squares", squares) as one:
        try:
            cal = umbmark.calibrate(
                profile,
                model,
                args.seed,
                side_m=args.side,
                runs_per_direction=args.runs,
                method=args.method,
                on_run=one,
            )
        except umbmark.CorrectionRefused as exc:  # FAIL on stderr, exit 1; the outputs written
            _write_refused(args, exc)
            raise
    print(header(args, model, "calibrate"))
    render.show(
        render.umbmark_table(cal.before, "Before"),
        render.calibration_table(cal, model),
        render.geometry_table(cal),
        render.umbmark_table(cal.after, "After"),
        render.improvement_line(cal),
    )
    report = {"robot": profile.name, "seed": args.seed, **calibration_report(cal, model)}
    kept = corrected_profile(profile, cal.corrected)
    report["ros2_diff_drive"] = multipliers = ros2_multipliers(profile, kept)
    report["inputs"] = experiment_inputs(profile, args)
    reasons = umbmark.calibration_faults(cal, profile, args.min_improvement)
    report.update(passed=not reasons, faults=reasons)
    print(f"\nROS 2 diff_drive_controller parameters (multipliers: corrected / these):\n"
          f"{ros2_yaml(multipliers)}", end="")
    if args.write_robot is not None and not reasons:
        write_robot(args.write_robot, kept)
        kept_path = shlex.quote(str(args.write_robot))
        print(f"corrected profile written to {args.write_robot} (sha256 "
              f"{profile_sha256(kept)[:12]}): the firmware's geometry (--robot {kept_path} for "
              f"this robot's logs); check it, the real robot kept:\n  {check_command(args)}")
    elif args.write_robot is not None:
        print(f"{args.write_robot} not written: the calibration failed")
    write_report(args.report, report)
    write_scatter(args, [("before calibration", report["before"]),
                         ("after calibration", report["after"])],
                  header(args, model, "calibrate"))
    write_checks(args, "calibrate", calibration_checks(report))
    return verdict("calibrate", reasons)


def _write_refused(args: argparse.Namespace, exc: umbmark.CorrectionRefused) -> None:
    """``--report`` and ``--junit`` of a calibration whose correction the firmware refused: the
    verdict, its reason, the benchmark before and the estimate refused (no benchmark after)."""
    profile = robot.load(args.robot)
    report = {"robot": profile.name, "seed": args.seed,
              **refused_report(exc.refusal, errors.parse(args.errors)),
              "inputs": experiment_inputs(profile, args), "passed": False, "faults": [str(exc)]}
    write_report(args.report, report)
    write_checks(args, "calibrate", calibration_checks(report))
