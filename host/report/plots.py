"""The figure of a run: the trajectory, and the on-board drift against time and distance.

Left, the path in the plane: the truth as a smooth line (the simulator's full-rate state when the
run recorded it, ``truth_full_*`` series; else the 10 Hz SIM_TRUTH samples carried onto the
50 Hz on-board path by interpolating the slowly varying truth - on-board difference, never the
positions themselves; the legend says which), the on-board pose from the bus and the float64
reference. Right, four rows of errors, against time (middle column) and distance travelled
(right column): on-board - truth (position mm, heading mrad) and on-board - reference (position
mm, heading mrad, the tolerance dashed). Headings are unwrapped, so a drifting FAIL shows its
growth rather than a +-pi sawtooth. Gaps (consecutive samples further apart in the encoder
sequence than usual: dropped frames) are shaded and no line bridges them (a NaN break);
reference restarts after an encoder-sequence gap are dotted vertical lines. The title carries the
robot, integrator, injected errors and bus faults (from the report's ``inputs``) and the figures.
Matplotlib's Agg backend; the format follows the extension, ``.png`` (100 dpi, 256 colours) or
``.svg``.
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from PIL import Image

from odocan.host.judge.analysis import Analysis, Tolerance
from odocan.host.stopped import partial_verdict

PNG_DPI = 100
_TRUTH, _ONBOARD, _REFERENCE = "0.45", "tab:blue", "tab:orange"
_GAP, _RESTART = "tab:red", "tab:purple"
Series = dict[str, np.ndarray]


def plot_analysis(analysis: Analysis, path: Path, *, tolerance: Tolerance | None = None) -> None:
    """Draw ``analysis`` and save it to ``path`` (``.png`` or ``.svg``)."""
    save(build_figure(analysis.series, analysis.report, tolerance or Tolerance()), path)


def save(figure: Figure, path: Path) -> None:
    """Save and close ``figure``: SVG as is, PNG at ``PNG_DPI`` with a 256-colour palette (a
    third of the bytes of full RGBA, the lines unchanged to the eye)."""
    try:
        if path.suffix.lower() != ".png":
            figure.savefig(path)
            return
        buffer = io.BytesIO()
        figure.savefig(buffer, format="png", dpi=PNG_DPI)
    finally:
        plt.close(figure)
    buffer.seek(0)
    with Image.open(buffer) as image:
        image.convert("RGB").quantize(colors=256).save(path, format="PNG", optimize=True)


def build_figure(series: Series, report: dict[str, Any], tolerance: Tolerance) -> Figure:
    """Trajectory | errors vs time | errors vs distance, four error rows (module docstring)."""
    figure = plt.figure(figsize=(17, 9.5), layout="constrained")
    grid = figure.add_gridspec(4, 3, width_ratios=(1.3, 1, 1))
    _draw_trajectory(figure.add_subplot(grid[:, 0]), series)
    time_axes = [figure.add_subplot(grid[row, 1]) for row in range(4)]
    dist_axes = [figure.add_subplot(grid[row, 2]) for row in range(4)]
    for axes, axis in ((time_axes, "t"), (dist_axes, "distance")):
        _draw_error_column(axes, series, axis, tolerance)
    time_axes[-1].set_xlabel("time since the log's first frame (s)")
    dist_axes[-1].set_xlabel("distance travelled (m)")
    _legend_of_marks(dist_axes[0], series)
    figure.suptitle(title(report), fontsize="medium")
    return figure


# --- title ------------------------------------------------------------------------------------


def title(report: dict[str, Any]) -> str:
    """Two lines: what ran (robot, integrator, errors, faults) and what was found."""
    inputs = report.get("inputs") or {}
    verdict = "PASS" if partial_verdict(report) else "FAIL"
    if report.get("stopped"):
        verdict = f"STOPPED: partial {verdict}"
    distance = (report.get("onboard_vs_truth") or {}).get("distance_travelled_m")
    line1 = (
        f"odocan: {report.get('scenario') or 'log'} on {report['robot']['name']}, "
        f"{report['integrator']} integrator, {report['sim_seconds']:.0f} s"
        + (f", {distance:.1f} m" if distance is not None else "")
        + f", errors {_input_text(inputs, 'errors')}, faults {_input_text(inputs, 'faults')}"
        + (f", seed {report['seed']}" if report.get("seed") is not None else "")
    )
    ref = report.get("onboard_vs_reference") or {}
    truth = report.get("onboard_vs_truth") or {}
    line2 = (
        f"{verdict}: on-board - reference max {_mm(ref.get('max_position_error_m'))}, "
        f"{_mrad(ref.get('max_heading_error_rad'))}; on-board - truth max "
        f"{_mm(truth.get('max_position_error_m'))}, {_mrad(truth.get('max_heading_error_rad'))}"
    )
    return f"{line1}\n{line2}"


def _input_text(inputs: dict[str, Any], key: str) -> str:
    if key not in inputs:
        return "not recorded"
    value = inputs[key]
    if value is None:
        return "unknown (a log)"
    return str(value) or "none"


def _mm(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value * 1e3:.4g} mm"


def _mrad(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value * 1e3:.4g} mrad"


# --- NaN breaks -------------------------------------------------------------------------------


def break_indices(seq: np.ndarray) -> np.ndarray:
    """Positions i where samples i and i + 1 are further apart in ``seq`` (encoder sequence
    numbers) than its usual (median) step, or where ``seq`` starts again (a firmware reboot:
    each life is numbered from 0): a line must not join them."""
    steps = np.diff(np.asarray(seq, dtype=np.int64))
    if len(steps) == 0:
        return np.zeros(0, dtype=np.int64)
    usual = max(1, int(np.median(steps)))
    return np.flatnonzero((steps > usual) | (steps <= 0))


def broken(values: np.ndarray, seq: np.ndarray) -> np.ndarray:
    """``values`` as float with a NaN inserted after each break of ``seq`` (``break_indices``)."""
    result: np.ndarray = np.insert(
        np.asarray(values, dtype=np.float64), break_indices(seq) + 1, np.nan
    )
    return result


# --- the trajectory -----------------------------------------------------------------------------


def smooth_truth(series: Series) -> tuple[np.ndarray, np.ndarray, str]:
    """The truth path (x, y in m, NaN breaks) and how it was obtained (for the legend)."""
    if len(series.get("truth_full_x_m", ())):
        rate = _rate_hz(series.get("truth_full_t_s", np.zeros(0)))
        return series["truth_full_x_m"], series["truth_full_y_m"], f"truth (sim state, {rate})"
    t_truth = series.get("truth_t_s", np.zeros(0))
    if len(t_truth) < 2:
        return np.zeros(0), np.zeros(0), "truth"
    t = series["t_s"]
    dx = np.interp(t, t_truth, series["truth_dx_m"])
    dy = np.interp(t, t_truth, series["truth_dy_m"])
    outside = (t < t_truth[0]) | (t > t_truth[-1])
    for i in break_indices(series["truth_seq"]):  # no truth across a SIM_TRUTH gap
        outside |= (t > t_truth[i]) & (t < t_truth[i + 1])
    x = np.where(outside, np.nan, series["onboard_x_m"] + dx)
    y = np.where(outside, np.nan, series["onboard_y_m"] + dy)
    seq = series["onboard_seq"]
    label = f"truth (SIM_TRUTH {_rate_hz(t_truth)}, difference interpolated on the on-board path)"
    return broken(x, seq), broken(y, seq), label


def _rate_hz(t_s: np.ndarray) -> str:
    """The usual sample rate of a time series, e.g. ``100 Hz``."""
    steps = np.diff(t_s)
    if len(steps) == 0 or not np.median(steps) > 0:
        return "? Hz"
    return f"{1.0 / float(np.median(steps)):.0f} Hz"


def _draw_trajectory(ax: Axes, series: Series) -> None:
    tx, ty, truth_label = smooth_truth(series)
    if len(tx):
        ax.plot(tx, ty, "-", color=_TRUTH, linewidth=3.0, label=truth_label)
    seq = series.get("onboard_seq", np.arange(len(series["onboard_x_m"])))
    ax.plot(broken(series["onboard_x_m"], seq), broken(series["onboard_y_m"], seq), "-",
            color=_ONBOARD, linewidth=1.4, label="on-board (bus)")
    ax.plot(broken(series["reference_x_m"], seq), broken(series["reference_y_m"], seq), "--",
            color=_REFERENCE, linewidth=1.1, label="float64 reference")
    x, y = series["onboard_x_m"], series["onboard_y_m"]
    gaps = break_indices(seq)
    if len(gaps):
        ax.plot(x[gaps], y[gaps], "|", color=_GAP, markersize=10, label="gap starts")
    if len(x):
        ax.plot(x[0], y[0], "o", color="tab:green", markersize=7, label="start")
        ax.plot(x[-1], y[-1], "s", color="tab:red", markersize=7, label="end (on-board)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("trajectory")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


# --- the error panels -------------------------------------------------------------------------


def _draw_error_column(
    axes: list[Axes], series: Series, axis: str, tolerance: Tolerance
) -> None:
    """Rows: truth position, truth heading, reference position, reference heading."""
    truth_x = series.get("truth_t_s" if axis == "t" else "truth_distance_m", np.zeros(0))
    ref_x = series["t_s" if axis == "t" else "distance_m"]
    truth_seq = series.get("truth_seq", np.zeros(0))
    ref_seq = series["onboard_seq"]
    rows = (
        (truth_x, series.get("truth_position_error_m"), truth_seq, 1e3, "mm", _TRUTH, None),
        (truth_x, series.get("truth_heading_error_unwrapped_rad"), truth_seq, 1e3, "mrad",
         _TRUTH, None),
        (ref_x, series["position_error_m"], ref_seq, 1e3, "mm", _ONBOARD, tolerance.position_m),
        (ref_x, series["heading_error_unwrapped_rad"], ref_seq, 1e3, "mrad", _ONBOARD,
         tolerance.heading_rad),
    )
    names = ("on-board - truth", "on-board - truth", "on-board - reference",
             "on-board - reference")
    for ax, name, (x, y, seq, scale, unit, colour, limit) in zip(axes, names, rows, strict=True):
        quantity = "position" if unit == "mm" else "heading (unwrapped)"
        ax.set_ylabel(f"{quantity}\n({unit})", fontsize="small")
        ax.set_title(f"{name}, {quantity}", fontsize="small", loc="left")
        ax.grid(True, alpha=0.3)
        _mark_gaps(ax, series, axis)
        if y is None or len(y) == 0:
            ax.text(0.5, 0.5, "no SIM_TRUTH in the log", transform=ax.transAxes,
                    ha="center", va="center", color="0.4")
            continue
        ax.plot(broken(x, seq), broken(y * scale, seq), color=colour, linewidth=1.0,
                marker="." if len(y) < 200 else None, markersize=3)
        if limit is not None:
            _draw_tolerance(ax, limit * scale, unit, symmetric=unit == "mrad")


def _draw_tolerance(ax: Axes, limit: float, unit: str, *, symmetric: bool) -> None:
    for sign in (1, -1) if symmetric else (1,):
        ax.axhline(sign * limit, color="tab:red", linestyle="--", linewidth=0.9)
    label = f"tolerance {'±' if symmetric else ''}{limit:.3g} {unit}"
    ax.text(0.99, 0.95, label, transform=ax.transAxes, ha="right", va="top",
            fontsize="x-small", color="tab:red")


def _mark_gaps(ax: Axes, series: Series, axis: str) -> None:
    """Shade each gap span and draw each reference restart (module docstring)."""
    key = "t_s" if axis == "t" else "distance_m"
    for start, end in zip(series.get(f"gap_start_{key}", ()), series.get(f"gap_end_{key}", ()),
                          strict=True):
        ax.axvspan(float(start), float(end), color=_GAP, alpha=0.18, linewidth=0)
    for where in series.get(f"restart_{key}", ()):
        ax.axvline(float(where), color=_RESTART, linestyle=":", linewidth=1.2)


def _legend_of_marks(ax: Axes, series: Series) -> None:
    """A legend for the gap shading and restart lines, when the run has any."""
    handles: list[Patch | Line2D] = []
    gaps = len(series.get("gap_start_t_s", ()))
    restarts = len(series.get("restart_t_s", ()))
    if gaps:
        handles.append(Patch(color=_GAP, alpha=0.3, label=f"gap: dropped frames ({gaps})"))
    if restarts:
        handles.append(Line2D([], [], color=_RESTART, linestyle=":",
                              label=f"reference restart ({restarts})"))
    if handles:
        ax.legend(handles=handles, loc="upper left", fontsize="x-small")


# --- UMBmark: Borenstein's return-position scatter ----------------------------------------------

_DIRECTION_STYLE = {"cw": ("tab:blue", "o", "CW"), "ccw": ("tab:red", "^", "CCW")}


def plot_umbmark(panels: list[tuple[str, dict[str, Any]]], path: Path, *, heading: str) -> None:
    """Borenstein & Feng's figure, one panel per benchmark (e.g. before and after calibration):
    each run's return error (true end - on-board end, mm, start frame) for CW and CCW, their
    centres of gravity joined to the origin, and the circle of radius E_max,syst. ``panels``:
    (title, ``umbmark.umbmark_report`` dict); ``heading``: the figure's title."""
    figure = plt.figure(figsize=(6.2 * len(panels), 6.4), layout="constrained")
    for k, (name, report) in enumerate(panels):
        _draw_scatter(figure.add_subplot(1, len(panels), k + 1), name, report)
    figure.suptitle(heading, fontsize="medium")
    save(figure, path)


