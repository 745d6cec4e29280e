"""ODOM_TWIST DISTANCE is judged (issue #11, rule 5): a firmware reporting a wrong path length
FAILs in the whole analyze, the streamed analyze and the live monitor; a right one PASSes on long,
reversing, gapped, rebooted drives and odd robots; an independent float64 checker (cantools
decoding, ``math.fsum``) agrees with the judge.

The logs are written directly (``tests/synth_log.py``, ``twist=True``: the firmware's own
``Odometry`` and ``Twist``, DISTANCE rounded as the ECU rounds it); a wrong firmware is the same
with ``distance_of`` changing what it reports.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable
from functools import cache
from pathlib import Path
from typing import Any, cast

import can
import cantools
import numpy as np
import numpy.typing as npt
import pytest
from cantools.database.can import Database
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from odocan.firmware import frames as fr
from odocan.firmware.odometry import Odometry
from odocan.host.io.logs import parse_candump, read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.board import TICK_S
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import RobotProfile, load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.independent_checker import Robot
from tests.synth_log import Synth, synthesize, wandering_drive
from tests.test_judge_campaign import drive as campaign_drive
from tests.test_judge_campaign import profile_of
from tests.test_judge_campaign import robots as campaign_robots

Wrong = Callable[[int, int, Odometry], int]
IntArray = npt.NDArray[np.int64]
# The synthesized drives run at 1 to 3.9 m/s (and 2 m a period for the long one): a kobuki
# bounded at 4 m/s, as before profiles carried a speed (its own 0.7 m/s refuses those steps).
KOBUKI = dataclasses.replace(load("kobuki"), max_wheel_speed_m_s=4.0)
ODD = RobotProfile("odd", 1 << 24, 0.0350000004, 0.0351234567, 0.01, 16)  # nm-inexact radii
SHORT = 3_000  # encoder periods (30 s)


# --- the independent checker: cantools, float64, math.fsum -------------------------------------

_LINE = re.compile(r"\((?P<t>[\d.]+)\) \S+ (?P<id>[0-9A-F]+)#(?P<data>[0-9A-F]*)")


def checker_errors_mm(lines: list[str], robot: RobotProfile) -> list[tuple[float, float]]:
    """Per ODOM_TWIST frame: its DISTANCE (extended against the path) minus the float64 path
    length (mm) of the wheel-axis midpoint over every encoder frame up to the one it names
    (ENC_COUNTER = that frame's COUNTER, the latest such), from the log's first encoder frame,
    restarted where the firmware rebooted (ODOM_STATUS UPTIME going back); and what the
    firmware's published arithmetic allows there (mm): the wire's half mm, its Q48 metres per
    count (one LSB, 2^-48 m, a count) and its Q40 sum (2^-41 m a step), from the life's start."""
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, Database)
    per_count = [2.0 * math.pi * round(r * 1e9) * 1e-9 / robot.counts_per_rev
                 for r in (robot.wheel_radius_left_m, robot.wheel_radius_right_m)]
    half = 1 << (min(robot.counter_bits, 24) - 1)
    path = _Path()
    slack = [0, 0]  # counts and frames since the firmware's start
    path_at: dict[int, tuple[float, float]] = {}  # encoder COUNTER -> path (m), allowed (mm)
    prev: tuple[int, int] | None = None
    uptime = -1
    errors = []
    for line in lines:
        m = _LINE.match(line)
        assert m is not None
        msg = db.get_message_by_frame_id(int(m["id"], 16))
        s = cast("dict[str, Any]", msg.decode(bytes.fromhex(m["data"]), decode_choices=False,
                                              scaling=False))
        if msg.name == "WHEEL_ENCODERS":
            counts = (int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))
            if prev is not None:
                d = [(c - p + half) % (2 * half) - half for c, p in zip(counts, prev, strict=True)]
                path.add(abs(0.5 * (d[0] * per_count[0] + d[1] * per_count[1])))
                slack = [slack[0] + abs(d[0]) + abs(d[1]), slack[1] + 1]
            prev, counter = counts, int(s["COUNTER"])
            path_at[counter] = (path.total(),
                                0.5 + 1e3 * (slack[0] * 2.0**-48 + slack[1] * 2.0**-41))
        elif msg.name == "ODOM_STATUS" and int(s["PAGE"]) == 0:
            if int(s["UPTIME"]) < uptime:  # a reboot, primed on the last frame: from 0 there
                path, slack = _Path(), [0, 0]
                path_at[counter] = (0.0, 0.5)
            uptime = int(s["UPTIME"])
        elif msg.name == "ODOM_TWIST":
            at_m, allowed_mm = path_at[int(s["ENC_COUNTER"])]
            diff = int(s["DISTANCE"]) - at_m * 1e3
            errors.append((diff - 65536 * round(diff / 65536), allowed_mm))
    return errors


