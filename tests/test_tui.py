"""The monitor's screen (``host.report.tui``): drawn on a fixed 80×24 console from a model fed by
the lockstep rig (healthy, and DEGRADED by a bus-off of the motor controller), the per-page
rates, the trace's filter and pause, ``--log`` read back by python-can, the fleet table's
staleness and order, and its timer.

What the screen must show is checked as text on the exact rows a person sees: the firmware line
and the three pose rows in the first 7 rows, whatever the terminal's size.
"""

from __future__ import annotations

import asyncio
import itertools
import math
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rich.console import Console

from odocan.host.cli.subparsers import monitor as monitor_cmd
from odocan.host.judge.monitor import BusMonitor
from odocan.host.mqtt.broker import BrokerURL, free_loopback_port
from odocan.host.report.live import render_fleet, with_staleness
from odocan.host.report.trace import FrameFilter, PageRates, Trace
from odocan.host.report.tui import SILENCE_S, View, screen
from odocan.host.report.tui_app import FrameLog, MonitorApp
from odocan.sim import robot
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.faults import FaultSpec
from odocan.sim.rig import LockstepRig, RigConfig
from tests.test_cli_run import assert_usage_error, run_cli

_channels = itertools.count()


@dataclass
class Fed:
    """A model and a trace fed by a lockstep run; ``last_s``: the last frame's bus time."""

    model: BusMonitor
    trace: Trace
    last_s: float

    def view(self, *, silent_s: float = 0.0, status_age_s: float = 0.1, **kw: Any) -> View:
        """A view ``silent_s`` after the last frame, the status ``status_age_s`` old."""
        now_s = self.last_s + silent_s
        heard = {name: now_s - s.heard_monotonic_s for name, s in self.model.messages.items()}
        heard["ODOM_STATUS"] = status_age_s + silent_s
        return View(source="udp_multicast:239.255.1.2", interface="udp_multicast", now_s=now_s,
                    started_s=0.0, last_frame_s=self.last_s, heard_s=heard, **kw)