def _draw_scatter(ax: Axes, name: str, report: dict[str, Any]) -> None:
    for direction, (colour, marker, label) in _DIRECTION_STYLE.items():
        part = report[direction]
        x = np.array([run["x_m"] for run in part["runs"]]) * 1e3
        y = np.array([run["y_m"] for run in part["runs"]]) * 1e3
        ax.plot(x, y, marker, color=colour, alpha=0.7, markersize=6,
                label=f"{label} runs ({len(x)})")
        cx, cy = part["cg"]["x_m"] * 1e3, part["cg"]["y_m"] * 1e3
        ax.plot([0, cx], [0, cy], "-", color=colour, linewidth=1)
        ax.plot(cx, cy, "X", markersize=14, markerfacecolor="none", markeredgecolor=colour,
                markeredgewidth=1.8,
                label=f"c.g. {label}: ({cx:.1f}, {cy:.1f}) mm, r = {part['r_cg_m'] * 1e3:.1f} mm")
    emax_mm = report["emax_syst_m"] * 1e3
    angle = np.linspace(0, 2 * math.pi, 181)
    ax.plot(emax_mm * np.cos(angle), emax_mm * np.sin(angle), "--", color="0.5", linewidth=0.9,
            label=f"E_max,syst = {emax_mm:.1f} mm")
    ax.plot(0, 0, "+", color="black", markersize=12)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("return error x (mm)")
    ax.set_ylabel("return error y (mm)")
    ax.set_title(f"{name}: {report['side_m']:g} m square", fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize="x-small")