class _Path:
    """A running float64 sum, compensated (Neumaier): exact to ~1e-16 of the total."""

    def __init__(self) -> None:
        self.sum = self.carry = 0.0

    def add(self, value: float) -> None:
        total = self.sum + value
        if abs(self.sum) >= abs(value):
            self.carry += (self.sum - total) + value
        else:
            self.carry += (value - total) + self.sum
        self.sum = total

    def total(self) -> float:
        return self.sum + self.carry


def checker_passes(errors: list[tuple[float, float]]) -> bool:
    """The checker's verdict: every DISTANCE within what the firmware's arithmetic allows (and
    a float's hair)."""
    return all(abs(error) <= allowed + 1e-6 for error, allowed in errors)


# --- drives ----------------------------------------------------------------------------------


def reversing(robot: RobotProfile, steps: int, step_m: float, seed: int) -> tuple[IntArray,
                                                                                IntArray]:
    """A wandering drive that backs up now and then (runs of 20 .. 200 periods reversed)."""
    d_left, d_right = wandering_drive(robot, steps, step_m, seed)
    sign = np.ones(steps, dtype=np.int64)
    rng = np.random.default_rng(seed)
    k = 0
    while k < steps:
        run = int(rng.integers(20, 200))
        if rng.random() < 0.4:
            sign[k : k + run] = -1
        k += run
    return d_left * sign, d_right * sign


def _synth(robot: RobotProfile, drive: tuple[IntArray, IntArray], wrong: Wrong | None = None,
           **kw: Any) -> Synth:
    return synthesize(robot, "exact", drive[0], drive[1], twist=True, distance_of=wrong, **kw)


@cache
def short_drive() -> tuple[IntArray, IntArray]:
    return reversing(KOBUKI, SHORT, 0.01, 3)


def off_by(mm: int, from_frame: int = 0) -> Wrong:
    return lambda k, d, odo: d + (mm if k >= from_frame else 0)


def manhattan() -> Wrong:
    """A firmware that counts |dx| + |dy| between its reports instead of |dS|."""
    state = {"x": 0, "y": 0, "sum": 0}

    def report(k: int, d: int, odo: Odometry) -> int:
        state["sum"] += abs(odo.x_q40_m - state["x"]) + abs(odo.y_q40_m - state["y"])
        state["x"], state["y"] = odo.x_q40_m, odo.y_q40_m
        return (state["sum"] * 1000 + (1 << 39)) >> 40
    return report


# --- the three judges on one log ---------------------------------------------------------------


def verdicts(path: Path, robot: RobotProfile, *, speed: int | None = 4000
             ) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """The DISTANCE judgement of the whole analyze, the streamed one (small chunks) and the
    monitor (and the MQTT bridge, its verdict alike) fed the log frame by frame."""
    whole = analyze(read_log(path), robot, max_wheel_speed_mm_s=speed)
    streamed = analyze_file(path, robot, chunk_frames=977, max_wheel_speed_mm_s=speed)
    monitor = BusMonitor(robot)
    bridge = RobotTelemetry("r", Geometry.of(robot), whole.report["integrator"],
                            counter_bits=robot.counter_bits)
    monitor.distance.max_wheel_speed_mm_s = bridge.distance.max_wheel_speed_mm_s = speed
    msg = None
    for msg in can.LogReader(path):
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(msg)
    assert msg is not None
    live = monitor.snapshot(now_s=msg.timestamp)
    live["bridge"] = bridge.status()[1]["distance"]  # the bridge's retained status
    assert live["bridge"]["passed"] == live["distance"]["passed"]
    assert whole.report["onboard_distance_vs_reference"] == streamed[
        "onboard_distance_vs_reference"]
    return whole.report, streamed, live


