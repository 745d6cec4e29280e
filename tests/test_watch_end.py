"""The ends of a live watch (issues #11/#13; rule 5: a PASS never hides a wrong pose).

* ``odocan bridge`` joining a running firmware publishes what it judged before its first
  connection, and counts no drop for it (before: "telemetry dropped 0 (queue full) + 9 (broker
  away)" with a healthy broker, the poses of the first frames never sent);
* it ends its watch as the fleet does: the frames a hold kept are judged before its last word,
  the retained ``offline`` status, which carries the robot's last status (before: a bare
  ``offline``, the held frames never judged);
* the ODOM_TWIST DISTANCE samples still waiting for the page after their frame at a watch's end
  are judged (before: never; a DISTANCE wrong in the last 0.6-1.8 s passed the monitor);
* ``monitor --require-firmware`` exits 1 on a watch that judged nothing.

The references are independent of the live judges: the whole log's E2E check
(``check_frames``) for the frames taken, the float64 checker of ``tests/test_distance.py``
(cantools, ``math.fsum``-grade sums) for DISTANCE.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from pathlib import Path
from typing import Any

import can
import can.interfaces.virtual
import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.fleetjudge import watched_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import load
from tests.conftest_mqtt import Mosquitto, client, mosquitto  # noqa: F401 (fixture)
from tests.test_capture_bunched import _starved
from tests.test_cli_run import run_cli
from tests.test_distance import (
    KOBUKI,
    _synth,
    checker_errors_mm,
    checker_passes,
    off_by,
    short_drive,
)

ROBOT = "robot001"
FAULTS = "delay=0.1:15,seed=7"  # test_live_settle's delayed drive: holds at a starved capture


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A correct firmware's delayed drive as a starved recorder stamped it (recorder seed 1):
    its last ~400 frames are held by the live judge when the capture ends."""
    folder = tmp_path_factory.mktemp("watchend")
    log, starved = folder / "drive.log", folder / "capture.log"
    main(["run", "--robot", "kobuki", "--duration", "4", "--seed", "3", "--log", str(log),
          "--firmware", "python", "--faults", FAULTS])
    _starved(log, starved, 1)
    return starved


async def _bridge_and_stop(url: BrokerURL, frames: list[can.Message]
                           ) -> tuple[Bridge, int, list[tuple[str, dict[str, Any]]]]:
    """A bridge whose robot's frames all came before its first connection (a running
    firmware's), stopped once it took them in and connected; the poses it published, and what a
    subscriber got, up to the ``offline`` status."""
    with can.Bus(interface="virtual", channel=f"watchend-{time.monotonic_ns()}") as bus:
        endpoint = RobotEndpoint(ROBOT, bus, Geometry.of(load("kobuki")), counter_bits=16)
        bridge = Bridge([endpoint], config=BridgeConfig(broker=url))
        link, plain = bridge.links[0], bridge.links[0].publish
        published = [0]

        def publish(leaf: str, payload: dict[str, Any]) -> None:
            published[0] += leaf == "pose"
            plain(leaf, payload)

        link.publish = publish  # type: ignore[method-assign]
        for start in range(0, len(frames), 64):
            bridge.offer([(0, m) for m in frames[start:start + 64]])
        got: list[tuple[str, dict[str, Any]]] = []
        async with client(url) as sub:
            await sub.subscribe(f"odocan/{ROBOT}/#", qos=1)
            stop = asyncio.Event()
            running = asyncio.create_task(bridge.run(stop=stop))
            async with asyncio.timeout(20):
                while bridge.frames_in < len(frames) or not bridge.links[0].connected.is_set():
                    await asyncio.sleep(0.01)
                await asyncio.sleep(0.3)
                stop.set()
                await running
                async for message in sub.messages:
                    assert isinstance(message.payload, bytes)
                    payload = json.loads(message.payload)
                    got.append((message.topic.value.rsplit("/", 1)[-1], payload))
                    if got[-1][0] == "status" and payload["state"] == "offline":
                        break
    return bridge, published[0], got


def test_the_bridge_publishes_what_it_judged_before_connecting_and_judges_the_hold_at_its_end(
        capture: Path, mosquitto: Mosquitto) -> None:  # noqa: F811
    """Every frame of the capture comes before the bridge's first connection. Before (main):
    ``telemetry_offline`` counted every publication of them (the summary's "+ N (broker
    away)"), none reached the broker, and the ``offline`` status was bare while ~400 frames a
    hold kept were never judged. Now nothing is counted lost, the poses arrive, and the
    ``offline`` status counts the frames the whole log's E2E check takes (1 297)."""
    frames = list(can.LogReader(str(capture)))
    whole = check_frames(read_log(capture))[0]
    taken = sum(v["ok"] for k, v in whole.items() if k != "unknown")
    bridge, published, got = asyncio.run(_bridge_and_stop(mosquitto.url(), frames))
    counters = bridge.counters()
    assert (counters["telemetry_offline"], counters["telemetry_dropped"]) == (0, 0), counters
    poses = [p for leaf, p in got if leaf == "pose"]
    assert len(poses) == published >= 20, (len(poses), published)  # every one, ~4 s at 10 Hz
    offline = got[-1][1]
    assert offline["reason"] == "bridge stopped"
    assert offline["frames_total"] == taken, (offline.get("frames_total"), taken)
    assert offline["pose_wrongs"]["episodes"] == 0  # a correct firmware
    assert offline["distance"]["passed"]
    assert offline["twist"]["passed"]


