"""The drift plots: the series the analysis adds for them, NaN breaks at gaps, unwrapped headings,
a smooth truth checked against the simulator's own full-rate state, the title's inputs, and the
UMBmark scatter drawn from a report."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from odocan.host.cli.subparsers.run import TruthTrace
from odocan.host.io.logs import FrameArrays, FrameCollector
from odocan.host.judge.analysis import Analysis, Tolerance, analyze
from odocan.host.report import plots
from odocan.sim import errors, robot
from odocan.sim.faults import FaultSpec
from odocan.sim.rig import LockstepRig, RigConfig

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _drive(config: RigConfig, ticks: int) -> tuple[FrameArrays, dict[str, np.ndarray]]:
    """Run the rig ``ticks`` ticks; the frames heard and the full-rate truth (``TruthTrace``)."""
    collector = FrameCollector()
    rig = LockstepRig(config, listeners=[collector])
    trace = TruthTrace(rig)
    try:
        for _ in range(ticks):
            rig.step()
            trace.record()
    finally:
        rig.close()
    frames = collector.arrays()
    return frames, trace.series(float(frames.timestamp_s[0]))


@pytest.fixture(scope="module")
def drift() -> tuple[Analysis, dict[str, np.ndarray]]:
    """20 s of the random drive on a robot with E_d, E_b: clean bus."""
    config = RigConfig(robot=robot.load("pmir"), seed=3, errors=errors.parse("ed=1.002,eb=1.01"))
    frames, full = _drive(config, 2000)
    return analyze(frames, config.robot, "exact"), full


@pytest.fixture(scope="module")
def gappy() -> Analysis:
    """30 s with the motor controller bus-off from 10 s to 12 s, analysed with the wrong robot
    (wheelbase a third short): a FAIL whose heading error grows past pi, with gaps."""
    faults = FaultSpec.parse("busoff=10:2,seed=1")
    profile = robot.load("pmir")
    config = RigConfig(robot=profile, seed=5, faults=faults)
    frames, _ = _drive(config, 3000)
    wrong = replace(profile, wheelbase_m=0.2)
    return analyze(frames, wrong, "exact")


def test_series_time_axis_and_lengths(drift: tuple[Analysis, dict[str, np.ndarray]]) -> None:
    series = drift[0].series
    n = len(series["onboard_x_m"])
    for key in ("t_s", "onboard_seq", "heading_error_unwrapped_rad", "distance_m"):
        assert len(series[key]) == n, key
    assert np.all(np.diff(series["t_s"]) > 0)
    assert series["t_s"][-1] == pytest.approx(20.0, abs=0.1)  # seconds since the first frame
    m = len(series["truth_t_s"])
    assert m == drift[0].report["samples"]["truth_compared"] > 150  # 10 Hz over 20 s
    for key in ("truth_seq", "truth_distance_m", "truth_position_error_m",
                "truth_heading_error_unwrapped_rad", "truth_dx_m", "truth_dy_m"):
        assert len(series[key]) == m, key
    # the truth error series is the verdict's: same maximum as the report
    truth = drift[0].report["onboard_vs_truth"]
    assert series["truth_position_error_m"].max() == pytest.approx(truth["max_position_error_m"])
    assert np.hypot(series["truth_dx_m"], series["truth_dy_m"]) == pytest.approx(
        series["truth_position_error_m"])
    assert len(series["gap_start_t_s"]) == len(series["restart_t_s"]) == 0  # a clean bus


def test_smooth_truth_matches_the_simulators_full_rate_state(
    drift: tuple[Analysis, dict[str, np.ndarray]],
) -> None:
    """From 10 Hz SIM_TRUTH only, the carefully interpolated truth (truth - on-board difference
    carried on the 50 Hz on-board path) is within 1 mm of the simulator's 100 Hz state, and
    closer than a straight polygon through the 10 Hz samples."""
    analysis, full = drift
    series = analysis.series
    x, y, label = plots.smooth_truth(series)
    assert "SIM_TRUTH 10 Hz" in label
    assert "interpolated" in label
    t = series["t_s"]
    fx = np.interp(t, full["truth_full_t_s"], full["truth_full_x_m"])
    fy = np.interp(t, full["truth_full_t_s"], full["truth_full_y_m"])
    careful = np.nanmax(np.hypot(x - fx, y - fy))
    tt = series["truth_t_s"]
    inside = (t >= tt[0]) & (t <= tt[-1])
    px, py = np.interp(t, tt, series["truth_x_m"]), np.interp(t, tt, series["truth_y_m"])
    polygon = np.max(np.hypot(px - fx, py - fy)[inside])
    assert careful < 1e-3
    assert careful < polygon
    assert np.count_nonzero(np.isnan(x)) < 10  # only before the first / after the last sample
    with_full = {**series, **full}
    _, _, label = plots.smooth_truth(with_full)
    assert label == "truth (sim state, 100 Hz)"


def test_gaps_and_restarts_are_found_where_the_bus_was_off(gappy: Analysis) -> None:
    series = gappy.series
    starts, ends = series["gap_start_t_s"], series["gap_end_t_s"]
    assert len(starts) >= 1
    widest = int(np.argmax(ends - starts))
    assert starts[widest] == pytest.approx(10.0, abs=0.1)
    assert ends[widest] - starts[widest] >= 1.9  # the 2 s bus-off
    restarts = series["restart_t_s"]
    assert len(restarts) == gappy.report["samples"]["reference_restarts"] >= 1
    assert np.any(np.abs(restarts - ends[widest]) < 0.05)
    assert np.all(series["gap_end_distance_m"] >= series["gap_start_distance_m"])


def test_heading_error_is_unwrapped_on_a_fail(gappy: Analysis) -> None:
    """The wrong wheelbase drives the heading error past pi: the wrapped series jumps by 2 pi,
    the plotted one does not (between gaps it moves by less than 0.05 rad a sample), and it
    equals the wrapped one modulo 2 pi."""
    series = gappy.series
    # the judge's heading error counts TURNS (it may pass pi); wrapped into (-pi, pi] it saws
    wrapped = np.angle(np.exp(1j * series["heading_error_rad"]))
    unwrapped = series["heading_error_unwrapped_rad"]
    assert not gappy.passed
    assert np.max(np.abs(unwrapped)) > 1.5 * math.pi
    assert np.max(np.abs(np.diff(wrapped))) > math.pi  # the sawtooth the plot must not show
    steps = np.abs(np.diff(unwrapped))
    steps[plots.break_indices(series["onboard_seq"])] = 0.0  # the error may grow over a gap
    assert np.max(steps) < 0.05
    turns = (unwrapped - wrapped) / (2 * math.pi)
    assert turns == pytest.approx(np.round(turns), abs=1e-9)


def test_broken_inserts_nan_at_sequence_gaps() -> None:
    seq = np.array([0, 2, 4, 10, 12, 14, 30])
    out = plots.broken(np.arange(7.0), seq)
    assert np.isnan(out).sum() == 2
    assert list(np.flatnonzero(np.isnan(out))) == [3, 7]
    assert list(out[~np.isnan(out)]) == list(range(7))
    assert len(plots.broken(np.zeros(0), np.zeros(0))) == 0


def test_no_line_joins_two_firmware_lives() -> None:
    """After a reboot the sequence starts again at 0 (each life is numbered from its boot):
    the end of one life is not joined to the power-up pose of the next."""
    seq = np.array([0, 2, 4, 6, 0, 2, 4])
    out = plots.broken(np.arange(7.0), seq)
    assert list(np.flatnonzero(np.isnan(out))) == [4]


def test_figure_lines_do_not_bridge_gaps(gappy: Analysis) -> None:
    """In the drawn figure, the on-board - reference heading line breaks at every gap, and
    shows the unwrapped values."""
    report = {**gappy.report, "inputs": {"errors": "ed=1.002", "faults": "busoff=10:2,seed=1"}}
    figure = plots.build_figure(gappy.series, report, Tolerance())
    try:
        heading_ax = figure.axes[4]  # the time column's fourth row
        assert "reference, heading" in heading_ax.get_title(loc="left")
        lines = heading_ax.get_lines()
        line = max(lines, key=lambda ln: len(np.asarray(ln.get_ydata())))  # not the marks
        y = np.asarray(line.get_ydata(), dtype=float)
        n_gaps = len(plots.break_indices(gappy.series["onboard_seq"]))
        assert n_gaps >= 1
        assert np.count_nonzero(np.isnan(y)) == n_gaps
        finite = y[~np.isnan(y)]
        assert finite == pytest.approx(gappy.series["heading_error_unwrapped_rad"] * 1e3)
        title = figure.get_suptitle()
        assert "errors ed=1.002" in title
        assert "faults busoff=10:2,seed=1" in title
        assert "FAIL" in title
        assert "pmir" in title
        assert "exact integrator" in title
        spans = [p for p in heading_ax.patches]
        assert len(spans) == len(gappy.series["gap_start_t_s"])
    finally:
        plt.close(figure)


def test_title_says_when_inputs_are_unknown(drift: tuple[Analysis, dict[str, np.ndarray]]) -> None:
    report = dict(drift[0].report)
    assert "errors not recorded" in plots.title(report)
    report["inputs"] = {"errors": None, "faults": None}
    assert "errors unknown (a log), faults unknown (a log)" in plots.title(report)
    report["inputs"] = {"errors": "", "faults": ""}
    assert "errors none, faults none" in plots.title(report)


def test_png_under_200_kb(gappy: Analysis, tmp_path: Path) -> None:
    path = tmp_path / "fail.png"
    plots.plot_analysis(gappy, path)
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) < 200_000


def _umbmark_report(scale_m: float) -> dict[str, object]:
    runs = {
        "cw": [(-0.30, -0.37), (-0.31, -0.36)],
        "ccw": [(0.09, -0.08), (0.10, -0.09)],
    }
    out: dict[str, object] = {"side_m": 4.0}
    r = {}
    for direction, points in runs.items():
        xs = [p[0] * scale_m for p in points]
        ys = [p[1] * scale_m for p in points]
        cg = (sum(xs) / 2, sum(ys) / 2)
        r[direction] = math.hypot(*cg)
        out[direction] = {"runs": [{"x_m": x, "y_m": y} for x, y in zip(xs, ys, strict=True)],
                          "cg": {"x_m": cg[0], "y_m": cg[1]}, "r_cg_m": r[direction]}
    out["emax_syst_m"] = max(r.values())
    return out


def test_umbmark_scatter_draws_runs_and_centres(tmp_path: Path) -> None:
    before, after = _umbmark_report(1.0), _umbmark_report(0.01)
    path = tmp_path / "umb.svg"
    plots.plot_umbmark([("before", before), ("after", after)], path, heading="calibrate: test")
    text = path.read_text()
    assert "calibrate: test" in text
    for label in ("c.g. CW", "c.g. CCW", "E_max,syst", "before: 4 m square", "after: 4 m square"):
        assert label in text, label
    png = tmp_path / "umb.png"
    plots.plot_umbmark([("UMBmark", before)], png, heading="UMBmark")
    assert png.read_bytes()[:8] == PNG_MAGIC


def test_reading_the_truth_for_the_plot_does_not_change_the_run(tmp_path: Path) -> None:
    """Same seed, same report, with and without --plot (which reads the sim state every tick)."""
    from odocan.host.cli.app import main

    reports = []
    for extra in ([], ["--plot", str(tmp_path / "p.svg")]):
        path = tmp_path / f"r{len(extra)}.json"
        assert main(["run", "--duration", "4", "--seed", "6", "--errors", "ed=1.01,slip=0.01",
                     "--report", str(path), *extra]) == 0
        data = json.loads(path.read_text())
        for key in ("wall_seconds", "realtime_factor"):
            data.pop(key)
        reports.append(data)
    assert reports[0] == reports[1]


def test_truth_trace_is_decimated_on_long_runs() -> None:
    config = RigConfig(robot=robot.load("pmir"), seed=1)
    rig = LockstepRig(config)
    try:
        trace = TruthTrace(rig, total_ticks=250_000)  # 2.5 x TRUTH_TRACE_MAX
        for _ in range(300):
            rig.step()
            trace.record()
    finally:
        rig.close()
    t = trace.series(0.0)["truth_full_t_s"]
    assert trace.every == 3
    assert len(t) == 100
    assert np.diff(t) == pytest.approx(0.03)