@pytest.mark.parametrize(("wrong", "name"), [
    (off_by(1), "1 mm from power-up"),
    (off_by(2, 1200), "2 mm from frame 1200"),
    (manhattan(), "|dx| + |dy|"),
])
def test_a_wrong_distance_fails_whole_streamed_and_live(tmp_path: Path, wrong: Wrong,
                                                         name: str) -> None:
    synth = _synth(KOBUKI, short_drive(), wrong)
    path = synth.write(tmp_path / "wrong.log")
    assert not checker_passes(checker_errors_mm(synth.lines(), KOBUKI)), name
    whole, streamed, live = verdicts(path, KOBUKI)
    assert whole["onboard_vs_reference"]["max_position_error_m"] < 1e-4  # the pose is right
    assert not whole["onboard_distance_vs_reference"]["passed"], name
    assert not whole["passed"]
    assert not streamed["passed"]
    assert live["health"]["state"] == "DISTANCE WRONG", live["health"]
    assert not live["distance"]["passed"]


def test_a_right_distance_passes_and_agrees_with_the_checker(tmp_path: Path) -> None:
    synth = _synth(KOBUKI, short_drive())
    errors = checker_errors_mm(synth.lines(), KOBUKI)
    assert checker_passes(errors)
    whole, streamed, live = verdicts(synth.write(tmp_path / "right.log"), KOBUKI)
    judged = whole["onboard_distance_vs_reference"]
    assert judged == {"samples": len(errors), "start": "power-up", "max_excess_m": 0.0,
                      "passed": True}
    assert whole["passed"]
    assert streamed["passed"]
    assert live["health"]["state"] == "OK"
    assert live["distance"]["passed"]
    assert live["distance"]["samples"] == len(errors)


@pytest.fixture(scope="module")
def wrapping_drive() -> tuple[IntArray, IntArray]:
    """80 m straight ahead at 4 cm a period: past DISTANCE's 65.536 m wrap."""
    per_count = 2.0 * math.pi * KOBUKI.wheel_radius_left_m / KOBUKI.counts_per_rev
    d = np.full(2_000, round(0.039 / per_count), dtype=np.int64)
    return d, d.copy()


@pytest.mark.parametrize(("wrong", "name"), [
    (lambda k, d, odo: min(d, 65535), "saturates at 65.535 m instead of wrapping"),
    (lambda k, d, odo: d % 65535, "wraps at 65.535 m"),
    (lambda k, d, odo: d + (65536 - 1 if k > 1800 else 0), "a wrap's 65.536 m less 1 mm"),
])
def test_a_firmware_wrong_at_the_wrap_fails(tmp_path: Path, wrapping_drive: tuple[
        IntArray, IntArray], wrong: Wrong, name: str) -> None:
    right = _synth(KOBUKI, wrapping_drive)
    whole, _, live = verdicts(right.write(tmp_path / "right.log"), KOBUKI)
    assert whole["onboard_distance_vs_reference"]["passed"]
    assert live["distance"]["passed"]
    synth = _synth(KOBUKI, wrapping_drive, wrong)
    assert not checker_passes(checker_errors_mm(synth.lines(), KOBUKI)), name
    whole, streamed, live = verdicts(synth.write(tmp_path / "wrong.log"), KOBUKI)
    assert not whole["onboard_distance_vs_reference"]["passed"], name
    assert not streamed["passed"]
    assert not live["distance"]["passed"]


