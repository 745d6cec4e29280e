"""Live Foxglove over a real WebSocket: a ``websockets`` client speaks the Foxglove WebSocket
protocol (serverInfo and advertise in JSON, subscribe, then binary message data: opcode 1,
subscription id u32, log time u64, payload) to the ``foxglove-sdk`` server of
``odocan run --foxglove`` and decodes what arrives, compared with the JSON report of the same
run and with cantools' decoding of the same frames.
"""

from __future__ import annotations

import asyncio
import json
import math
import socket
import struct
import threading
from pathlib import Path
from typing import Any

import pytest
import websockets
from websockets.typing import Subprotocol

from odocan.host.cli.app import main
from odocan.host.io.logs import FrameCollector
from odocan.host.judge.analysis import analyze
from odocan.host.report.foxglove import FoxgloveLive
from odocan.sim.pose import wrap_angle
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load

# foxglove-sdk >= 0.2x names the protocol foxglove.sdk.v1; older servers foxglove.websocket.v1
SUBPROTOCOLS = [Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1")]
MESSAGE_DATA = 0x01
PMIR = load("pmir")
Received = dict[str, list[tuple[int, dict[str, Any]]]]


async def _connect(port: int) -> Any:
    for _ in range(100):  # the server may still be starting
        try:
            return await websockets.connect(
                f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS,
            )
        except OSError:
            await asyncio.sleep(0.05)
    raise AssertionError(f"no server on port {port}")


async def _collect(port: int, idle_s: float) -> tuple[Received, dict[str, Any]]:
    """Connect, subscribe to every advertised channel, read until ``idle_s`` of silence."""
    ws = await _connect(port)
    async with ws:
        channels: dict[int, dict[str, Any]] = {}
        info = json.loads(await ws.recv())
        assert info["op"] == "serverInfo"
        while not channels:
            message = json.loads(await ws.recv())
            if message["op"] == "advertise":
                channels = {c["id"]: c for c in message["channels"]}
        topics = {sub: channels[cid]["topic"] for sub, cid in enumerate(channels)}
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sub, "channelId": cid} for sub, cid in enumerate(channels)]}))
        received: Received = {}
        while True:
            try:
                data = await asyncio.wait_for(ws.recv(), idle_s)
            except TimeoutError:
                break
            assert isinstance(data, bytes), data
            opcode, sub, log_time = struct.unpack_from("<BIQ", data)
            assert opcode == MESSAGE_DATA
            received.setdefault(topics[sub], []).append((log_time, json.loads(data[13:])))
    return received, {c["topic"]: c for c in channels.values()}


def collect(port: int, idle_s: float = 1.5) -> tuple[Received, dict[str, Any]]:
    return asyncio.run(_collect(port, idle_s))


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def heading_of(q: dict[str, float]) -> float:
    return 2 * math.atan2(q["z"], q["w"])


@pytest.fixture(scope="module")
def live_drive() -> tuple[Received, dict[str, Any], Any, FrameCollector]:
    """A 3 s lockstep drive served live; what a client received, and every frame."""
    collector = FrameCollector()
    with FoxgloveLive(PMIR, port=0) as live:
        result: dict[str, Any] = {}

        def drive() -> None:
            assert live.wait_for_client(30)
            with LockstepRig(RigConfig(PMIR, "exact", "random", 4), [live, collector]) as rig:
                rig.run(3.0)

        thread = threading.Thread(target=drive)
        thread.start()
        result["received"], result["channels"] = collect(live.port)
        thread.join(30)
        published = live.published
    return result["received"], result["channels"], published, collector


def test_every_published_message_arrives_decoded(
    live_drive: tuple[Received, dict[str, Any], int, FrameCollector],
) -> None:
    received, channels, published, _ = live_drive
    assert sum(len(v) for v in received.values()) == published > 1000
    assert channels["/pose/onboard"]["schemaName"] == "foxglove.PoseInFrame"
    assert channels["/tf"]["schemaName"] == "foxglove.FrameTransform"
    assert channels["/pose/truth"]["encoding"] == "json"
    assert json.loads(channels["/pose/onboard"]["schema"])["title"] == "foxglove.PoseInFrame"
    assert len(received["/pose/onboard"]) == 150  # ODOM_POSE_X/Y at 50 Hz for 3 s
    assert len(received["/pose/truth"]) == 30  # SIM_TRUTH samples at 10 Hz
    children = {m["child_frame_id"] for _, m in received["/tf"]}
    assert children == {"base_link", "reference_link", "truth_link"}


