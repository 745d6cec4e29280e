"""``odocan umbmark``: Borenstein & Feng's bidirectional square test, the firmware navigating.

``--runs`` squares of ``--side`` metres clockwise, then as many counter-clockwise
(``host.experiments.umbmark``), each on a fresh robot in the closed-loop rig under ``--errors``;
prints the return errors, their centres of gravity, r_c.g. and E_max,syst. Exit 0, or 2 on bad
usage.
"""

from __future__ import annotations

import argparse

from odocan.host.cli.options import float_in
from odocan.host.experiments import render, umbmark
from odocan.host.experiments.options import add_common_arguments, check_report_path, write_report
from odocan.host.report.progress import wall_clock_progress
from odocan.sim import errors, robot

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
    parser.set_defaults(func=_do_umbmark)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``umbmark`` (``calibrate`` shares them)."""
    add_common_arguments(parser, DEFAULT_ERRORS, umbmark.RUNS_PER_DIRECTION)
    parser.add_argument(
        "--side",
        type=float_in(SIDE_MIN_M, SIDE_MAX_M),
        default=umbmark.SIDE_M,
        metavar="METRES",
        help=f"side of the square, {SIDE_MIN_M:g} .. {SIDE_MAX_M:g} m "
        f"(default: {umbmark.SIDE_M:g})",
    )


def header(args: argparse.Namespace, model: errors.ErrorModel, name: str) -> str:
    """The line printed before the tables."""
    return (
        f"{name}: {args.runs} x CW + {args.runs} x CCW, {args.side:g} m square, robot "
        f"{args.robot}, errors ed={model.ed:g}, eb={model.eb:g}, slip={model.slip:g}, "
        f"seed {args.seed}"
    )


def _do_umbmark(args: argparse.Namespace) -> int:
    check_report_path(args.report)
    profile, model = robot.load(args.robot), errors.parse(args.errors)
    with wall_clock_progress(f"UMBmark: 2 x {args.runs} squares", None):
        result = umbmark.run_umbmark(
            profile, model, args.seed, side_m=args.side, runs_per_direction=args.runs
        )
    print(header(args, model, "UMBmark"))
    render.show(render.umbmark_table(result))
    report = {
        "robot": profile.name,
        "seed": args.seed,
        "error_model": {"ed": model.ed, "eb": model.eb, "slip": model.slip},
        **umbmark.umbmark_report(result),
    }
    write_report(args.report, report)
    return 0