def test_over_100_km_a_right_distance_passes_and_1_mm_fails(tmp_path: Path) -> None:
    """51 000 periods of 2 m (102 km; faster than any ECU build: no plausibility rule), reversing
    now and then: the judge's exact sum keeps its own error far below the wire's LSB."""
    drive = reversing(KOBUKI, 51_000, 2.0, 5)
    right = _synth(KOBUKI, drive)
    errors = checker_errors_mm(right.lines(), KOBUKI)
    assert checker_passes(errors)
    whole = analyze(read_log(right.write(tmp_path / "long.log")), KOBUKI,
                    max_wheel_speed_mm_s=None).report
    assert whole["onboard_vs_truth"]["distance_travelled_m"] > 100e3
    assert whole["onboard_distance_vs_reference"]["passed"], whole[
        "onboard_distance_vs_reference"]
    wrong = _synth(KOBUKI, drive, off_by(1, 50_000))
    assert not checker_passes(checker_errors_mm(wrong.lines(), KOBUKI))
    report = analyze(read_log(wrong.write(tmp_path / "wrong.log")), KOBUKI,
                     max_wheel_speed_mm_s=None).report
    assert not report["onboard_distance_vs_reference"]["passed"]


def test_an_odd_robot_passes(tmp_path: Path) -> None:
    """2^24 counts/rev, radii not whole nanometres (the firmware runs with them rounded), 1 cm
    wheelbase, 16-bit counters: right PASSes, 1 mm off FAILs."""
    drive = wandering_drive(ODD, SHORT, 0.01, 7)
    right = _synth(ODD, drive)
    assert checker_passes(checker_errors_mm(right.lines(), ODD))
    whole, _, live = verdicts(right.write(tmp_path / "odd.log"), ODD)
    assert whole["onboard_distance_vs_reference"]["passed"]
    assert live["distance"]["passed"]
    wrong = _synth(ODD, drive, off_by(1, 100))
    whole, _, live = verdicts(wrong.write(tmp_path / "wrong.log"), ODD)
    assert not whole["onboard_distance_vs_reference"]["passed"]
    assert not live["distance"]["passed"]


def test_a_reboot_restarts_the_distance(tmp_path: Path) -> None:
    """The firmware's DISTANCE restarts at 0 on a reboot: a right one PASSes; one that keeps
    counting from before the reboot FAILs (its new life starts at power-up, offset 0)."""
    drive = short_drive()
    right = _synth(KOBUKI, drive, reboot_at=1500)
    whole = analyze(read_log(right.write(tmp_path / "reboot.log")), KOBUKI).report
    assert len(whole["reboots"]) == 1
    assert whole["onboard_distance_vs_reference"]["passed"], whole[
        "onboard_distance_vs_reference"]
    before = {"mm": 0}

    def keeps(k: int, d: int, odo: Odometry) -> int:
        if k < 1500:
            before["mm"] = d
        return d + (before["mm"] if k >= 1500 else 0)

    wrong = _synth(KOBUKI, drive, keeps, reboot_at=1500)
    report = analyze(read_log(wrong.write(tmp_path / "kept.log")), KOBUKI).report
    assert not report["onboard_distance_vs_reference"]["passed"]


def test_a_gap_with_reversing_inside_passes(tmp_path: Path) -> None:
    """The log misses 6 encoder frames while the robot reverses inside them: the firmware
    integrated them one by one (sum |dS_i|), the log holds one merged step (|sum dS_i|, less):
    within the gap's path bound, PASS; 2 mm off after it still FAILs."""
    n = SHORT
    d = np.full(n, 40, dtype=np.int64)
    d[1000:1003] = -40  # back 3 periods, forth 3: the merged step over the gap is 0
    drive = (d, d.copy())

    def without_gap(synth: Synth) -> list[str]:  # the logger missed frames 999 .. 1004
        return [line for k, group in enumerate(synth.groups) if not 999 <= k <= 1004
                for line in group]

    right = _synth(KOBUKI, drive)
    path = tmp_path / "gap.log"
    path.write_text("\n".join(without_gap(right)) + "\n")
    whole, _, live = verdicts(path, KOBUKI)
    assert whole["onboard_distance_vs_reference"]["passed"], whole[
        "onboard_distance_vs_reference"]
    assert live["distance"]["passed"]
    wrong = _synth(KOBUKI, drive, off_by(2, 1500))
    path.write_text("\n".join(without_gap(wrong)) + "\n")
    whole, _, _ = verdicts(path, KOBUKI)
    assert not whole["onboard_distance_vs_reference"]["passed"]