# --- DISTANCE waiting at the watch's end ---------------------------------------------------


def _monitor_of(frames: list[can.Message], *argv: str,
                capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``odocan monitor -i virtual --json`` hearing ``frames`` (sent at once, their stamps
    kept) and ending its watch."""
    channel = f"watchend-monitor-{time.monotonic_ns()}"

    def send() -> None:
        with can.Bus(interface="virtual", channel=channel, preserve_timestamps=True) as tx:
            deadline = time.monotonic() + 10
            while len(can.interfaces.virtual.channels.get(channel, [])) < 2:
                if time.monotonic() > deadline:
                    return
                time.sleep(0.01)
            for msg in frames:
                tx.send(msg)

    sender = threading.Thread(target=send, name="watchend-sender")
    sender.start()
    try:
        return run_cli(capsys, "monitor", "-i", "virtual", "-c", channel, "--json", *argv)
    finally:
        sender.join()


def test_a_distance_wrong_in_the_watchs_last_twists_fails_the_monitor(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A firmware whose DISTANCE is 2 mm off from its last 30 frames on (0.3 s: no ODOM_STATUS
    page after them): the independent checker finds it wrong, and so does the monitor's end of
    watch. Before (main): the twists waiting for that page were never judged: exit 0, DISTANCE
    passed."""
    drive = short_drive()
    synth = _synth(KOBUKI, drive, off_by(2, len(drive[0]) - 30))
    assert not checker_passes(checker_errors_mm(synth.lines(), KOBUKI))
    frames = list(can.LogReader(str(synth.write(tmp_path / "late.log"))))
    robot = tmp_path / "kobuki4.toml"  # the synthesized drive's speed bound (test_distance)
    robot.write_text(_profile_toml(KOBUKI))
    code, out, err = _monitor_of(frames, "--robot", str(robot), "--duration", "6",
                                 capsys=capsys)
    distance = json.loads(out)["distance"]
    assert code == 1, err
    assert "monitor: FAIL: ODOM_TWIST DISTANCE off" in err, err
    assert not distance["passed"], distance
    assert distance["judged_at_end"] > 0, distance


def test_the_fleets_report_judges_the_twists_waiting_at_its_end(tmp_path: Path) -> None:
    """The same drive through a fleet robot's telemetry: its report's ``distance`` has the
    last twists judged, wrong (before: no ``distance`` in the report, and the bridge's status
    said ``passed`` at the end), and its verdict FAILs on it as the bridge's end verdict does
    (before: PASS, the right pose's, with DISTANCE said beside it; issue #11: the fleet PASSed
    what the bridge FAILed, ``tests/test_reset_then_halt.py``)."""
    drive = short_drive()
    synth = _synth(KOBUKI, drive, off_by(2, len(drive[0]) - 30))
    telemetry = RobotTelemetry(ROBOT, Geometry.of(KOBUKI), "exact",
                               counter_bits=KOBUKI.counter_bits)
    telemetry.distance.max_wheel_speed_mm_s = 4000  # the drive's bound (test_distance)
    for msg in can.LogReader(str(synth.write(tmp_path / "late.log"))):
        telemetry.feed(msg)
    entry = watched_verdict(telemetry, 0, None)
    assert entry["verdict"] == "FAIL", entry  # the pose is right, DISTANCE wrong
    assert entry["reason"].startswith("ODOM_TWIST DISTANCE off"), entry
    assert not telemetry.status()[1]["distance"]["passed"]  # (the retained status's)
    assert not entry["distance"]["passed"], entry["distance"]


def _profile_toml(profile: Any) -> str:
    return "\n".join([
        f'name = "{profile.name}4"', f"counts_per_rev = {profile.counts_per_rev}",
        f"wheel_radius_left_m = {profile.wheel_radius_left_m!r}",
        f"wheel_radius_right_m = {profile.wheel_radius_right_m!r}",
        f"wheelbase_m = {profile.wheelbase_m!r}", f"counter_bits = {profile.counter_bits}",
        f"max_wheel_speed_m_s = {profile.max_wheel_speed_m_s!r}", ""])


# --- monitor --require-firmware ----------------------------------------------------------


@pytest.mark.parametrize("require", [False, True])
def test_a_watch_that_heard_no_firmware_fails_only_when_required(
        require: bool, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bus of foreign frames only: the recorder (``--log``) keeps working and exits 0 as
    before; with ``--require-firmware`` the watch judged nothing and exits 1, saying why
    (before: no such check, NO FIRMWARE exited 0)."""
    frames = [can.Message(arbitration_id=0x7FF, data=b"\x00", is_extended_id=False,
                          timestamp=k * 0.01) for k in range(20)]
    log = tmp_path / "foreign.log"
    argv = ["--duration", "1", "--log", str(log), *(["--require-firmware"] * require)]
    code, out, err = _monitor_of(frames, *argv, capsys=capsys)
    assert json.loads(out)["health"]["state"] == "NO FIRMWARE"
    assert len(read_log(log)) == 20  # recorded either way
    if require:
        assert code == 1, err
        assert err == ("monitor: FAIL: no firmware heard (no cyclic ODOM_MCU message): "
                       "nothing judged (--require-firmware)\n"), err
    else:
        assert (code, err) == (0, "")