def test_live_poses_agree_with_the_offline_analysis(
    live_drive: tuple[Received, dict[str, Any], int, FrameCollector],
) -> None:
    """The last on-board pose served is the analysis' final pose; the live errors stay within
    the analysis' tolerance of the reference and near its truth errors."""
    received, _, _, collector = live_drive
    analysis = analyze(collector.arrays(), PMIR)
    report = analysis.report
    log_time, last = received["/pose/onboard"][-1]
    final = report["final_onboard_pose"]
    assert last["pose"]["position"] == {"x": final["x_m"], "y": final["y_m"], "z": 0.0}
    assert abs(wrap_angle(heading_of(last["pose"]["orientation"]) - final["heading_rad"])) < 1e-9
    # served at the ODOM_POSE_Y completing the sample, 1 ms after the encoder frame it names
    assert log_time == round(analysis.series["timestamp_s"][-1] * 1e9) + 1_000_000
    ref_errors = [m["position_error_m"] for _, m in received["/errors/reference"]]
    assert len(ref_errors) >= 140
    assert max(ref_errors) <= 1.5 * report["tolerance"]["position_m"]
    truth_errors = [m["position_error_m"] for _, m in received["/errors/truth"]]
    assert max(truth_errors) == pytest.approx(
        report["onboard_vs_truth"]["max_position_error_m"], abs=2e-4
    )


def test_live_signals_are_cantools_decoding(
    live_drive: tuple[Received, dict[str, Any], int, FrameCollector],
) -> None:
    received, _, _, collector = live_drive
    frames = collector.arrays()
    from odocan.sim.contract import database

    db = database()
    encoders = db.get_message_by_name("WHEEL_ENCODERS")
    rows = [i for i in range(len(frames)) if frames.can_id[i] == encoders.frame_id]
    live = received["/can/WHEEL_ENCODERS"]
    assert len(live) == len(rows) == 300
    for (log_time, message), i in zip(live, rows, strict=True):
        expected = db.decode_message(encoders.frame_id, bytes(frames.data[i][:8]))
        assert isinstance(expected, dict)
        assert message["LEFT_COUNT_count"] == expected["LEFT_COUNT"]
        assert message["RIGHT_COUNT_count"] == expected["RIGHT_COUNT"]
        assert log_time == round(float(frames.timestamp_s[i]) * 1e9)


