"""The figure of a run: the trajectory, and the on-board error against distance travelled.

Left, the path in the plane (truth, on-board pose from the bus, float64 reference; equal aspect,
start and end marked). Right, on-board minus reference at each on-board pose sample: the
position error in mm and the heading error in mrad, against the distance travelled, with the
tolerance drawn as a dashed line. Matplotlib's Agg backend (no display needed); the format
follows the file's extension, ``.png`` (150 dpi) or ``.svg``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from odocan.host.judge.analysis import Analysis, Tolerance

_COLOURS = {"truth": "0.55", "onboard": "tab:blue", "reference": "tab:orange"}


def plot_analysis(analysis: Analysis, path: Path, *, tolerance: Tolerance | None = None) -> None:
    """Draw ``analysis`` and save it to ``path`` (``.png`` or ``.svg``)."""
    figure = build_figure(analysis.series, analysis.report, tolerance or Tolerance())
    try:
        figure.savefig(path, dpi=150)
    finally:
        plt.close(figure)


def build_figure(
    series: dict[str, np.ndarray], report: dict[str, Any], tolerance: Tolerance
) -> Figure:
    """The two-panel figure (trajectory | errors vs distance) of one analysis."""
    figure = plt.figure(figsize=(13, 6), layout="constrained")
    grid = figure.add_gridspec(2, 2, width_ratios=(1.1, 1))
    path_ax = figure.add_subplot(grid[:, 0])
    pos_ax = figure.add_subplot(grid[0, 1])
    head_ax = figure.add_subplot(grid[1, 1], sharex=pos_ax)
    _draw_trajectory(path_ax, series)
    _draw_errors(pos_ax, head_ax, series, tolerance)
    figure.suptitle(_title(report))
    return figure


def _title(report: dict[str, Any]) -> str:
    scenario = report.get("scenario") or "log"
    verdict = "PASS" if report.get("passed") else "FAIL"
    return (
        f"odocan: {scenario} on {report['robot']['name']}, {report['integrator']} integrator, "
        f"{report['sim_seconds']:.0f} s: {verdict}"
    )


def _draw_trajectory(ax: Axes, series: dict[str, np.ndarray]) -> None:
    curves = (
        ("truth", "truth_x_m", "truth_y_m", 3.0, "-"),
        ("on-board (bus)", "onboard_x_m", "onboard_y_m", 1.6, "-"),
        ("float64 reference", "reference_x_m", "reference_y_m", 1.2, "--"),
    )
    for (label, xkey, ykey, width, style), colour in zip(curves, _COLOURS.values(), strict=True):
        x, y = series.get(xkey, np.empty(0)), series.get(ykey, np.empty(0))
        if len(x):
            ax.plot(x, y, style, color=colour, linewidth=width, label=label)
    x, y = series["onboard_x_m"], series["onboard_y_m"]
    if len(x):
        ax.plot(x[0], y[0], "o", color="tab:green", markersize=7, label="start")
        ax.plot(x[-1], y[-1], "s", color="tab:red", markersize=7, label="end (on-board)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("trajectory")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def _draw_errors(
    pos_ax: Axes, head_ax: Axes, series: dict[str, np.ndarray], tolerance: Tolerance
) -> None:
    distance = series["distance_m"]
    pos_ax.plot(distance, series["position_error_m"] * 1e3, color="tab:blue", linewidth=1)
    pos_ax.axhline(
        tolerance.position_m * 1e3,
        color="tab:red",
        linestyle="--",
        linewidth=1,
        label=f"tolerance {tolerance.position_m * 1e3:g} mm",
    )
    pos_ax.set_ylabel("position error (mm)")
    pos_ax.set_title("on-board minus float64 reference")
    head_ax.plot(distance, series["heading_error_rad"] * 1e3, color="tab:purple", linewidth=1)
    for sign in (1, -1):
        head_ax.axhline(
            sign * tolerance.heading_rad * 1e3,
            color="tab:red",
            linestyle="--",
            linewidth=1,
            label=f"tolerance ±{tolerance.heading_rad * 1e3:.3g} mrad" if sign > 0 else None,
        )
    head_ax.set_ylabel("heading error (mrad)")
    head_ax.set_xlabel("distance travelled (m)")
    pos_ax.tick_params(labelbottom=False)
    for ax in (pos_ax, head_ax):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper left", fontsize="small")
