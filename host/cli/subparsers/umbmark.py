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
import sys

from odocan.host.experiments import render, umbmark
from odocan.host.experiments.options import (
    add_common_arguments,
    check_report_path,
    verdict,
    write_report,
)
from odocan.sim import errors, robot
from odocan.sim.exceptions import ConfigurationError

DEFAULT_ERRORS = "ed=1.002,eb=1.01,slip=0.005"


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
        "--max-emax",
        type=float,
        metavar="MM",
        help="fail when E_max,syst exceeds this many mm (default: no limit)",
    )
    parser.add_argument(
        "--side",
        type=float,
        default=umbmark.SIDE_M,
        metavar="METRES",
        help=f"side of the square (default: {umbmark.SIDE_M:g})",
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
    if args.max_emax is not None and not args.max_emax > 0:
        raise ConfigurationError(f"--max-emax must be a positive length in mm, got {args.max_emax}")
    profile, model = robot.load(args.robot), errors.parse(args.errors)
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
    reasons = umbmark.faults(result, profile)
    if args.max_emax is not None and result.emax_m * 1e3 > args.max_emax:
        reasons.append(f"E_max,syst {result.emax_m * 1e3:.1f} mm exceeds --max-emax "
                       f"{args.max_emax:g} mm")
    report.update(passed=not reasons, faults=reasons)
    write_report(args.report, report)
    return verdict("UMBmark", reasons)


def main(argv: list[str] | None = None) -> int:
    """``odocan umbmark`` on its own (until the subcommand is registered in host.cli)."""
    from odocan.host.cli.app import _Parser

    parser = _Parser(prog="odocan umbmark")
    add_arguments(parser)
    return _do_umbmark(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
