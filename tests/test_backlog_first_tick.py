"""A correct firmware whose first tick integrates a backlog (issue #11: a FAIL must never blame a
correct firmware; a pose 10 mm off must FAIL), made deterministic from lockstep drives
(``tests.backlog_drive``): the new firmware's bus open 0.47..0.7 s before its first tick, its
32-slot mailbox keeping the oldest 32 encoder frames and dropping the rest, its first pose
naming frame prime + 31 by ENC_COUNTER, one or two COUNTER laps before the newest of that
COUNTER; it says DEGRADED (POSE_UNCERTAIN) itself for the steps it merged after.

Two shapes, as the two captured logs (``/work/findings/backlog_first_tick_b5.log``, ``_c2``):

* ``reboot``: a firmware killed at 3 s, a new one's bus open at 4 s, its first tick at 4.7 s,
  that tick's Y half, twist and summary 12.7 ms after its X (``first_tick_late``; b5: 17.7 ms).
  Before (main): ``analyze`` whole and streamed FAIL the correct firmware (pmir and kobuki:
  ``lapfirst`` found no Y half within a 10 ms cycle of the X and left the first pose on the
  newest frame of its COUNTER, two laps late; b5: 58.8 mm, DISTANCE 59.6 mm); the live judges
  PASS (their rule reads the heading alone).
* ``power_up``: the recorder started before the firmware, whose bus opened at 0.24 s, its
  first tick at 0.71 s: it primed on encoder frame 24 of the log, not on the log's first, and
  ``lapfirst`` looked for the laps from (0, 0, 0) at frame 0 only. Before: every judge FAILs it
  (pmir: 79.7 mm, 78.5 mrad and DISTANCE 79.2 mm off; c2: 81.1 mm, DISTANCE 21.5 mm); now
  ``analyze`` whole and streamed PASS (``host.judge.primedlap``); the live judges are pinned
  (xfail): their first-pose rule (``livelapfirst``) still starts at the first frame heard.
"""

from __future__ import annotations

import math
from pathlib import Path

import can
import pytest

from odocan.host.mqtt.endverdict import end_verdict
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import load
from tests.backlog_drive import POWER_UP, REBOOT, Backlog, backlog_drive, first_tick_late
from tests.dbc_typed import load_can_dbc, numbers
from tests.independent_checker import HEADING_LSB_RAD, POSITION_LSB_M
from tests.judges_cli import STREAMS, analyze, fails_by_position, live_judges, raise_x_10_mm

SHAPES = {"reboot": REBOOT, "power_up": POWER_UP}
ROBOTS = ("pmir", "kobuki")
LOGS = [f"{shape}_{robot}" for shape in SHAPES for robot in ROBOTS]
MAILBOX_FRAMES = 32  # the Python firmware's mailbox: its first tick took 32 encoder frames
LIVE_XFAIL = pytest.mark.xfail(strict=True, reason=(
    "power-up with a backlog, the firmware primed on the log's frame 24: the monitor POSE "
    "WRONG and the bridge FAIL, 79.7 mm / 78.5 mrad off (pmir), 80.0 mm / 80.5 mrad (kobuki) "
    "at 0.79 s: livelapfirst tells the first pose's lap from (0, 0, 0) at the first frame "
    "heard, primedlap's search is analyze's only"))


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Each shape's drive on each robot; the reboot's with its first tick's halves late."""
    out: dict[str, Path] = {}
    work = tmp_path_factory.mktemp("backlog")
    for shape, backlog in SHAPES.items():
        for robot in ROBOTS:
            log = work / f"{shape}_{robot}.log"
            watch = backlog_drive(log, backlog, robot)
            assert watch.steps > 500
            assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)
            if shape == "reboot":
                late = work / f"{shape}_{robot}_late.log"
                assert first_tick_late(log, late, backlog.first_tick * 0.01 + 0.001) >= 3
                log = late
            out[f"{shape}_{robot}"] = log
    return out


def _encoders_and_first_pose(log: Path, after_s: float) -> tuple[
        list[tuple[float, int, int, int]], dict[str, float]]:
    """The log's WHEEL_ENCODERS (time, COUNTER, LEFT, RIGHT) and the first ODOM_POSE_X, Y and
    ODOM_TWIST heard after ``after_s``, decoded by cantools."""
    db = load_can_dbc(DBC_PATH)
    enc: list[tuple[float, int, int, int]] = []
    pose: dict[str, float] = {}
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            name = db.get_message_by_frame_id(msg.arbitration_id).name
            s = numbers(db, msg.arbitration_id, msg.data)
            if name == "WHEEL_ENCODERS":
                enc.append((msg.timestamp, int(s["COUNTER"]), int(s["LEFT_COUNT"]),
                            int(s["RIGHT_COUNT"])))
            elif msg.timestamp > after_s and name == "ODOM_POSE_X" and "x" not in pose:
                pose |= {"x": float(s["X"]), "heading": float(s["HEADING"]),
                         "enc_counter": float(s["ENC_COUNTER"])}
            elif msg.timestamp > after_s and name == "ODOM_POSE_Y" and "y" not in pose:
                pose |= {"y": float(s["Y"]), "turns": float(s["TURNS"])}
    return enc, pose


