"""The fleet table of ``odocan monitor --mqtt`` draws whatever MQTT brings (house rule 6).

A pose of ``{"x_m": "1"}``, a list, or a JSON integer beyond every float (``1`` and 400 zeros)
under ``odocan/<robot>/`` used to raise while the row was drawn (``format("1", ".4f")``,
``math.isfinite("x")`` in the sort, OverflowError): one message from anyone allowed to publish
stopped the monitor. Such values are drawn as ``-`` and sort with the rows without an error.
"""

from __future__ import annotations

import io
import json
import time

from rich.console import Console

from odocan.host.judge.monitor import to_json
from odocan.host.mqtt.fleetview import RobotState, fleet_snapshot
from odocan.host.report.live import render_fleet

HUGE = b"1" + b"0" * 400


def _row(**fields: object) -> dict[str, object]:
    row: dict[str, object] = {"online": True, "pose": None, "error": None, "status": None,
                              "rate_hz": None, "encoder_hz": None, "updated_unix_s": time.time()}
    row.update(fields)
    return row


def test_the_fleet_table_draws_rows_with_hostile_values() -> None:
    huge = json.loads(HUGE)
    snapshot = {
        "robot001": _row(pose={"x_m": 1.0, "y_m": 2.0, "heading_rad": 0.5},
                         error={"dpos_m": 1e-4, "dheading_rad": 1e-5}, rate_hz=360.0),
        "robot002": _row(pose={"x_m": "1", "y_m": huge, "heading_rad": [1]},
                         error={"dpos_m": "x", "dheading_rad": huge}, rate_hz="fast"),
        "robot003": _row(error={"dpos_m": huge, "dheading_rad": None}),
    }
    console = Console(width=80, record=True, file=io.StringIO())
    console.print(render_fleet(snapshot, source="mqtt://x", elapsed_s=1.0))
    lines = console.export_text().splitlines()
    good = next(line for line in lines if "robot001" in line)
    assert good.split()[1:6] == ["1.0000", "2.0000", "0.5000", "0.1000", "0.0100"]
    for name in ("robot002", "robot003"):
        line = next(line for line in lines if name in line)
        assert "1000000" not in line  # a value beyond every float is not drawn
        assert line.split()[1:6] == ["-"] * 5
    # a sane error sorts first; rows without a usable one after it, by name
    order = [line.split()[0] for line in lines if line.startswith("robot0")]
    assert order == ["robot001", "robot002", "robot003"]


def test_a_hostile_retained_status_or_rate_leaves_the_snapshot_whole() -> None:
    """``monitor --mqtt --json`` builds its rows from retained messages anyone allowed to
    publish can leave: an error mask that is no integer (or beyond every float), an enum that
    is a list, rates that are strings stopped every later monitor with a traceback. Such a
    status is no firmware summary (None) and such a rate is not counted; the rest stays."""
    states = {
        "robot001": RobotState("robot001", status={"state": "online", "firmware": {
            "summary": {"error_mask": 0, "state": 1, "integrator": 2, "uptime": 5}}},
            rates={"hz": {"WHEEL_ENCODERS": 100.0, "ODOM_POSE_X": 50}}),
        "robot002": RobotState("robot002", status={"state": "online", "firmware": {
            "summary": {"error_mask": "x"}}}, rates={"hz": {"WHEEL_ENCODERS": "fast"}}),
        "robot003": RobotState("robot003", status={"firmware": {"summary": {
            "error_mask": json.loads(HUGE)}}}, rates={"hz": {"A": json.loads(b"1e400"),
                                                            "B": json.loads(HUGE), "C": 7}}),
        "robot004": RobotState("robot004", status={"firmware": {"summary": {"state": [1]}}},
                               rates={"hz": [1, 2]}),
        "robot005": RobotState("robot005", status={"firmware": "x"}),
    }
    snapshot = fleet_snapshot(states)
    good = snapshot["robot001"]
    assert good["status"] == {"state": "OK", "integrator": "EXACT", "error_mask": 0,
                              "errors": [], "uptime_s": 5}
    assert (good["rate_hz"], good["encoder_hz"]) == (150.0, 100.0)
    for name in ("robot002", "robot003", "robot004", "robot005"):
        assert snapshot[name]["status"] is None, name
    assert (snapshot["robot002"]["rate_hz"], snapshot["robot002"]["encoder_hz"]) == (None, None)
    assert snapshot["robot003"]["rate_hz"] == 7.0
    assert snapshot["robot004"]["rate_hz"] is None
    assert json.loads(to_json(snapshot))["robot003"]["rate_hz"] == 7.0  # what --json prints
