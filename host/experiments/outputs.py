"""What ``experiment``, ``umbmark`` and ``calibrate`` write besides their tables and ``--report``:
``--plot`` (Borenstein's scatter), ``--junit`` (``host.report.ci``) and the report's ``inputs``.

Every path is checked before the runs (``check_outputs``), so minutes of driving are never lost
to an output that cannot be written.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from odocan.host.outputs import check_writable, replaced
from odocan.host.report import provenance
from odocan.host.report.ci import add_junit_argument, check_junit_path
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import RobotProfile, profile_sha256

PLOT_SUFFIXES = (".png", ".svg")
INTEGRATOR = "exact"  # NavSession's on-board integrator


def add_plot_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--plot PATH`` (the UMBmark scatter) and ``--junit PATH``."""
    parser.add_argument(
        "--plot", type=Path, metavar="PATH",
        help="write Borenstein's return-position scatter, CW and CCW with their centres of "
        "gravity (.png, .svg) (default: none)",
    )
    add_junit_argument(parser)


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse a ``--plot`` of unknown format, or a ``--plot``/``--junit`` that cannot be
    written, up front."""
    plot: Path | None = getattr(args, "plot", None)
    if plot is not None and plot.suffix.lower() not in PLOT_SUFFIXES:
        raise ConfigurationError(
            f"--plot {plot}: unknown format {plot.suffix or '(none)'!r} (use .png or .svg)"
        )
    check_writable(plot, "--plot")
    check_junit_path(args)


def experiment_inputs(
    robot: RobotProfile,
    args: argparse.Namespace,
    *,
    firmware: RobotProfile | None = None,
    integrator: str = INTEGRATOR,
) -> dict[str, Any]:
    """The report's ``inputs``: the real robot's profile (hash), the integrator, ``--errors``,
    the seed, version and DBC; ``firmware_robot`` when the firmware had another profile."""
    section = provenance.inputs(
        robot, integrator=integrator, errors=args.errors, faults="", seeds={"seed": args.seed}
    )
    if firmware is not None:
        section["firmware_robot"] = {**firmware.firmware_params(), "name": firmware.name,
                                     "sha256": profile_sha256(firmware)}
    return section


def write_scatter(
    args: argparse.Namespace, panels: list[tuple[str, dict[str, Any]]], heading: str
) -> None:
    """Draw ``--plot`` (nothing without it); an I/O error names the path."""
    path: Path | None = getattr(args, "plot", None)
    if path is None:
        return
    from odocan.host.report.plots import plot_umbmark  # matplotlib only when asked

    with replaced(path, "--plot") as target:  # a full disk: no part left, an older plot kept
        plot_umbmark(panels, target, heading=heading)