# --- bus latency (odocan run -b ... --latency-plot) -----------------------------------------


def plot_latency(report: dict[str, Any], path: Path) -> None:
    """The report's ``bus`` section as a figure saved to ``path`` (``.png`` or ``.svg``)."""
    save(build_latency_figure(report["bus"]), path)


def build_latency_figure(bus: dict[str, Any]) -> Figure:
    """Per message, highest priority on top: the measured p99 and maximum latency (queued to end
    of frame) as bars, the analysis' worst case R as a black tick, the deadline as a red one;
    a log-scaled time axis in ms, so a 0.2 ms frame and a 100 ms deadline share it."""
    rows = bus["messages"]
    figure = plt.figure(figsize=(10, 1.2 + 0.45 * max(len(rows), 1)), layout="constrained")
    axes = figure.add_subplot()
    names = [row["name"] for row in rows]
    ys = list(range(len(rows)))[::-1]
    for y, row in zip(ys, rows, strict=True):
        if row["max_latency_us"] is not None:
            axes.barh(y, row["max_latency_us"] / 1000, height=0.7, color="tab:orange",
                      label="max" if y == ys[0] else None)
            axes.barh(y, row["p99_latency_us"] / 1000, height=0.7, color="tab:blue",
                      label="p99" if y == ys[0] else None)
        for key, colour, label in (("bound_us", "black", "R (analysis)"),
                                   ("deadline_us", "red", "deadline")):
            if row[key] is not None:
                axes.plot([row[key] / 1000] * 2, [y - 0.45, y + 0.45], color=colour, lw=2,
                          label=label if y == ys[0] else None)
        if row.get("starved"):
            axes.annotate(f"starved: {row['late']} late, {row['still_queued']} never sent",
                          (0.99, y), xycoords=("axes fraction", "data"), va="center",
                          ha="right", fontsize="small", color="red",
                          bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8})
    axes.set_yticks(ys, names)
    axes.set_xscale("log")
    axes.set_xlabel("latency, ready in the transmit buffer to end of frame (ms)")
    load = bus.get("load")
    load_text = "-" if load is None else f"{load:.1%}"
    axes.set_title(f"bus latency per message: {bus['bitrate'] // 1000} kbit/s, measured load "
                   f"{load_text} over {bus['span_s']:.1f} s, {bus['frames']} frames",
                   fontsize="medium")
    axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small")
    axes.grid(axis="x", which="both", alpha=0.3)
    return figure
