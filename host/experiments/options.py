"""Command-line options shared by ``odocan experiment``, ``umbmark`` and ``calibrate``.

Values are checked in ``_do_<cmd>`` (not by argparse ``type=``) so that a bad value gives the
error model's or the profile's own one-line message, ``error: ...`` and exit 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from odocan.host import jsonutil
from odocan.host.cli.options import add_robot_argument, add_seed_argument, int_in
from odocan.host.outputs import check_writable

RUNS_MAX = 1000  # runs of an experiment (about a second of CPU each)


def add_common_arguments(parser: argparse.ArgumentParser, default_errors: str, runs: int) -> None:
    """``--robot``, ``--errors``, ``--seed``, ``--runs`` and ``--report``."""
    add_robot_argument(parser)
    parser.add_argument(
        "--errors",
        default=default_errors,
        metavar="ed=..,eb=..,slip=..",
        help=f"the real robot's errors: E_d, E_b, slip std; keys left out are 0 error "
        f"(default: {default_errors})",
    )
    add_seed_argument(parser)
    parser.add_argument(
        "--runs",
        type=int_in(1, RUNS_MAX),
        default=runs,
        help=f"runs, 1 .. {RUNS_MAX} (default: {runs})",
    )
    parser.add_argument(
        "--report", type=Path, metavar="PATH", help="write the JSON report here (default: none;"
        " - for stdout: the summary then goes to stderr)"
    )


def check_report_path(path: Path | None) -> None:
    """Refuse a ``--report`` that cannot be written, before a long run."""
    check_writable(path, "--report")


def write_report(path: Path | None, report: dict[str, object]) -> None:
    """Write ``report`` as strict JSON (nothing without ``--report``); an error names it."""
    if path is not None:
        jsonutil.write_report(path, report)


def verdict(name: str, reasons: list[str]) -> int:
    """Print the verdict (``NAME: PASS``, or ``NAME: FAIL`` and one ``  - reason`` line each) and
    return the exit code: 0 PASS, 1 FAIL."""
    if not reasons:
        print(f"{name}: PASS")
        return 0
    print(f"{name}: FAIL")
    for reason in reasons:
        print(f"  - {reason}")
    return 1
