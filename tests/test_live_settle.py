"""The live judge settles a starved recorder's encoder frames as the whole log does (issue #11,
one judge; rule 5: a FAIL never blames a correct firmware, a PASS never hides a wrong pose).

The delayed drive (``delay=0.1:15,seed=7``: a frame late on the bus locks the firmware's E2E
window out for up to 15 periods) of kobuki and pmir, right and with ODOM_POSE_X 2 LSB off in
X or HEADING, its log stamped as starved recorders stamp it (``_starved``, recorder seeds
1..8). The whole log's check settles the frames the stamps leave open from the firmware's
poses and ENC_E2E_OK pages (``host.protocol.e2e_evidence``, ``e2e_pages``); the live judge
(the monitor model, and the MQTT bridge) judged each frame when it came and followed the
sender's order after a release. Before (main, 48 captures): every capture's live receiver
took 373 encoder frames (the firmware took 262..266 by the whole log's count), and 5 of the
16 captures of the correct firmware FAILed live (0.15..0.26 mm) while ``analyze`` PASSed
them. Now it holds the frames from one the stamps cannot decide and judges them whole
(``host.judge.livesettle``; the bridge: ``host.mqtt.livehold``): the same frames taken, the
same verdict, the independent checker's (``_checker_errors``); the bridge's samples are the
monitor's.
"""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.livesettle import HOLD_S
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import load
from tests.sweeps import sample
from tests.test_capture_bunched import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    _checker_errors,
    _live_passes,
    _starved,
)
from tests.test_reorder import _off_by_two

FAULTS = "delay=0.1:15,seed=7"
FIRMWARES = [("kobuki", None), ("pmir", None), ("kobuki", "X"), ("pmir", "HEADING")]


@pytest.fixture(scope="module", params=FIRMWARES, ids=[f"{r}-{w or 'right'}" for r, w in FIRMWARES])
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[Path, str, bool]:
    """The delayed drive's lockstep log, its robot, and whether the independent checker finds
    its poses right (within one LSB of position and heading)."""
    robot, wrong = request.param
    log = tmp_path_factory.mktemp("drive") / "drive.log"
    with _off_by_two(wrong):
        main(["run", "--robot", robot, "--duration", "4", "--seed", "3", "--log", str(log),
              "--firmware", "python", "--faults", FAULTS])
    dpos_m, dheading_rad = _checker_errors(log, robot)
    return log, robot, dpos_m <= POSITION_LSB_M and dheading_rad <= HEADING_LSB_RAD


def _monitor(capture: Path, robot: str) -> BusMonitor:
    """The monitor model fed ``capture`` at its stamps, its held frames judged at the end."""
    monitor = BusMonitor(load(robot))
    with can.LogReader(str(capture)) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    monitor.release_held()
    return monitor


def _bridge(capture: Path, robot: str) -> RobotTelemetry:
    """The MQTT bridge's telemetry fed ``capture``, its held frames judged at the end."""
    profile = load(robot)
    bridge = RobotTelemetry("r", Geometry.of(profile), "exact", counter_bits=profile.counter_bits)
    with can.LogReader(str(capture)) as reader:
        for msg in reader:
            bridge.feed(msg)
    bridge.hold.release(ends=True)
    return bridge


@pytest.mark.parametrize("recorder", sample(range(1, 9), 4, [1, 4, 7]))  # tests.sweeps
def test_the_live_judge_takes_the_whole_logs_frames_and_verdict(
        drive: tuple[Path, str, bool], recorder: int, tmp_path: Path) -> None:
    """The monitor and the bridge take the whole log's frames and give its verdict. Before:
    373 frames taken live (monitor and bridge) on every capture; kobuki's right firmware
    FAILed live at recorder seeds 1, 2, 4, 7 and 8 (PASS whole)."""
    log, robot, right = drive
    capture = tmp_path / "capture.log"
    _starved(log, capture, recorder)
    frames = read_log(capture)
    whole_taken = check_frames(frames)[0]["WHEEL_ENCODERS"]["ok"]
    monitor, bridge = _monitor(capture, robot), _bridge(capture, robot)
    assert monitor.e2e.counts()["WHEEL_ENCODERS"]["ok"] == whole_taken
    assert bridge.e2e.counts()["WHEEL_ENCODERS"]["ok"] == whole_taken
    live = _live_passes(capture, robot)
    assert live == analyze(frames, load(robot)).passed == right
    ref, bridged = monitor.tracker.vs_reference, bridge.tracker.vs_reference
    assert (bridged.samples, bridged.max_dpos_m, bridged.max_dheading_rad) == (
        ref.samples, ref.max_dpos_m, ref.max_dheading_rad)  # one judge: the same samples


def test_the_monitor_says_held_while_frames_wait(drive: tuple[Path, str, bool],
                                                 tmp_path: Path) -> None:
    """While frames wait for the evidence the verdict is never OK on frames not judged: HELD,
    with its reason, unless the firmware's own state or a wrong pose found outranks it; the bus
    going quiet for a hold's time judges them (then no HELD)."""
    log, robot, right = drive
    capture = tmp_path / "capture.log"
    _starved(log, capture, 1)
    monitor = BusMonitor(load(robot))
    states = []
    with can.LogReader(str(capture)) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
            health = monitor.health(now_s=msg.timestamp)
            states.append(health["state"])
            if monitor.settle.held:  # the firmware's own state or a finding may outrank it
                assert health["state"] != "OK", health
            if health["state"] == "HELD":
                assert "wait for the firmware's poses and pages" in health["why"][0]
    assert monitor.settle.holds > 0
    assert ("HELD" in states) == right  # a wrong pose found outranks it (POSE WRONG)
    assert monitor.settle.held  # the capture's last frames wait for evidence still
    health = monitor.health(now_s=msg.timestamp + 2 * HOLD_S)  # quiet for two holds' time
    assert not monitor.settle.held
    assert health["state"] != "HELD"