def test_odocan_run_foxglove(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The CLI: serves, waits for the client, drives, reports, stays until the client leaves;
    a frame the live side fails on costs that frame only (the drive and the check go on)."""
    publish = FoxgloveLive.publish
    failed: list[float] = []

    def fail_once(self: FoxgloveLive, msg: Any) -> None:
        if not failed and msg.timestamp >= 1.0:
            failed.append(msg.timestamp)
            raise ValueError("a listener bug")
        publish(self, msg)

    monkeypatch.setattr(FoxgloveLive, "publish", fail_once)
    port = free_port()
    report = tmp_path / "report.json"
    codes: list[int] = []
    argv = ["run", "--duration", "2", "--seed", "1", "--foxglove", str(port), "--report",
            str(report)]
    thread = threading.Thread(target=lambda: codes.append(main(argv)))
    thread.start()
    received, _ = collect(port)
    thread.join(30)
    assert codes == [0]
    final = json.loads(report.read_text())["final_onboard_pose"]
    _, last = received["/pose/onboard"][-1]
    assert last["pose"]["position"] == {"x": final["x_m"], "y": final["y_m"], "z": 0.0}
    assert len(failed) == 1
    assert len(received["/pose/onboard"]) in (99, 100)  # the failed frame may have been a pose


def test_port_in_use_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code = main(["run", "--duration", "1", "--foxglove", str(port)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"error: --foxglove {port}: cannot serve on 127.0.0.1:{port}")
    assert err.count("\n") == 1


def test_bad_port_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--foxglove", "70000"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:")
    assert "70000" in err
    assert err.count("\n") == 1


def test_an_owned_monitor_is_published_not_fed_twice() -> None:
    """``odocan monitor``'s way: its loop feeds its own BusMonitor, then ``publish``es."""
    import can

    from odocan.host.judge.monitor import BusMonitor

    model = BusMonitor(PMIR)
    with FoxgloveLive(PMIR, port=0, monitor=model) as live:

        class Loop(can.Listener):
            def on_message_received(self, msg: can.Message) -> None:
                model.feed(msg)
                live.publish(msg)

        def drive() -> None:
            assert live.wait_for_client(30)
            with LockstepRig(RigConfig(PMIR, "exact", "random", 2), [Loop()]) as rig:
                rig.run(2.0)

        thread = threading.Thread(target=drive)
        thread.start()
        received, _ = collect(live.port)
        thread.join(30)
    assert model.frames_total == len(received["/can/frames"])
    decoded = sum(len(v) for k, v in received.items() if k.startswith("/can/")) - model.frames_total
    assert decoded == model.frames_total  # every frame of this clean drive accepted
    assert len(received["/pose/onboard"]) == 100
    assert model.tracker.pose is not None
    assert received["/pose/onboard"][-1][1]["pose"]["position"]["x"] == model.tracker.pose.x_m


def test_realtime_without_foxglove_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--duration", "1", "--realtime"]) == 2
    assert capsys.readouterr().err == (
        "error: --realtime paces the drive for --foxglove: give --foxglove\n"
    )


def test_realtime_waits_for_each_frames_simulated_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """The pacing, on a fake clock: each frame waits until its timestamp after the first."""
    import can


    clock = [100.0]
    sleeps: list[float] = []

    def sleep(seconds: float) -> None:
        sleeps.append(seconds)
        clock[0] += seconds

    monkeypatch.setattr("time.monotonic", lambda: clock[0])
    monkeypatch.setattr("time.sleep", sleep)
    with FoxgloveLive(PMIR, port=0, realtime=True) as live:
        for timestamp_s, work_s in ((5.0, 0.1), (5.25, 0.3), (5.5, 0.0), (6.0, 0.0)):
            live.on_message_received(can.Message(timestamp=timestamp_s, arbitration_id=0x7FF))
            clock[0] += work_s
    # 0.25 s on, less 0.1 s of work; the third frame is already late; the fourth 0.45 s early
    assert sleeps == pytest.approx([0.15, 0.45])


def test_odocan_monitor_foxglove_serves_what_it_hears(monkeypatch: pytest.MonkeyPatch) -> None:
    """``odocan monitor --foxglove``: the monitor's own model, published frame by frame to a
    client, from a live bus fed by a lockstep drive."""
    import can

    from odocan.host.cli.subparsers import monitor as monitor_cmd

    made: list[FoxgloveLive] = []
    real = monitor_cmd._foxglove

    def keep(*args: Any) -> FoxgloveLive | None:
        live = real(*args)
        if live is not None:
            made.append(live)
        return live

    monkeypatch.setattr(monitor_cmd, "_foxglove", keep)
    port, channel = free_port(), f"fox-monitor-{port_suffix()}"
    codes: list[int] = []
    argv = ["monitor", "-i", "odocan", "-c", channel, "--duration", "8", "--json",
            "--foxglove", str(port)]
    monitor = threading.Thread(target=lambda: codes.append(main(argv)))
    monitor.start()
    result: dict[str, Any] = {}

    def listen() -> None:
        result["received"], result["channels"] = collect(port, idle_s=3.0)

    client = threading.Thread(target=listen)
    client.start()
    for _ in range(200):  # the command builds its server first
        if made:
            break
        threading.Event().wait(0.05)
    assert made
    assert made[0].wait_for_client(30)

    class Forward(can.Listener):
        def __init__(self, bus: can.BusABC) -> None:
            self.bus = bus

        def on_message_received(self, msg: can.Message) -> None:
            self.bus.send(msg)

    with can.Bus(interface="odocan", channel=channel) as bus:
        with LockstepRig(RigConfig(PMIR, "exact", "random", 2), [Forward(bus)]) as rig:
            rig.run(2.0)
        client.join(30)
    monitor.join(30)
    assert codes == [0]
    poses = result["received"]["/pose/onboard"]
    assert len(poses) >= 90  # 50 Hz over 2 s of drive, every one published
    assert "/can/WHEEL_ENCODERS" in result["received"]


def port_suffix() -> str:
    import os

    return f"{os.getpid()}-{threading.get_ident()}"
