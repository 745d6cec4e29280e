"""``odocan fleet --foxglove``: a real fleet (two real-time robots, the embedded broker, the
bridge's MQTT telemetry) served as the Foxglove WebSocket protocol, read by a ``websockets``
client that subscribes to every channel and decodes the binary message data (opcode 1,
subscription id u32, log time u64, JSON payload); what it decodes is checked against the
fleet's own JSON report of the same run.
"""

from __future__ import annotations

import asyncio
import json
import math
import socket
import struct
import threading
import time
from pathlib import Path
from typing import Any

import pytest
import websockets

from odocan.host.cli.app import main
from odocan.host.mqtt.foxglove_fleet import FleetFoxglove
from tests.test_cli_run import assert_usage_error
from tests.test_foxglove import MESSAGE_DATA, SUBPROTOCOLS, free_port, heading_of

ROBOTS = ("robot001", "robot002")
FLEET_S = 8.0
MIN_POSES = 10  # of each robot's on-board and reference poses (10 Hz telemetry)
Received = dict[str, list[dict[str, Any]]]


async def _connect(port: int, timeout_s: float) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:  # the fleet starts its broker first, then the server
        try:
            return await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS)
        except OSError:
            if time.monotonic() > deadline:
                raise AssertionError(f"no Foxglove server on port {port}") from None
            await asyncio.sleep(0.1)


def _enough(received: Received) -> bool:
    """Every robot's series the test reads, each with as many messages as it asks for."""
    children = {m["child_frame_id"] for m in received.get("/tf", [])}
    return all(
        len(received.get(f"/{robot}/pose/onboard", [])) >= MIN_POSES
        and len(received.get(f"/{robot}/pose/reference", [])) >= MIN_POSES
        and received.get(f"/{robot}/pose/truth") and received.get(f"/{robot}/errors/reference")
        and {f"{robot}/base_link", f"{robot}/reference_link", f"{robot}/truth_link"} <= children
        for robot in ROBOTS)


async def _collect(port: int, listen_s: float) -> tuple[Received, set[str]]:
    """Subscribe to every channel of the first advertise; decode until ``_enough`` came or
    ``listen_s`` passed (a bound: a loaded machine's fleet publishes later, and a fixed window
    closed before it had)."""
    async with await _connect(port, 30.0) as ws:
        assert json.loads(await ws.recv())["op"] == "serverInfo"
        channels: dict[int, str] = {}
        while not channels:
            message = json.loads(await ws.recv())
            if message["op"] == "advertise":
                channels = {c["id"]: c["topic"] for c in message["channels"]}
        subs = dict(enumerate(channels))
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sub, "channelId": cid} for sub, cid in subs.items()]}))
        received: Received = {}
        end = time.monotonic() + listen_s
        while (left := end - time.monotonic()) > 0:
            try:
                data = await asyncio.wait_for(ws.recv(), left)
            except (TimeoutError, websockets.ConnectionClosed):  # the bound, or the fleet ended
                break
            if isinstance(data, str):
                continue  # a later advertise or status, in JSON
            opcode, sub, _log_ns = struct.unpack_from("<BIQ", data)
            assert opcode == MESSAGE_DATA
            received.setdefault(channels[subs[sub]], []).append(json.loads(data[13:]))
            if _enough(received):
                break
    return received, set(channels.values())


def test_fleet_foxglove_serves_every_robot(tmp_path: Path) -> None:
    port, report_path = free_port(), tmp_path / "fleet.json"
    codes: list[int] = []
    fleet = threading.Thread(target=lambda: codes.append(main([
        "fleet", "-n", str(len(ROBOTS)), "--duration", str(FLEET_S), "--seed", "5",
        "--foxglove", str(port), "--report", str(report_path), "--max-miss-ratio", "1",
    ])), name="fleet")
    fleet.start()
    try:
        received, advertised = asyncio.run(_collect(port, FLEET_S + 30.0))
    finally:
        fleet.join(60)
    assert codes in ([0], [1]), codes
    report = json.loads(report_path.read_text())
    counts = {topic: len(messages) for topic, messages in sorted(received.items())}
    print(f"\n{counts}")
    assert "/tf" in advertised
    children = {m["child_frame_id"] for m in received["/tf"]}
    for robot in ROBOTS:
        assert {f"/{robot}/pose/onboard", f"/{robot}/pose/reference", f"/{robot}/pose/truth",
                f"/{robot}/errors/reference", f"/{robot}/errors/reference_vs_truth"} <= advertised
        onboard = received[f"/{robot}/pose/onboard"]
        assert len(onboard) >= MIN_POSES, robot
        for message in onboard:
            assert message["frame_id"] == "odom"
            position = message["pose"]["position"]
            assert math.isfinite(position["x"])
            assert math.isfinite(position["y"])
            assert abs(heading_of(message["pose"]["orientation"])) <= math.pi + 1e-9
        assert len(received[f"/{robot}/pose/reference"]) >= MIN_POSES
        assert received[f"/{robot}/pose/truth"]
        assert {f"{robot}/base_link", f"{robot}/reference_link", f"{robot}/truth_link"} <= children
        # the error series is the bridge's on-board - reference: within the fleet's own maximum
        errors = [m["position_error_m"] for m in received[f"/{robot}/errors/reference"]]
        assert errors
        worst_m = report["per_robot"][robot]["pose_vs_reference"]["max_dpos_m"]
        assert max(errors) <= worst_m + 1e-12
        assert max(errors) < 1e-3  # quantisation of the on-board pose only


def test_malformed_telemetry_is_skipped_never_raised() -> None:
    live = FleetFoxglove(port=0, robots=["robot001"])
    try:
        live.on_telemetry("robot001", "pose", {"x_m": "1", "y_m": 0.0, "heading_rad": 0.0})
        live.on_telemetry("robot001", "pose", {"x_m": math.nan, "y_m": 0.0, "heading_rad": 0.0})
        live.on_telemetry("robot001", "error", {"pose_vs_reference": [1, 2]})
        live.on_telemetry("robot001", "rates", {"hz": {}})
        live._on_mqtt("odocan/robot001/pose", b"not json")
        live._on_mqtt("elsewhere/robot001/pose", b"{}")
        assert live.published == 0
        live.on_telemetry("robot009", "pose", {"x_m": 1.0, "y_m": 2.0, "heading_rad": 0.5})
        assert live.published == 2  # a new robot's pose and its transform, on new channels
    finally:
        live.close()


def test_fleet_foxglove_on_a_port_in_use_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code = main(["fleet", "-n", "1", "--duration", "1", "--foxglove", str(port)])
    assert_usage_error(capsys, code, "--foxglove", f"127.0.0.1:{port}", "in use")


def test_fleet_foxglove_bad_port_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["fleet", "--foxglove", "70000"])
    assert_usage_error(capsys, code, "--foxglove", "expected a TCP port 0..65535")
