"""Measured bus load and latency (host.judge.busstats, sim.canbits.LatencyHistogram), and how
``odocan run -b`` and ``odocan analyze -b`` report them."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.io.logs import FrameCollector, read_log
from odocan.host.judge import busstats
from odocan.sim import robot
from odocan.sim.canbits import (
    LATENCY_COARSE_SHIFT,
    LATENCY_EXACT_BITS,
    LATENCY_MAX_BINS,
    LatencyHistogram,
)
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.transport import OdocanBus


def _exact_quantile(values: list[int], fraction: float) -> int:
    """The smallest value with at least ``fraction`` of the values at or below it."""
    ordered = sorted(values)
    k = int(np.ceil(fraction * len(ordered)))
    return ordered[max(k, 1) - 1]


@pytest.mark.parametrize("high", [500, 20_000, 10_000_000])
def test_histogram_max_exact_and_p99_never_understated(high: int) -> None:
    rng = random.Random(high)
    values = [rng.randrange(high) for _ in range(5000)]
    hist = LatencyHistogram()
    for v in values:
        hist.add(v)
    assert hist.count == len(values)
    assert hist.max_bits == max(values)
    p99 = hist.quantile_bits(0.99)
    exact = _exact_quantile(values, 0.99)
    assert exact <= p99 <= max(values)
    width = 1 if exact < LATENCY_EXACT_BITS else 1 << LATENCY_COARSE_SHIFT
    if exact < LATENCY_EXACT_BITS + (LATENCY_MAX_BINS - LATENCY_EXACT_BITS - 1) * width:
        assert p99 - exact < width  # within one bin
    assert len(hist.bins) <= LATENCY_MAX_BINS
    assert hist.quantile_bits(1.0) == max(values)


def test_empty_histogram() -> None:
    assert LatencyHistogram().quantile_bits(0.99) == 0


def test_a_log_s_load_from_a_hand_counted_frame() -> None:
    """ID 0, no data: SOF, ID, RTR, IDE, r0, DLC and CRC-15 are 34 dominant bits (the CRC of zeros
    is zero), stuffed after the 5th, 10th, ... 30th: 6 stuff bits; + 10 tail bits = 50, + 3 IFS."""
    collector = FrameCollector()
    for k in range(4):
        collector.on_message_received(
            can.Message(timestamp=0.001 * (k + 1), arbitration_id=0, is_extended_id=False)
        )
    stats = busstats.from_frames(collector.arrays(), 125_000)
    assert stats.busy_bits == 4 * 53
    assert stats.span_s == pytest.approx(0.004 - (0.001 - 50 / 125_000))  # from the 1st SOF
    assert stats.load == pytest.approx(4 * 53 / 125_000 / stats.span_s)
    assert stats.as_dict()["messages"] == []


def test_the_wire_and_the_log_count_the_same_bits() -> None:
    """A bit-timed run: the busy bits the wire counted equal those recomputed from every frame
    the host heard, and every DBC message's measured maximum is within its R."""
    collector = FrameCollector()
    config = RigConfig(robot=robot.load("pmir"), integrator="exact", scenario="random", seed=3,
                       duration_s=5.0, bitrate=250_000, channel="busstats-wire")
    rig = LockstepRig(config, listeners=[collector])
    assert isinstance(rig.host_bus, OdocanBus)  # no fault injection: the plain in-process bus
    wire = rig.host_bus.timing
    try:
        rig.run(5.0)
    finally:
        rig.close()
    assert wire is not None
    measured = busstats.from_wire(wire, database())
    from_log = busstats.from_frames(collector.arrays(), 250_000)
    assert from_log.frames == measured.frames == len(collector) > 1000
    assert from_log.busy_bits == measured.busy_bits
    assert 111 + 3 <= measured.busy_bits / measured.frames <= 135  # 8-byte standard frames
    assert measured.load is not None
    assert from_log.load is not None
    assert from_log.load == pytest.approx(measured.load, rel=1e-3)
    names = {m.name for m in measured.messages}
    assert {"WHEEL_ENCODERS", "ODOM_POSE_X", "ODOM_STATUS", "SIM_TRUTH"} <= names
    assert measured.within_bounds is True
    for m in measured.messages:
        assert m.bound_us is not None
        assert m.p99_us is not None
        assert m.max_us is not None
        assert 0 < m.p99_us <= m.max_us <= m.bound_us
        assert not m.starved


def _odocan(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "odocan", *args], capture_output=True, text=True, timeout=300
    )


