"""A correct firmware's log replayed faster (or slower) than recorded: the live judges say what
they say at ``--speed 1`` (issue #11: a FAIL must never blame a correct firmware).

``odocan replay LOG --realtime --speed 4`` sends the frames at their recorded times / 4, and the
receiving interface stamps them as it hears them (udp_multicast and socketcan keep no sender's
time). The live judges read silences from bus time against the encoders' 10 ms cycle, so a
0.5 s bus-off heard in 0.125 s was 12.5 periods long, under the E2E COUNTER's lap of 16: the
COUNTER's step read as 2 periods, not 50, the step after it refused, the frames after it taken
for a counter restart the firmware never made. Measured before ``host.judge.livepace`` (main
a213a680), the monitor model and the bridge's judge fed the trial's kobuki seed 7 20 s
``busoff=10:0.5`` drive at 4x: POSE WRONG 1109.8 mm, DISTANCE 237.9 mm beyond its tolerance
(speed 1: PASS, 0.07 mm), as ``odocan monitor`` said live; with ``babble=200,...,reboot=14``
1004.8 mm at 2x, 998.1 mm at 4x. On this module's 8 s drive (bus-off at 6 s), beyond the
allowance: 112.9 mm, DISTANCE 100.7 mm at 4x; 131.7 mm at 2x; 112.9 mm at 10x.

The judges are fed here as the player delivers: every stamp divided by the speed, plus a
seeded 0..0.3 ms lateness (the player's sleep; kept in bus order). The monitor model
(``BusMonitor.feed``) and the bridge's judge fed as ``host.mqtt.busfeed`` feeds it (each frame
through ``LivePace.stamped``) must PASS the correct drive at every speed, measure the pace within
0.1 %, and FAIL +10 mm on its pose after the bus-off at 4x. A live bus's pace is 1.0 exactly:
its times untouched.
"""

from __future__ import annotations

import math
import random
from pathlib import Path

import can
import pytest

from odocan.host.judge.livepace import PACE_INTERVALS, LivePace
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.busfacts import ENC_CYCLE_S
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.judges_cli import POSE_X, TEN_MM_LSB, both_analyses, correct_drive
from tests.log_edit import raise_raw
from tests.test_edge_tamper import first_pose_after_silence

ROBOT = "kobuki"
DRIVE = ("random", 7, 8, "busoff=6:0.5")  # scenario, seed, duration (s), faults
BUS_OFF = (0.4, 6.0)  # ODOM_POSE_X silent this long (s), ending at or after this time (s)
LATE_S = 3e-4  # the player's lateness: up to this, seeded
SPEEDS = (0.5, 2.0, 4.0, 10.0)
BEYOND_M = 5e-3  # a tamper's FAIL by the position: beyond the allowance by more than this


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The drive, recorded under the tests' watch (``correct_drive``: run PASSes it, every
    step of its firmware within 1/1000 LSB of the float64 check)."""
    return correct_drive(tmp_path_factory.mktemp("speed") / "drive.log", ROBOT, *DRIVE)


def played(log: Path, speed: float) -> list[can.Message]:
    """``log``'s frames as a receiver stamps them under ``replay --realtime --speed``."""
    rng = random.Random(f"{speed}")
    out: list[can.Message] = []
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            t0 = out[0].timestamp if out else msg.timestamp
            heard = t0 + (msg.timestamp - t0) / speed + rng.uniform(0.0, LATE_S)
            msg.timestamp = max(heard, out[-1].timestamp if out else heard)
            out.append(msg)
    return out


def judged(log: Path, speed: float) -> tuple[BusMonitor, RobotTelemetry, LivePace]:
    """The monitor model and the bridge's judge fed ``log`` played at ``speed`` (the bridge's
    frames through its bus feed's pace); the bridge's pace."""
    profile = load(ROBOT)
    monitor = BusMonitor(profile)
    bridge = RobotTelemetry("r", Geometry.of(profile), "exact",
                            counter_bits=profile.counter_bits)
    pace = LivePace(database())
    for msg in played(log, speed):
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(pace.stamped(msg))
    monitor.release_held()
    return monitor, bridge, pace


def test_run_and_both_analyses_pass_it(drive: Path) -> None:
    assert both_analyses(drive) == [0, 0]


def test_at_speed_1_a_live_bus_keeps_its_times(drive: Path) -> None:
    monitor, bridge, pace = judged(drive, 1.0)
    assert monitor.pace.facts.pace == 1.0
    assert pace.facts.pace == 1.0
    for judge in (monitor, bridge):
        assert judge.tracker.wrongs.count == 0
        assert judge.distance.verdict() == []


