"""The fleet view never shows OK for a robot whose pose stands wrong (issue #11;
``host.mqtt.fleetview``, ``host.report.live.render_fleet``).

The bridge publishes what its judge found (``status.pose_wrongs.this_life`` while an offset
stands in the pose's current life, ``error.since_last`` when a sample since the previous
``error`` was wrong), but ``odocan monitor --mqtt`` showed the firmware's own state: the pmir of
``test_pose_offset_state`` with X 1.2 LSB off from tick 300 (its latest sample right half the
time, by the pose signals' rounding) read OK in the fleet table. Now its row carries
``this_life`` and ``since_last`` and its state is POSE WRONG; a correct drive stays OK.

Wrong or right by the independent float64 dead reckoning of ``test_pose_offset_state``
(cantools: ``tests.independent_checker``), not by the judges under test.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

from rich.console import Console

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import topics
from odocan.host.mqtt.fleetview import RobotState, apply, fleet_snapshot
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.report.live import render_fleet
from tests.test_pose_offset_state import PMIR, _checker_max_lsb, _drive
from tests.test_stall_bound import _messages

ROBOT = "robot001"


def _fleet(path: Path) -> tuple[dict[str, RobotState], list[dict[str, Any]]]:
    """The bridge's publications of the log folded into a fleet table as a subscriber gets
    them (the retained status at the end); the errors published."""
    bridge = RobotTelemetry(ROBOT, Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits)
    table: dict[str, RobotState] = {}
    errors = []
    for msg in _messages(path):
        for leaf, payload in bridge.feed(msg):
            apply(table, topics.topic(ROBOT, leaf), topics.dumps(payload))
            if leaf == "error":
                errors.append(payload)
    leaf, payload = bridge.status()
    apply(table, topics.topic(ROBOT, leaf), topics.dumps(payload))
    return table, errors


def _state_shown(table: dict[str, RobotState]) -> str:
    console = Console(width=100, record=True, file=io.StringIO())
    console.print(render_fleet(fleet_snapshot(table), source="mqtt://x", elapsed_s=1.0))
    line = next(line for line in console.export_text().splitlines() if ROBOT in line)
    return "POSE WRONG" if "POSE WRONG" in line else line.split()[6]


def test_a_standing_offset_reads_pose_wrong_in_the_fleet(tmp_path: Path) -> None:
    path = _drive(tmp_path, 1.2)
    assert _checker_max_lsb(path) > 1.0  # the premise: the firmware's pose is wrong
    table, errors = _fleet(path)
    assert any("since_last" in e for e in errors)
    row = fleet_snapshot(table)[ROBOT]
    assert row["status"]["state"] == "OK"  # the firmware's own word
    assert row["this_life"]["episodes"] >= 1  # absent before
    assert row["pose_wrong"] is True
    assert _state_shown(table) == "POSE WRONG"  # was OK


def test_a_correct_drive_reads_ok_in_the_fleet(tmp_path: Path) -> None:
    """The guard against a false POSE WRONG (passes before the change too)."""
    path = _drive(tmp_path, 0.0)
    assert _checker_max_lsb(path) <= 1.0
    table, errors = _fleet(path)
    assert not any("since_last" in e for e in errors)
    row = fleet_snapshot(table)[ROBOT]
    assert not row.get("pose_wrong")
    assert row.get("this_life") is None
    assert _state_shown(table) == "OK"


def test_a_wrong_sample_since_the_last_error_reads_pose_wrong() -> None:
    """A batch whose worst sample was wrong (``since_last``), the latest one right."""
    table: dict[str, RobotState] = {}
    apply(table, topics.topic(ROBOT, "status"), topics.dumps({"state": "online", "firmware": {
        "summary": {"error_mask": 0, "state": 1, "integrator": 2, "uptime": 5}}}))
    apply(table, topics.topic(ROBOT, "error"), topics.dumps({
        "pose_vs_reference": {"dpos_m": 1e-5, "dheading_rad": 0.0}, "pose_wrong": False,
        "since_last": {"samples": 51, "wrong": 1, "worst": {"t_s": 1.0, "enc_seq": 7}}}))
    assert fleet_snapshot(table)[ROBOT]["since_last"]["wrong"] == 1
    assert _state_shown(table) == "POSE WRONG"