def _float64_from(enc: list[tuple[float, int, int, int]], prime: int, named: int,
                  robot: str) -> tuple[float, float, float]:
    """(0, 0, 0) at encoder frame ``prime`` carried to frame ``named`` in plain float64 (the
    exact arc), the counts' differences taken modulo the robot's wire counter."""
    p = load(robot).firmware_params()
    wrap = 1 << min(load(robot).counter_bits, 24)
    m_l = 2 * math.pi * p["wheel_radius_left_nm"] * 1e-9 / p["counts_per_rev"]
    m_r = 2 * math.pi * p["wheel_radius_right_nm"] * 1e-9 / p["counts_per_rev"]
    b = p["wheelbase_nm"] * 1e-9
    x = y = h = 0.0
    for (_, _, l0, r0), (_, _, l1, r1) in zip(enc[prime:named], enc[prime + 1:named + 1],
                                              strict=True):
        dl = ((l1 - l0 + wrap // 2) % wrap - wrap // 2) * m_l
        dr = ((r1 - r0 + wrap // 2) % wrap - wrap // 2) * m_r
        ds, dth = (dl + dr) / 2, (dr - dl) / b
        if abs(dth) < 1e-6:
            x, y = x + ds * math.cos(h + dth / 2), y + ds * math.sin(h + dth / 2)
        else:
            x += ds / dth * (math.sin(h + dth) - math.sin(h))
            y -= ds / dth * (math.cos(h + dth) - math.cos(h))
        h += dth
    return x, y, h


@pytest.mark.parametrize("name", LOGS)
def test_the_first_pose_is_the_backlogs_own(logs: dict[str, Path], name: str) -> None:
    """The firmware primed on the frame of its bus's opening tick and its first pose is that
    frame's (0, 0, 0) carried over the 31 frames its mailbox kept, in float64 within an LSB;
    it names that frame, a COUNTER lap or more before the newest of its ENC_COUNTER."""
    robot = name.rsplit("_", 1)[1]
    backlog: Backlog = SHAPES["power_up" if name.startswith("power_up") else "reboot"]
    enc, pose = _encoders_and_first_pose(logs[name], backlog.first_tick * 0.01)
    prime = next(i for i, e in enumerate(enc) if e[0] >= backlog.start_tick * 0.01 - 1e-9)
    named = prime + MAILBOX_FRAMES - 1
    assert int(pose["enc_counter"]) == enc[named][1]
    newest = max(i for i, e in enumerate(enc) if e[0] < backlog.first_tick * 0.01 + 1e-9
                 and e[1] == enc[named][1])
    assert newest - named >= 16, (newest, named)
    x, y, h = _float64_from(enc, prime, named, robot)
    assert abs(pose["x"] - x) <= POSITION_LSB_M
    assert abs(pose["y"] - y) <= POSITION_LSB_M
    heading = pose["heading"] + 2 * math.pi * pose["turns"]
    assert abs(math.remainder(heading - h, 2 * math.pi)) <= HEADING_LSB_RAD


@pytest.mark.parametrize("name", LOGS)
@pytest.mark.parametrize("stream", STREAMS)
def test_analyze_passes_the_correct_firmware(logs: dict[str, Path], name: str,
                                             stream: str) -> None:
    assert analyze(logs[name], stream) == 0


@pytest.mark.parametrize("name", [
    pytest.param(n, marks=LIVE_XFAIL) if n.startswith("power_up") else n for n in LOGS])
def test_the_live_judges_pass_the_correct_firmware(logs: dict[str, Path], name: str) -> None:
    """The monitor at most DEGRADED (the firmware's own POSE_UNCERTAIN: it merged the steps its
    mailbox dropped) and the bridge PASS, the pose within its allowance."""
    monitor, bridge = live_judges(name.rsplit("_", 1)[1], logs[name])
    bridge.end_watch()
    assert monitor.health(monitor.bus_time_s)["state"] in ("OK", "DEGRADED")
    assert end_verdict(bridge).verdict == "PASS"
    for judge in (monitor, bridge):
        assert judge.tracker.max_beyond_allowance_m <= POSITION_LSB_M


@pytest.mark.parametrize("name", LOGS)
def test_x_10_mm_off_fails_in_every_judge(logs: dict[str, Path], name: str,
                                          tmp_path: Path) -> None:
    """X raised 10 mm from a second after the first tick on: analyze whole and streamed FAIL
    by the position, the live judges see it beyond the allowance."""
    backlog = SHAPES["power_up" if name.startswith("power_up") else "reboot"]
    tampered = tmp_path / "tampered.log"
    assert raise_x_10_mm(logs[name], tampered, backlog.first_tick * 0.01 + 1.0) > 100
    assert fails_by_position(tampered, tmp_path) == []
    monitor, bridge = live_judges(name.rsplit("_", 1)[1], tampered)
    bridge.end_watch()
    assert monitor.health(monitor.bus_time_s)["state"] != "OK"
    assert end_verdict(bridge).verdict != "PASS"
    for judge in (monitor, bridge):
        assert judge.tracker.max_beyond_allowance_m > 9e-3