@pytest.mark.parametrize("wrong_mm", [0, 2])
def test_across_a_stall(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, wrong_mm: int) -> None:
    """The MCU halted 2 s on a curvy drive (the lockstep rig, our firmware): its first ODOM_TWIST
    after the stall names a backlog frame ENC_COUNTER cannot resolve (left out, as the pose is)
    and it took the frames it missed as one step (its path may grow less there): a right
    DISTANCE PASSes; one 2 mm off from after the stall FAILs, whole, streamed and live."""
    pack = fr.pack_odom_twist
    sent = [0]

    def wrong_pack(counter: int, enc: int, v: int, w: int, distance_mm: int,
                   errors: Any) -> bytes:
        sent[0] += 1
        return pack(counter, enc, v, w, distance_mm + (wrong_mm if sent[0] > 300 else 0), errors)

    monkeypatch.setattr(fr, "pack_odom_twist", wrong_pack)
    messages: list[can.Message] = []
    profile = load("pmir")
    with FaultRig(scenario=get_scenario("random", profile, seed=4, duration_s=60.0)) as rig:
        rig.observers.append(lambda tick, frames: messages.extend(frames))
        rig.halted = lambda k: 500 <= k < 700
        rig.run(1_000 * TICK_S)
    path = tmp_path / "stall.log"
    with can.Logger(str(path)) as log:  # candump text
        for msg in messages:
            log.on_message_received(msg)
    whole, streamed, live = verdicts(path, profile)
    assert whole["events"][0]["kind"] in ("firmware_stall", "encoder_frames_lost_on_board")
    assert whole["onboard_vs_reference"]["max_position_error_beyond_allowance_m"] < 1e-4
    assert whole["onboard_distance_vs_reference"]["passed"] is (wrong_mm == 0)
    assert streamed["onboard_distance_vs_reference"]["passed"] is (wrong_mm == 0)
    assert live["distance"]["passed"] is (wrong_mm == 0)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          phases=[Phase.explicit, Phase.generate])
@given(robot=campaign_robots(), seed=st.integers(0, 2**16), distance_m=st.floats(5.0, 5e3),
       reverse=st.booleans())
def test_the_judge_agrees_with_the_checker_on_drawn_robots(
        robot: Robot, seed: int, distance_m: float, reverse: bool) -> None:
    """Drawn robots (16/32-bit counters, 12 .. 2^24 counts/rev, wheelbase 1 cm .. 2 m, unequal
    radii), drives of 5 m .. 5 km (backing up at times): a right DISTANCE PASSes as the checker
    says, one 1 mm off from frame 200 FAILs as the checker says."""
    profile = profile_of(robot)
    d_left, d_right = campaign_drive(robot, 600, distance_m, seed)
    if reverse:
        sign = np.where((np.arange(600) // 50) % 3 == 2, -1, 1).astype(np.int64)
        d_left, d_right = d_left * sign, d_right * sign
    for wrong in (None, off_by(1, 200)):
        synth = _synth(profile, (d_left, d_right), wrong)
        report = analyze(parse_candump("\n".join(synth.lines()).encode()), profile,
                         max_wheel_speed_mm_s=None).report
        checker = checker_passes(checker_errors_mm(synth.lines(), profile))
        assert checker is (wrong is None)
        assert report["onboard_distance_vs_reference"]["passed"] is checker, (
            robot, report["onboard_distance_vs_reference"])
