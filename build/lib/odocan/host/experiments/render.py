"""The experiments' tables (rich), laid out like the papers': one row per run, then the means.

Lengths are shown in cm (seed 002's tables) or mm (UMBmark's return errors), angles in degrees;
the JSON reports keep SI units (m) and degrees.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterable

from rich import box
from rich.console import Console
from rich.table import Table

from odocan.host.experiments.seed002 import Seed002Result
from odocan.host.experiments.umbmark import DIRECTIONS, Calibration, UmbmarkResult
from odocan.sim.errors import ErrorModel


def _table(title: str, *columns: str) -> Table:
    table = Table(title=title, box=box.SIMPLE_HEAD, header_style="bold", title_justify="left")
    for i, name in enumerate(columns):
        table.add_column(name, justify="left" if i == 0 else "right")
    return table


def _mean(values: Iterable[float]) -> float:
    items = list(values)
    return math.fsum(items) / len(items)


def straight_table(result: Seed002Result) -> Table:
    """Table 1: distance travelled (cm) and deviation angle (deg) per run, then the mean."""
    table = _table(
        f"Table 1. 1 m straight, {len(result.straight)} runs",
        "Run", "Distance travelled (cm)", "Deviation angle (deg)",
    )
    for i, run in enumerate(result.straight, start=1):
        table.add_row(str(i), f"{run.distance_m * 100:.2f}", f"{run.deviation_deg:+.2f}")
    table.add_section()
    table.add_row("Mean", f"{_mean(r.distance_m for r in result.straight) * 100:.2f}",
                  f"{_mean(r.deviation_deg for r in result.straight):+.2f}", style="bold")
    return table


def square_table(result: Seed002Result) -> Table:
    """Table 2: side length (cm), deviation angle and turn angle (deg) per run, then the mean."""
    table = _table(
        f"Table 2. 80 cm square (counter-clockwise), {len(result.square)} runs",
        "Run", "Side length (cm)", "Deviation angle (deg)", "Turn angle (deg)",
    )
    for i, run in enumerate(result.square, start=1):
        table.add_row(str(i), f"{run.side_m * 100:.2f}", f"{run.deviation_deg:+.2f}",
                      f"{run.turn_deg:.2f}")
    table.add_section()
    table.add_row("Mean", f"{_mean(r.side_m for r in result.square) * 100:.2f}",
                  f"{_mean(r.deviation_deg for r in result.square):+.2f}",
                  f"{_mean(r.turn_deg for r in result.square):.2f}", style="bold")
    return table


def umbmark_table(result: UmbmarkResult, title: str = "UMBmark") -> Table:
    """Return errors (mm) per run for CW and CCW, their centres of gravity and r_c.g."""
    table = _table(
        f"{title}: {result.side_m:g} m square, return errors true - odometry",
        "Run", "CW x (mm)", "CW y (mm)", "CCW x (mm)", "CCW y (mm)",
    )
    cw, ccw = result.of("cw"), result.of("ccw")
    for i in range(max(len(cw), len(ccw))):
        cells = [f"{v * 1000:+.1f}" for runs in (cw, ccw) if i < len(runs)
                 for v in (runs[i].error_x_m, runs[i].error_y_m)]
        table.add_row(str(i + 1), *cells)
    table.add_section()
    cgs = [result.cg(d) for d in DIRECTIONS]
    table.add_row("c.g.", *(f"{v * 1000:+.1f}" for cg in cgs for v in (cg.x_m, cg.y_m)),
                  style="bold")
    table.add_row("r_c.g.", f"{cgs[0].r_m * 1000:.1f}", "", f"{cgs[1].r_m * 1000:.1f}", "",
                  style="bold")
    table.caption = f"E_max,syst = {result.emax_m * 1000:.1f} mm"
    return table


def calibration_table(cal: Calibration, errors: ErrorModel) -> Table:
    """E_d and E_b injected / estimated, the geometry written over CAN, E_max before and after."""
    table = _table("Calibration (Borenstein & Feng)", "", "E_d", "E_b")
    table.add_row("injected", f"{errors.ed:.6f}", f"{errors.eb:.6f}")
    table.add_row("Borenstein (centres of gravity)", f"{cal.borenstein.ed:.6f}",
                  f"{cal.borenstein.eb:.6f}")
    table.add_row("model (encoder log fit)", f"{cal.model[0]:.6f}", f"{cal.model[1]:.6f}")
    ed, eb = cal.estimated
    table.add_row(f"applied ({cal.method})", f"{ed:.6f}", f"{eb:.6f}", style="bold")
    return table


def geometry_table(cal: Calibration) -> Table:
    """The firmware's geometry before and after (nm, as written over CAN)."""
    table = _table("Written to the firmware over CAN (ODOM_CONFIG + APPLY)", "",
                   "nominal (nm)", "corrected (nm)")
    n, c = cal.nominal, cal.corrected
    for name, before, after in (
        ("wheel radius left", n.wheel_radius_left_m, c.wheel_radius_left_m),
        ("wheel radius right", n.wheel_radius_right_m, c.wheel_radius_right_m),
        ("wheelbase", n.wheelbase_m, c.wheelbase_m),
    ):
        table.add_row(name, f"{before * 1e9:.0f}", f"{after * 1e9:.0f}")
    return table


def improvement_line(cal: Calibration) -> str:
    """E_max,syst before and after, and the factor."""
    before, after = cal.before.emax_m, cal.after.emax_m
    factor = f"{before / after:.1f}x smaller" if after > 0 else "to zero"
    return f"E_max,syst {before * 1000:.1f} mm -> {after * 1000:.1f} mm ({factor})"


def show(*items: Table | str) -> None:
    """Print tables and lines to stdout."""
    console = Console(file=sys.stdout, highlight=False, width=110)
    for item in items:
        console.print(item)