def test_run_and_analyze_report_the_bus(tmp_path: Path) -> None:
    log, run_json, log_json = tmp_path / "r.log", tmp_path / "run.json", tmp_path / "log.json"
    done = _odocan("run", "-b", "500000", "--duration", "5", "--log", str(log),
                   "--report", str(run_json))
    assert done.returncode == 0, done.stderr
    assert "measured load" in done.stdout
    assert "R ms" in done.stdout
    bus = json.loads(run_json.read_text())["bus"]
    assert bus["source"] == "run"
    assert bus["bitrate"] == 500_000
    assert bus["within_bounds"] is True
    assert 0.05 < bus["load"] < 0.15
    rows = {row["name"]: row for row in bus["messages"]}
    assert rows["WHEEL_ENCODERS"]["frames"] == 500
    assert rows["WHEEL_ENCODERS"]["max_latency_us"] <= rows["WHEEL_ENCODERS"]["bound_us"]

    done = _odocan("analyze", str(log), "-b", "500000", "--report", str(log_json))
    assert done.returncode == 0, done.stderr
    logged = json.loads(log_json.read_text())["bus"]
    assert logged["source"] == "log"
    assert logged["messages"] == []
    assert logged["frames"] == bus["frames"] == len(read_log(log))
    assert logged["load"] == pytest.approx(bus["load"], rel=1e-3)


def test_latency_plot(tmp_path: Path) -> None:
    plot = tmp_path / "latency.svg"
    done = _odocan("run", "-b", "250000", "--duration", "2", "--latency-plot", str(plot))
    assert done.returncode == 0, done.stderr
    svg = plot.read_text()
    assert svg.startswith("<?xml")
    assert "WHEEL_ENCODERS" in svg
    assert "250 kbit/s" in svg
    done = _odocan("run", "--duration", "2", "--latency-plot", str(tmp_path / "x.png"))
    assert done.returncode == 2
    assert "needs a bit-timed bus" in done.stderr
    done = _odocan("run", "-b", "250000", "--duration", "2", "--latency-plot",
                   str(tmp_path / "x.pdf"))
    assert done.returncode == 2
    assert "unknown format" in done.stderr
    assert "Traceback" not in done.stderr


def test_no_bus_section_without_a_bitrate(tmp_path: Path) -> None:
    report = tmp_path / "run.json"
    done = _odocan("run", "--duration", "2", "--report", str(report))
    assert done.returncode == 0, done.stderr
    assert "bus" not in json.loads(report.read_text())
    assert "measured load" not in done.stdout


def test_analyze_refuses_a_bitrate_that_is_not_can(tmp_path: Path) -> None:
    done = _odocan("analyze", str(tmp_path / "none.log"), "-b", "300000")
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1].startswith("error:")
    assert "Traceback" not in done.stderr


def test_the_monitor_s_bus_load_over_its_window() -> None:
    """Frames of a known length at a known pace: 53-bit frames (ID 0, no data, see above) every
    1 ms are 53 000 bit/s; at 125 kbit/s a load of 42.4 %; the window forgets older frames."""
    from odocan.host.judge.monitor import BusMonitor

    model = BusMonitor(robot.load("pmir"), bitrate=125_000)
    assert model.snapshot(0.0)["bus_load"]["bits_per_s"] is None
    for k in range(3000):  # 3 s
        model.feed(can.Message(timestamp=0.001 * (k + 1), arbitration_id=0, is_extended_id=False))
    load = model.snapshot(0.0)["bus_load"]
    assert load["frames"] == 1000  # the last second only
    assert load["bits_per_s"] == pytest.approx(53_000, rel=1e-6)
    assert load["load"] == pytest.approx(0.424, rel=1e-6)
    window = busstats.LoadWindow(window_s=1.0, max_frames=10)
    for k in range(100):
        window.add(can.Message(timestamp=0.001 * (k + 1), arbitration_id=0, is_extended_id=False))
    assert window.snapshot(None)["frames"] == 10
    assert window.snapshot(None)["load"] is None
    assert window.bits_per_s() == pytest.approx(53_000, rel=1e-6)  # 9 frames over 9 ms


@pytest.mark.parametrize("bitrate", [500_000, None])
def test_the_monitor_header_shows_the_bus_load(bitrate: int | None) -> None:
    from rich.console import Console

    from odocan.host.judge.monitor import BusMonitor
    from odocan.host.report.trace import Trace
    from odocan.host.report.tui import View, screen

    model = BusMonitor(robot.load("pmir"), bitrate=bitrate)
    config = RigConfig(robot=robot.load("pmir"), seed=1, channel=f"busstats-tui-{bitrate}")

    class Feed(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            model.feed(msg, now_s=msg.timestamp)

    with LockstepRig(config, listeners=[Feed()]) as rig:
        for _ in range(300):
            rig.step()
    snapshot = model.snapshot(now_s=3.0)
    load = snapshot["bus_load"]
    # the rig's traffic: 360 frames/s (the summary's counts), 8-byte standard frames of 111 to
    # 135 bits + 3 IFS
    assert 360 * 114 < load["bits_per_s"] < 360 * 138
    console = Console(width=80, height=24, record=True, color_system=None, force_terminal=False)
    view = View(source="test", interface=None, now_s=3.0, started_s=0.0, last_frame_s=3.0)
    console.print(screen(snapshot, Trace(model.db), view, width=80, height=24), end="")
    header = console.export_text(styles=False).split("\n")[0]
    if bitrate is None:
        assert f"bus {load['bits_per_s'] / 1000:.1f} kbit/s" in header
    else:
        assert load["load"] == pytest.approx(load["bits_per_s"] / bitrate)
        assert f"bus {load['load']:.0%}" in header
