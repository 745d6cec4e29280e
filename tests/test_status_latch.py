"""Sticky errors latched (issue #11, ``host.judge.statuslatch``): every ERROR_MASK bit newly set
and every STATE change the host sees in ODOM_STATUS summaries becomes an event with its time and
name, in the monitor model (``firmware_events``), on MQTT (the bridge's retained ``status``:
``events``, ``latched_errors``) and in the ``analyze`` report (whole and streamed), so a short
DEGRADED (TIME_LOST lasts 50 ms, the summary goes out every 100 ms) is never lost.

The expected times come from the test's own decoding of the summaries with cantools (not the
host's decoders); the case is a stall of the firmware in the lockstep rig
(``tests/test_health_rig.run_stall``), and the same frames with every summary that says
DEGRADED taken out (a summary the host missed): the sticky bit still tells it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.io.frames import to_message
from odocan.host.io.logs import FrameArrays, FrameCollector, read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.mqtt.topics import TELEMETRY_LEAVES
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.test_forged_pairing import RecordingWatch, written
from tests.test_health_rig import run_stall

PMIR = load("pmir")
DB = database()
STATUS = DB.get_message_by_name("ODOM_STATUS")
TIME_LOST_BIT = 7  # the DBC's ERROR_MASK comment: bit 7 TIME_LOST


def _stall_frames(monkeypatch: pytest.MonkeyPatch) -> FrameArrays:
    """Every frame of a 13-tick stall of the MCU at 5 s (then 3 s more)."""
    collector = FrameCollector()
    monkeypatch.setattr(RecordingWatch, "collector", collector)
    monkeypatch.setattr("tests.test_health_rig.Watch", RecordingWatch)
    _, figures = run_stall(13)
    assert figures["periods_lost"] == 13
    return collector.arrays()


def _decoded(msg: can.Message) -> dict[str, Any]:
    """An ODOM_STATUS frame's raw signals, decoded with cantools."""
    signals = DB.decode_message(msg.arbitration_id, bytes(msg.data), decode_choices=False)
    assert isinstance(signals, dict)
    return signals


def _summaries(messages: list[can.Message]) -> list[tuple[float, dict[str, Any]]]:
    """(bus time, signals) of every ODOM_STATUS summary, decoded with cantools."""
    status = [(m.timestamp, _decoded(m)) for m in messages if m.arbitration_id == STATUS.frame_id]
    return [(t, s) for t, s in status if s["PAGE"] == 0]


def _first_time_lost_s(messages: list[can.Message]) -> float:
    return next(t for t, s in _summaries(messages)
                if int(s["ERROR_MASK"]) >> TIME_LOST_BIT & 1)


def _time_lost(events: list[dict[str, Any]]) -> list[float]:
    return [e["t_s"] for e in events if e["kind"] == "error_bit" and e["bit"] == "TIME_LOST"]


def _without_degraded(messages: list[can.Message]) -> list[can.Message]:
    """``messages`` less every summary that says DEGRADED (STATE 2)."""
    degraded = {id(m) for m in messages if m.arbitration_id == STATUS.frame_id
                and (s := _decoded(m))["PAGE"] == 0 and s["STATE"] == 2}
    assert degraded  # the stall made the firmware say DEGRADED
    return [m for m in messages if id(m) not in degraded]


@pytest.mark.parametrize("drop_degraded", [False, True])
def test_a_stall_leaves_a_time_lost_event_live_on_mqtt_and_in_the_report(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, drop_degraded: bool
) -> None:
    frames = _stall_frames(monkeypatch)
    messages = [to_message(frames, i) for i in range(len(frames))]
    if drop_degraded:
        messages = _without_degraded(messages)
        kept = FrameCollector()
        for msg in messages:
            kept.on_message_received(msg)
        frames = kept.arrays()
    assert all(s["STATE"] != 2 for _, s in _summaries(messages)) == drop_degraded
    want_s = _first_time_lost_s(messages)
    monitor = BusMonitor(PMIR, "exact")
    bridge = RobotTelemetry("r1", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits)
    published = []
    for msg in messages:
        monitor.feed(msg, now_s=msg.timestamp)
        published += bridge.feed(msg)
    health = monitor.health(messages[-1].timestamp)
    assert _time_lost(health["firmware_events"]) == [pytest.approx(want_s, abs=1e-9)]
    states = [e["state"] for e in health["firmware_events"] if e["kind"] == "state"]
    assert states == ([] if drop_degraded else ["DEGRADED", "OK"])
    assert "TIME_LOST" in monitor.status["latched_errors"]
    status = bridge.status()[1]  # retained on MQTT: the latest events and every bit seen
    assert _time_lost(status["events"]) == [pytest.approx(want_s, abs=1e-9)]
    assert "TIME_LOST" in status["latched_errors"]
    assert not [leaf for leaf, _ in published if leaf not in (*TELEMETRY_LEAVES, "status")]
    whole = analyze(frames, PMIR, "exact").report
    assert _time_lost(whole["firmware_events"]) == [pytest.approx(want_s, abs=1e-9)]
    log = written(frames, tmp_path / "stall.log")  # its times in whole microseconds
    streamed = analyze_file(log, PMIR, "exact", chunk_frames=257)
    assert streamed["firmware_events"] == analyze(read_log(log), PMIR, "exact").report[
        "firmware_events"]
    assert _time_lost(streamed["firmware_events"]) == [pytest.approx(want_s, abs=1e-6)]