@pytest.mark.parametrize("speed", SPEEDS, ids=str)
def test_a_replay_at_speed_n_passes_as_at_speed_1(drive: Path, speed: float) -> None:
    """Before: POSE WRONG 112.9 mm, DISTANCE 100.7 mm at 4x; 131.7 mm at 2x (docstring)."""
    at_1 = judged(drive, 1.0)[0].tracker.vs_reference.samples
    monitor, bridge, pace = judged(drive, speed)
    for judge in (monitor, bridge):
        assert judge.tracker.wrongs.count == 0, (speed, judge.tracker.max_beyond_allowance_m)
        assert judge.tracker.max_beyond_allowance_m <= 1e-4, speed
        assert judge.distance.verdict() == [], speed
        assert judge.twist.verdict() == [], speed
    assert monitor.tracker.vs_reference.samples >= 0.99 * at_1, speed  # (10x: one less)
    for measured in (monitor.pace.pace, pace.pace):
        assert measured == pytest.approx(speed, rel=1e-3)
    said = monitor.snapshot(now_s=0.0)["pace"]
    assert said["pace"] == monitor.pace.pace
    # decided after PACE_INTERVALS one-step intervals from the first frame, in bus seconds
    assert said["decided_after_s"] == pytest.approx(PACE_INTERVALS * ENC_CYCLE_S / speed,
                                                    rel=0.1), speed


TAMPERS = ("first after the bus-off", 7.0)  # +10 mm on ODOM_POSE_X from then on


@pytest.mark.parametrize("from_s", TAMPERS, ids=str)
def test_plus_10_mm_still_fails_at_speed_4(drive: Path, tmp_path: Path,
                                           from_s: float | str) -> None:
    at_s = first_pose_after_silence(drive, *BUS_OFF) - 1e-4 if isinstance(from_s, str) else from_s
    tampered = tmp_path / "t.log"
    assert raise_raw(drive, tampered, "ODOM_POSE_X", POSE_X, TEN_MM_LSB, at_s) > 20
    for judge in judged(tampered, 4.0)[:2]:
        assert judge.tracker.wrongs.count > 0, from_s
        assert judge.tracker.max_beyond_allowance_m > BEYOND_M, from_s


RECEIVED_20X = Path(__file__).parent / "files" / "replay_speed20_received.blf"


@pytest.mark.xfail(strict=True, reason=(
    "a replay at --speed 20 heard by udp_multicast (the trial's kobuki 7 busoff=10:0.5 drive, "
    "its first 700 encoder frames as `odocan monitor --log` recorded them, before the bus-off): "
    "the receiver stamps the frames in bursts, one-step intervals of 0.02 to 15 ms (up to 30 "
    "drive periods, beyond the COUNTER's lap of 16, COUNTER contiguous), so the judge reads "
    "silences the drive never had; the monitor model, the pace right (20.26), latches 2 wrong "
    "samples, 0.102 mm at encoder frame 518 and 0.115 mm at 610 (limit 0.1 mm; 1x: 0.0695 mm "
    "at most); which rule turns the read silences into those samples is not traced: the stamps "
    "cannot tell the drive's timing at this pace, so the monitor should say so (UNVERIFIED) "
    "rather than FAIL"))
def test_a_replay_heard_in_bursts_at_speed_20_passes() -> None:
    monitor = BusMonitor(load(ROBOT))
    with can.LogReader(str(RECEIVED_20X)) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    monitor.release_held()
    assert monitor.pace.pace == pytest.approx(20.0, rel=0.02)
    assert monitor.tracker.wrongs.count == 0, monitor.tracker.max_beyond_allowance_m


@pytest.mark.parametrize("step_s", [0.0, -ENC_CYCLE_S / 8])
def test_frames_stamped_alike_or_backwards_keep_finite_times(drive: Path, step_s: float) -> None:
    """A recorder that stamped every frame alike, or whose clock ran backwards: the intervals'
    mean is zero or below, no pace (``LivePace._repace``); the frames keep finite times. Found by
    ``tests/test_host_fuzz.py``: a pace of infinity stamped a frame NaN (0 x inf), and the
    monitor raised ValueError in ``livefill`` on it."""
    pace = LivePace(database())
    with can.LogReader(str(drive)) as reader:
        for k, msg in enumerate(reader):
            msg.timestamp = k * step_s
            assert math.isfinite(pace.stamped(msg).timestamp), k
    assert pace.facts.pace is None or 0.0 < pace.facts.pace < math.inf