def feed_rig(ticks: int, faults: str = "") -> Fed:
    """Run the lockstep rig ``ticks`` × 10 ms; every host-bus frame goes to a model and a trace.

    The model's clock is the bus time (``now_s=msg.timestamp``), so ages are exact."""
    model = BusMonitor(robot.load("pmir"))
    trace = Trace(model.db)
    last = [0.0]

    class Feed(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            model.feed(msg, now_s=msg.timestamp)
            trace.feed(msg)
            last[0] = msg.timestamp

    config = RigConfig(robot=robot.load("pmir"), seed=2,
                       channel=f"tui-{os.getpid()}-{next(_channels)}",
                       faults=FaultSpec.parse(faults) if faults else None)
    with LockstepRig(config, listeners=[Feed()]) as rig:
        for _ in range(ticks):
            rig.step()
    return Fed(model, trace, last[0])


def draw(fed: Fed, view: View, width: int = 80, height: int = 24) -> list[str]:
    """The screen as the rows of a ``width`` × ``height`` terminal (plain text)."""
    console = Console(width=width, height=height, record=True, color_system=None,
                      force_terminal=False, legacy_windows=False)
    snapshot = fed.model.snapshot(now_s=view.now_s)
    console.print(screen(snapshot, fed.trace, view, width=width, height=height), end="")
    return console.export_text(styles=False).split("\n")[:height]


@pytest.fixture(scope="module")
def healthy() -> Fed:
    return feed_rig(300)


@pytest.fixture(scope="module")
def degraded() -> Fed:
    return feed_rig(160, faults="busoff=1.0:1.0")  # the motor controller off the bus at 1 s


def _pose_cells(snapshot: dict[str, Any], key: str) -> list[str]:
    pose = snapshot[key]
    heading = math.remainder(pose["heading_rad"], math.tau)
    return [f"{pose['x_m']:.4f}", f"{pose['y_m']:.4f}", f"{heading:.4f}"]


def test_healthy_screen_fits_80x24(healthy: Fed) -> None:
    rows = draw(healthy, healthy.view())
    assert len(rows) == 24
    assert all(len(r.rstrip()) <= 80 for r in rows)
    assert rows[0].startswith("odocan monitor udp_multicast:239.255.1.2")
    assert rows[1].startswith("verdict OK")
    assert rows[2].startswith("firmware OK  reason no error bits  age 0.1 s  EXACT  uptime 2 s")
    snapshot = healthy.model.snapshot(now_s=healthy.last_s)
    for row, (label, key) in zip(rows[4:7], (("on-board", "pose"), ("reference", "reference"),
                                              ("truth", "truth")), strict=True):
        assert row.split()[:4] == [label, *_pose_cells(snapshot, key)]
    ref_error_mm = snapshot["error"]["pose_vs_reference"]["dpos_m"] * 1e3
    assert rows[5].split()[4] == f"{ref_error_mm:.3f}"
    assert rows[7].startswith("not checked: none")
    assert rows[8].split()[:3] == ["message", "ID", "frames"]
    assert rows[9].split()[:4] == ["WHEEL_ENCODERS", "0x100", "300", "100.0"]
    assert rows[10].startswith("MOTOR_CMD")
    assert any(r.startswith("trace") for r in rows[11:23])
    assert rows[23].startswith("space/p pause  f filter  q quit")


def test_healthy_screen_shows_the_newest_trace_lines(healthy: Fed) -> None:
    rows = draw(healthy, healthy.view())
    title = next(i for i, r in enumerate(rows) if r.startswith("trace"))
    shown = rows[title + 1:23]
    newest = list(healthy.trace.lines)[-len(shown):]
    for row, line in zip(shown, newest, strict=True):
        assert row.split()[1:3] == [f"{line.arbitration_id:03X}", line.name]


def test_a_larger_terminal_shows_more(healthy: Fed) -> None:
    tall = draw(healthy, healthy.view(), width=100, height=50)
    assert sum(r.startswith(("ODOM_STATUS", "SIM_TRUTH")) for r in tall) == 4  # rates + values
    assert sum(1 for r in tall if "ENC_COUNTER" in r) > 10  # a long trace
    wide = draw(healthy, healthy.view(), width=220, height=24)
    status = next(r for r in wide if r.startswith("ODOM_STATUS"))
    assert "SUMMARY=10" in status
    assert "FRAME_TOTALS=1.67" in status  # page names in full (six pages rotate)
    assert re.search(r" \d+\.\d{3} [0-9A-F]{3} [A-Z_]+ ", status)  # the trace beside the table


def test_degraded_screen_says_why(degraded: Fed) -> None:
    rows = draw(degraded, degraded.view())
    assert rows[2].startswith("firmware DEGRADED  reason ENCODER_TIMEOUT  age 0.1 s")
    assert rows[1].startswith("verdict DEGRADED: firmware reports DEGRADED (ENCODER_TIMEOUT)")
    assert rows[4].split()[0] == "on-board"
    encoders = next(r for r in rows if r.startswith("WHEEL_ENCODERS"))
    assert encoders.split()[2] == "100"  # nothing after the bus-off at 1 s


def test_stale_screen_warns_and_marks_the_firmware(healthy: Fed) -> None:
    rows = draw(healthy, healthy.view(silent_s=5.0))
    assert rows[2].startswith("firmware OK STALE  reason no error bits  age 5.1 s")
    assert rows[7].startswith("nothing heard for 5.0 s since the last frame: the sender stopped")
    assert [r.split()[0] for r in rows[4:7]] == ["on-board", "reference", "truth"]


def test_silence_from_the_start_says_why_per_interface() -> None:
    fed = Fed(BusMonitor(robot.load("pmir")), Trace(BusMonitor(robot.load("pmir")).db), 0.0)
    view = View(source="virtual:vcan0", interface="virtual", now_s=3.0, started_s=0.0)
    rows = draw(fed, view)
    assert rows[2].startswith("firmware no ODOM_STATUS summary yet")
    assert rows[7].startswith("nothing heard for 3.0 s: a python-can virtual bus lives inside")
    view.now_s = SILENCE_S - 0.1
    assert draw(fed, view)[7].startswith("not checked: none")
    view.now_s, view.interface = 3.0, "udp_multicast"
    assert "same group and port" in draw(fed, view, width=200)[7]


def test_events_and_model_staleness_are_shown_when_the_model_gives_them(healthy: Fed) -> None:
    snapshot = healthy.model.snapshot(now_s=healthy.last_s)
    snapshot["status"] = {**snapshot["status"], "stale": True, "age_s": 7.5}
    snapshot["events"] = [{"kind": "reboot", "node": "ODOM_MCU", "uptime_s": 0}]
    console = Console(width=80, height=24, record=True, color_system=None)
    console.print(screen(snapshot, healthy.trace, healthy.view()), end="")
    rows = console.export_text(styles=False).split("\n")
    assert rows[2].startswith("firmware OK STALE  reason no error bits  age 7.5 s")
    assert rows[7].startswith("event: kind reboot node ODOM_MCU uptime_s 0")


def test_page_rates_from_bus_time() -> None:
    pages = PageRates()
    for k in range(40):  # 3 parts heard in the order 2, 0, 1 at 40 Hz in all
        number = (2, 0, 1)[k % 3]
        pages.heard("SIM_TRUTH", number, ("X", "Y", "HEADING")[number], k * 0.025)
    rates = pages.rates_hz("SIM_TRUTH")
    assert [(p.number, p.name) for p in rates] == [(0, "X"), (1, "Y"), (2, "HEADING")]
    for page in rates:
        assert page.rate_hz == pytest.approx(40 / 3)
    assert pages.rates_hz("ODOM_STATUS") == []


def test_page_rates_add_up_to_the_message_rate(healthy: Fed) -> None:
    snapshot = healthy.model.snapshot(now_s=healthy.last_s)
    for name, pages in (("ODOM_STATUS", 7), ("SIM_TRUTH", 3)):
        rates = healthy.trace.pages.rates_hz(name)
        assert [p.number for p in rates] == list(range(pages))
        total = sum(p.rate_hz for p in rates if p.rate_hz is not None)
        assert total == pytest.approx(snapshot["messages"][name]["rate_hz"], rel=0.1)
    status = {p.name: p.number for p in healthy.trace.pages.rates_hz("ODOM_STATUS")}
    assert status["SUMMARY"] == 0
    assert status["FRAME_TOTALS"] == 1  # the DBC's VAL_ table
    assert healthy.trace.pages.rates_hz("SIM_TRUTH")[0].rate_hz == pytest.approx(10.0)
    row = next(r for r in draw(healthy, healthy.view()) if r.startswith("ODOM_STATUS"))
    assert "SUMMARY=10 p1=1.67 p2=1.67 p3=1.67" in row


def test_filter_by_name_and_id(healthy: Fed) -> None:
    db = healthy.model.db
    only = FrameFilter.parse(["odom_pose_x", "0x380,SIM_TRUTH"], db)
    assert only.names == {"ODOM_POSE_X", "SIM_TRUTH"}
    assert only.ids == {0x380}
    trace = Trace(db, only)
    fed = feed_rig(50)
    for line in fed.trace.lines:
        trace.feed(can.Message(arbitration_id=line.arbitration_id, data=bytes(8),
                               is_extended_id=False))
    assert {line.name for line in trace.lines} <= {"ODOM_POSE_X", "SIM_TRUTH", "ODOM_STATUS"}
    assert {line.arbitration_id for line in trace.lines} == {0x200, 0x380, 0x700}
    for bad in ("NO_SUCH_MESSAGE", "0xZZ"):
        with pytest.raises(ConfigurationError, match="--filter"):
            FrameFilter.parse([bad], db)


def test_pause_freezes_the_trace_and_keys_edit_the_filter(healthy: Fed) -> None:
    model = BusMonitor(robot.load("pmir"))
    app = MonitorApp(can.Bus(interface="virtual", channel=f"tui-keys-{os.getpid()}"), model,
                     Trace(model.db), View(source="x"))
    try:
        frames = [can.Message(arbitration_id=line.arbitration_id, data=bytes(8), timestamp=i,
                              is_extended_id=False)
                  for i, line in enumerate(list(healthy.trace.lines)[-40:])]
        for msg in frames[:10]:
            app.on_frame(msg)
        app.on_keys("p")
        for msg in frames[10:20]:
            app.on_frame(msg)
        assert app.trace.paused
        assert len(app.trace.lines) == 10
        assert app.trace.hidden_while_paused == 10
        assert model.frames_total == 20  # the statistics never pause
        app.on_keys(" fODOM_POSE_YY\x7f\r")
        assert not app.trace.paused
        assert app.trace.filter.names == {"ODOM_POSE_Y"}
        for msg in frames[20:]:
            app.on_frame(msg)
        assert {line.name for line in app.trace.lines} == {"ODOM_POSE_Y"}
        app.on_keys("fNOPE\r")
        assert "NOPE" in app.view.note
        assert app.trace.filter.names == {"ODOM_POSE_Y"}
        app.on_keys("f\x1b")
        assert app.view.editing is None
        app.on_keys("q")
        assert app.quit
    finally:
        app.bus.shutdown()


class _UntilDrained:
    """A bus that ends the app's receive loop (``quit``, as ``q`` does) at its first empty
    ``recv``: every frame of the test is queued before the loop starts."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.app: MonitorApp | None = None

    def recv(self, timeout: float | None = None) -> can.Message | None:
        msg = self.bus.recv(timeout)
        if msg is None and self.app is not None:
            self.app.quit = True
        return msg

    def shutdown(self) -> None:
        self.bus.shutdown()


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_log_records_every_frame_heard(suffix: str, tmp_path: Path, healthy: Fed) -> None:
    """Frames over a real python-can bus pair, received by the app, read back by python-can."""
    channel = f"tui-log-{os.getpid()}-{next(_channels)}"
    receiver, sender = (can.Bus(interface="virtual", channel=channel) for _ in range(2))
    path = tmp_path / f"watch{suffix}"
    model = BusMonitor(robot.load("pmir"))
    sent = [can.Message(arbitration_id=line.arbitration_id, data=bytes(range(k, k + 8)),
                        is_extended_id=False)
            for k, line in enumerate(list(healthy.trace.lines)[-60:])]
    recorder = FrameLog(path)
    try:
        drained = _UntilDrained(receiver)
        app = MonitorApp(drained, model, Trace(model.db), View(source="x"),  # type: ignore[arg-type]
                         recorder)
        drained.app = app
        for msg in sent:
            sender.send(msg)
        # every frame is queued before: the loop ends once the bus is drained (a 0.5 s deadline
        # on the wall clock cut a loaded machine's receiving short); the deadline only bounds it
        app.receive(time.monotonic() + 60.0)
        assert app.quit, "the bus was not drained within 60 s"
    finally:
        recorder.close()
        receiver.shutdown()
        sender.shutdown()
    assert recorder.count == len(sent) == model.frames_total
    back = list(can.LogReader(path))
    assert [(m.arbitration_id, bytes(m.data)) for m in back] == \
        [(m.arbitration_id, bytes(m.data)) for m in sent]


def test_cli_log_and_filter(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                            capsys: pytest.CaptureFixture[str]) -> None:
    from tests.test_cli_monitor import _InterruptingBus

    monkeypatch.setattr(monitor_cmd, "open_bus", lambda args: _InterruptingBus(7))
    path = tmp_path / "seen.asc"
    code, out, err = run_cli(capsys, "monitor", "-i", "virtual", "--log", str(path),
                             "--filter", "0x7FF")
    assert (code, err) == (0, "")
    assert "filter 0x7FF" in out
    assert "log 7 frames to /" in out
    assert len(list(can.LogReader(path))) == 7


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--filter", "NOPE"], ["--filter", "NOPE"]),
        (["--log", "/nonexistent/dir/x.asc"], ["--log", "/nonexistent/dir"]),
        (["--log", "x.txt"], ["--log", ".txt"]),
    ],
)
def test_cli_bad_filter_or_log_is_one_line(argv: list[str], words: list[str],
                                           capsys: pytest.CaptureFixture[str]) -> None:
    from odocan.host.cli.app import main

    assert_usage_error(capsys, main(["monitor", "-i", "virtual", *argv]), *words)


def _fleet_row(dpos_m: float | None, updated_unix_s: float, online: bool = True) -> dict[str, Any]:
    return {"online": online, "pose": {"x_m": 1.0, "y_m": 2.0, "heading_rad": 0.5},
            "error": None if dpos_m is None else {"dpos_m": dpos_m, "dheading_rad": 0.0},
            "status": {"state": "OK", "errors": []}, "rate_hz": 250.0,
            "updated_unix_s": updated_unix_s}


def test_fleet_sorted_by_error_and_stale_marked() -> None:
    now = 1000.0
    fleet = {"robot001": _fleet_row(1e-6, now - 0.5), "robot002": _fleet_row(5e-3, now - 0.2),
             "robot003": _fleet_row(None, now - 0.1), "robot004": _fleet_row(2e-5, now - 10.0),
             "robot005": _fleet_row(1e-3, now - 0.1, online=False)}
    console = Console(width=80, record=True, color_system=None)
    console.print(render_fleet(fleet, source="mqtt://x", elapsed_s=3.0, now_unix_s=now))
    rows = console.export_text(styles=False).splitlines()
    assert "5 robots (1 stale)" in rows[0]
    order = [r.split()[0] for r in rows if r.startswith("robot0")]
    assert order == ["robot002", "robot005", "robot004", "robot001", "robot003"]
    states = {r.split()[0]: r for r in rows if r.startswith("robot0")}
    assert "stale 10s" in states["robot004"]
    assert "offline" in states["robot005"]
    assert " OK " in states["robot001"]
    # the header stays one line at 80 columns: a long broker URL is cut, the counts are kept
    console = Console(width=80, record=True, color_system=None)
    long_url = "mqtts://viewer@broker.fleet.example.org:8883"
    console.print(render_fleet(fleet, source=long_url, elapsed_s=12.6, now_unix_s=now))
    rows = console.export_text(styles=False).splitlines()
    assert "5 robots (1 stale)" in rows[0]
    assert rows[0].rstrip().endswith("…")
    assert rows[1].startswith("robot ")
    # --json carries what the screen marks: the same robots stale, with their age
    marked = with_staleness(fleet, now)
    assert {name for name, row in marked.items() if row["stale"]} == {"robot004"}
    assert marked["robot004"]["age_s"] == 10.0
    assert marked["robot002"]["age_s"] == pytest.approx(0.2)
    assert marked["robot001"]["stale"] is False
    never = with_staleness({"robot006": _fleet_row(None, 0.0)}, now)["robot006"]
    assert never["stale"] is True
    assert never["age_s"] is None  # JSON has no infinity


def test_fleet_view_redraws_on_a_timer_without_messages() -> None:
    """No broker at all: the screen still redraws every REFRESH_S (its clock moves)."""
    watch = monitor_cmd._FleetWatch(BrokerURL.parse(f"mqtt://127.0.0.1:{free_loopback_port()}"),
                                    1.2)
    draws: list[float] = []
    asyncio.run(watch.run(lambda: draws.append(time.monotonic())))
    assert len(draws) >= 2  # the first draw, and at least one from the timer alone
    assert not watch.connected_once


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frames=st.lists(st.tuples(
    st.sampled_from([0x100, 0x110, 0x200, 0x201, 0x380, 0x700, 0x123]) | st.integers(0, 0x7FF),
    st.binary(min_size=0, max_size=8), st.booleans(), st.sampled_from(["", "error", "remote"])),
    max_size=30))
def test_no_frame_stops_the_trace_or_the_screen(
        frames: list[tuple[int, bytes, bool, str]]) -> None:
    """Any ID, length, ID kind, error or remote frame: decoded or shown raw, never raised."""
    model = BusMonitor(robot.load("pmir"))
    trace = Trace(model.db)
    for k, (can_id, data, extended, kind) in enumerate(frames):
        msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=extended,
                          is_error_frame=kind == "error", is_remote_frame=kind == "remote",
                          timestamp=k * 0.01)
        model.feed(msg, now_s=msg.timestamp)
        trace.feed(msg)
    assert len(trace.lines) == len(frames)
    rows = draw(Fed(model, trace, len(frames) * 0.01), View(source="x"))
    assert rows[2].startswith("firmware")


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full on this system")
def test_cli_log_to_a_device_is_refused_before_the_watch(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--log`` linked to /dev/full: refused up front (exit 2, one line naming the path), like
    every output the CLI writes, before any bus is opened."""
    path = tmp_path / "full.log"
    path.symlink_to("/dev/full")
    code, out, err = run_cli(capsys, "monitor", "-i", "virtual", "--log", str(path))
    assert (code, out) == (2, "")
    assert err.startswith(f"error: --log {path}: ")
    assert len(err.strip().splitlines()) == 1
