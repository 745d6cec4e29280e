"""``odocan umbmark``: Borenstein & Feng's bidirectional square test, the firmware navigating.

``--runs`` squares of ``--side`` metres clockwise, then as many counter-clockwise
(``host.experiments.umbmark``), each on a fresh robot in the closed-loop rig under ``--errors``;
prints the return errors, their centres of gravity, r_c.g. and E_max,syst, then the verdict:
PASS when every run is valid (the firmware back at the origin by its own odometry, its on-board
end agreeing with the float64 reference on the logged counts) and E_max,syst is within
``--max-emax`` when given. Exit 0 PASS, 1 FAIL (the reasons printed), 2 on bad usage.
"""

from __future__ import annotations

import argparse

from odocan.host.cli.options import float_in
from odocan.host.experiments import render, umbmark
from odocan.host.experiments.options import (
    add_common_arguments,
    check_report_path,
    verdict,
    write_report,
)
from odocan.host.experiments.outputs import (
    add_plot_argument,
    check_outputs,
    experiment_inputs,
    write_scatter,
)
from odocan.host.experiments.umbmark import Correction
from odocan.host.experiments.umbmark_bounds import small_angle_faults
from odocan.host.report.ci import umbmark_checks, write_checks
from odocan.host.report.progress import counted_progress
from odocan.sim import errors, robot
from odocan.sim.exceptions import ConfigurationError

DEFAULT_ERRORS = "ed=1.002,eb=1.01,slip=0.005"
SIDE_MIN_M, SIDE_MAX_M = 0.2, 20.0


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan umbmark``."""
    parser = subparsers.add_parser(
        "umbmark",
        help="UMBmark: the bidirectional square test of systematic odometry errors",
        description="Borenstein & Feng's UMBmark: the firmware drives the square (turn-go-turn, "
        "from its own odometry) RUNS times clockwise and RUNS times counter-clockwise; the "
        "return errors (true end - on-board end, start frame), their centres of gravity and "
        "E_max,syst.",
    )
    add_arguments(parser)
    add_firmware_robot_argument(parser)
    parser.set_defaults(func=_do_umbmark)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``umbmark`` (``calibrate`` shares them)."""
    add_common_arguments(parser, DEFAULT_ERRORS, umbmark.RUNS_PER_DIRECTION)
    parser.add_argument(
        "--max-emax",
        type=float,
        metavar="MM",
        help="fail when E_max,syst exceeds this many mm (default: no limit)",
    )
    parser.add_argument(
        "--side",
        type=float_in(SIDE_MIN_M, SIDE_MAX_M),
        default=umbmark.SIDE_M,
        metavar="METRES",
        help=f"side of the square, {SIDE_MIN_M:g} .. {SIDE_MAX_M:g} m "
        f"(default: {umbmark.SIDE_M:g})",
    )
    add_plot_argument(parser)


def add_firmware_robot_argument(parser: argparse.ArgumentParser) -> None:
    """``--firmware-robot``: the firmware's profile, when it is not the real robot's."""
    parser.add_argument(
        "--firmware-robot", metavar="NAME|PATH",
        help="configure the firmware (over CAN, at every power-up) with this profile instead of "
        "--robot, e.g. the one 'odocan calibrate --write-robot' wrote; the real robot stays "
        "--robot with --errors (default: --robot)",
    )


def firmware_profile(
    args: argparse.Namespace, real: robot.RobotProfile
) -> robot.RobotProfile | None:
    """The ``--firmware-robot`` profile (None without it); it must share the real robot's
    encoders (counts per revolution, counter width)."""
    if getattr(args, "firmware_robot", None) is None:
        return None
    profile = robot.load(args.firmware_robot)
    if (profile.counts_per_rev, profile.counter_bits) != (real.counts_per_rev, real.counter_bits):
        raise ConfigurationError(
            f"--firmware-robot {args.firmware_robot}: {profile.counts_per_rev} counts/rev, "
            f"{profile.counter_bits}-bit counters, but the robot has {real.counts_per_rev}, "
            f"{real.counter_bits}-bit"
        )
    return profile


def header(args: argparse.Namespace, model: errors.ErrorModel, name: str) -> str:
    """The line printed before the tables."""
    return (
        f"{name}: {args.runs} x CW + {args.runs} x CCW, {args.side:g} m square, robot "
        f"{args.robot}, errors ed={model.ed:g}, eb={model.eb:g}, slip={model.slip:g}, "
        f"seed {args.seed}"
    )


def _do_umbmark(args: argparse.Namespace) -> int:
    check_report_path(args.report)
    check_outputs(args)
    if args.max_emax is not None and not args.max_emax > 0:
        raise ConfigurationError(f"--max-emax must be a positive length in mm, got {args.max_emax}")
    profile, model = robot.load(args.robot), errors.parse(args.errors)
    firmware = firmware_profile(args, profile)
    geometry = None if firmware is None else Correction.nominal(firmware)
    with counted_progress(f"UMBmark: 2 x {args.runs} squares", 2 * args.runs) as one_more:
        result = umbmark.run_umbmark(
            profile, model, args.seed, side_m=args.side, runs_per_direction=args.runs,
            geometry=geometry, on_run=one_more,
        )
    print(header(args, model, "UMBmark"))
    render.show(render.umbmark_table(result))
    report = {
        "robot": profile.name,
        "seed": args.seed,
        "error_model": {"ed": model.ed, "eb": model.eb, "slip": model.slip},
        **umbmark.umbmark_report(result),
    }
    reasons = umbmark.faults(result, profile) + small_angle_faults(result.emax_m, result.side_m)
    if args.max_emax is not None and result.emax_m * 1e3 > args.max_emax:
        reasons.append(f"E_max,syst {result.emax_m * 1e3:.1f} mm exceeds --max-emax "
                       f"{args.max_emax:g} mm")
    report.update(passed=not reasons, faults=reasons)
    report["inputs"] = experiment_inputs(profile, args, firmware=firmware)
    write_report(args.report, report)
    write_scatter(args, [("UMBmark", umbmark.umbmark_report(result))],
                  header(args, model, "UMBmark"))
    write_checks(args, "umbmark", umbmark_checks(report))
    code = verdict("UMBmark", reasons)
    if args.max_emax is None and not reasons:  # a PASS says only that every run was valid
        print("  (every run valid; E_max,syst is judged only with --max-emax MM)")
    return code
