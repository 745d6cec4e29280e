"""``odocan experiment seed002``: seed 002's Tables 1 and 2 with the firmware navigating.

10 x 1 m straight and 10 laps of the 80 cm square (``host.experiments.seed002``), each run a
fresh robot in the closed-loop lockstep rig under ``--errors`` and a seeded start misalignment
(``--misalign``, the std in degrees); the tables are measured from the ground truth. Verdict:
PASS when every run is valid (``Seed002Result.faults``: the firmware at its goal by its own
odometry, its on-board end = the float64 reference on the logged counts). Exit 0 PASS, 1 FAIL
(the reasons printed), 2 on bad usage.
"""

from __future__ import annotations

import argparse

from odocan.host.cli.options import float_in
from odocan.host.experiments import render, seed002
from odocan.host.experiments.options import (
    add_common_arguments,
    check_report_path,
    verdict,
    write_report,
)
from odocan.host.experiments.outputs import experiment_inputs
from odocan.host.report.ci import (
    add_junit_argument,
    check_junit_path,
    experiment_checks,
    write_checks,
)
from odocan.host.report.progress import counted_progress
from odocan.sim import errors, robot

EXPERIMENTS = ("seed002",)


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan experiment``."""
    parser = subparsers.add_parser(
        "experiment",
        help="re-run a paper's experiment with the firmware navigating",
        description="Re-run a paper's experiment in the closed-loop rig (the firmware navigates "
        "from its own odometry, the host sends NAV_GOAL paths) and print its tables, measured "
        "from the ground truth. seed002: 1 m straight (Table 1) and 80 cm square (Table 2).",
    )
    _add_arguments(parser)
    parser.set_defaults(func=_do_experiment)


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=EXPERIMENTS, help="the experiment")
    add_common_arguments(parser, seed002.DEFAULT_ERRORS, seed002.RUNS)
    parser.add_argument(
        "--misalign",
        type=float_in(0.0, 45.0),
        default=seed002.DEFAULT_MISALIGN_DEG,
        metavar="DEG",
        help="std of the random start misalignment, degrees, 0 .. 45 "
        f"(default: {seed002.DEFAULT_MISALIGN_DEG:g})",
    )
    add_junit_argument(parser)


def _do_experiment(args: argparse.Namespace) -> int:
    check_report_path(args.report)
    check_junit_path(args)
    config = seed002.Seed002Config(
        robot=robot.load(args.robot),
        errors=errors.parse(args.errors),
        misalign_deg=args.misalign,
        seed=args.seed,
        runs=args.runs,
    )
    with counted_progress(f"seed002: 2 x {config.runs} runs", 2 * config.runs) as one_more:
        result = seed002.run_seed002(config, on_run=one_more)
    e = config.errors
    print(
        f"seed002 on {config.robot.name}: ed={e.ed:g}, eb={e.eb:g}, slip={e.slip:g}, start "
        f"misalignment N(0, {config.misalign_deg:g} deg), seed {config.seed}; measured from the "
        "ground truth, deviations positive to the left"
    )
    render.show(render.straight_table(result), render.square_table(result))
    reasons = result.faults()
    report = {**seed002.report(result), "passed": not reasons, "faults": reasons,
              "inputs": experiment_inputs(config.robot, args, integrator=config.integrator)}
    write_report(args.report, report)
    write_checks(args, "experiment", experiment_checks(report))
    return verdict("seed002", reasons)
