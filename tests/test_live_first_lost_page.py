"""The first lost-frames page of a life gets its loss allowance, live and in ``analyze`` alike.

Found under overload: a fleet's loop ran a few ticks 9 periods late before the firmware's first
ODOM_STATUS page of encoder E2E counts (every board then runs the tick as a halted MCU's: its
receive FIFO keeps 3 frames, overruns the rest). That page already counts frames the firmware
lost (ENC_E2E_LOST > 0), so its ENC_E2E_OK falls short of the frames heard: the power-up was not
proven (``analyze`` fitted the start) and the live judge gave the page no allowance (it had no
page before it): the merged steps' 0.11 mm FAILed a correct firmware live while ``analyze``
PASSed it. The firmware counts each frame since its first once, accepted (ENC_E2E_OK) or lost
(ENC_E2E_LOST): their sum proves the power-up too, and the losses counted from 0 on the primed
frame give the first page its allowance.

The proof is independent of ``host.judge``: the test spies the encoder frames that reached the
firmware (its FIFO's survivors), integrates them in float64 (``tests.independent_checker``'s
odometry, cantools decoding) and compares every on-board pose with it: the correct firmware is
right to the LSB, and a firmware 2 LSB off still FAILs both judges.
"""

from __future__ import annotations

import asyncio
import math
from pathlib import Path
from typing import Any, cast

import cantools
import pytest
from cantools.database.can import Database

from odocan.firmware import encoders as fw_encoders
from odocan.firmware import frames as fw_frames
from odocan.host.io.logs import parse_candump
from odocan.host.judge.analysis import analyze
from odocan.host.judge.reference import Geometry
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.mqtt.fleetjudge import judge_robot
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import fleet as sim_fleet
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.contract import DBC_PATH
from odocan.sim.fleet import Batch, Fleet, FleetConfig, frame_fields
from tests.independent_checker import HEADING_LSB_RAD, POSITION_LSB_M, Robot, _Odometry
from tests.overloaded_fleet import LateTicksClock

SEED = 2
# tick k's run starts this many periods late, the rest on time: the firmware's FIFO keeps 3 of
# the 10 frames each late tick finds, so it loses 7, before its first page of E2E counts (frame 37)
LATE_TICKS = {1: 9, 11: 9, 21: 9}
ONE_LATE_TICK = {2: 9}  # 7 frames lost in one run: an allowance below one LSB
DURATION_S = 3.0
WRONG_FROM_SAMPLE = 100  # the wrong firmware: x 2 LSB off from its 100th ODOM_POSE_X (1 s)


class EarlyLateClock(LateTicksClock):
    """The loop ``late_ticks`` late (whole periods by release), else on time."""

    late_ticks: dict[int, int] = LATE_TICKS

    def late(self) -> int:
        return self.late_ticks.get(self.k, 0)


class Checker:
    """Float64 odometry of the encoder frames the firmware received, from (0, 0, 0) at its
    first; each on-board pose compared with it at the frame it names (ENC_COUNTER)."""

    def __init__(self, profile: robot.RobotProfile) -> None:
        db = cantools.database.load_file(str(DBC_PATH))
        assert isinstance(db, Database)
        self.db = db
        p = profile.firmware_params()
        self.odo = _Odometry(Robot(p["counts_per_rev"], p["wheel_radius_left_nm"],
                                   p["wheel_radius_right_nm"], p["wheelbase_nm"],
                                   p["counter_bits"], p["max_wheel_speed_mm_s"]), "exact")
        self.bits = int(p["counter_bits"])
        self.last: tuple[int, int, int] | None = None  # COUNTER, left, right
        self.received = 0
        self.x: dict[str, int] | None = None
        self.errors: list[tuple[float, float]] = []
        self.unnamed = 0  # poses naming another frame than the latest received

    def decode(self, name: str, data: bytes) -> dict[str, int]:
        return cast(dict[str, int], self.db.decode_message(name, data, decode_choices=False,
                                                           scaling=False))

    def encoder(self, data: bytes) -> None:
        s = self.decode("WHEEL_ENCODERS", data)
        frame = (int(s["COUNTER"]), int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))
        if self.last is not None:
            half, span = 1 << (self.bits - 1), 1 << self.bits
            steps = zip(self.last[1:], frame[1:], strict=True)
            self.odo.step(*((b - a + half) % span - half for a, b in steps))
        self.last = frame
        self.received += 1

    def pose(self, name: str, data: bytes) -> None:
        s = self.decode(name, data)
        if self.last is None or int(s["ENC_COUNTER"]) != self.last[0]:
            self.unnamed += 1
            return
        if name == "ODOM_POSE_X":
            self.x = s
            return
        if self.x is None or self.x["ENC_COUNTER"] != s["ENC_COUNTER"]:
            return
        x, y = self.x["X"] * POSITION_LSB_M, s["Y"] * POSITION_LSB_M
        heading = s["TURNS"] * 2 * math.pi + self.x["HEADING"] * HEADING_LSB_RAD
        dh = (heading - self.odo.heading + math.pi) % (2 * math.pi) - math.pi
        self.errors.append((math.hypot(x - self.odo.x, y - self.odo.y), abs(dh)))
        self.x = None

    def right(self) -> bool:
        return max(e for e, _ in self.errors) <= POSITION_LSB_M and \
            max(h for _, h in self.errors) <= HEADING_LSB_RAD


def _drive(monkeypatch: pytest.MonkeyPatch, late_ticks: dict[int, int] = LATE_TICKS) -> tuple[
        RobotTelemetry, str, Checker]:
    """One kobuki of the fleet (the Python firmware) with ``late_ticks``: its bridge's live
    judge, its frames as a candump log, and the checker fed what its firmware received."""
    profile = robot.load("kobuki")
    config = FleetConfig(robots=1, robot=profile, seed=SEED, firmware="python")
    monkeypatch.setattr(EarlyLateClock, "late_ticks", late_ticks)
    monkeypatch.setattr(sim_fleet, "RealTimeClock", EarlyLateClock)
    checker = Checker(profile)
    on_frame = fw_encoders.EncoderInput.on_frame

    def spied(self: fw_encoders.EncoderInput, data: bytes) -> None:
        checker.encoder(bytes(data))
        on_frame(self, data)

    monkeypatch.setattr(fw_encoders.EncoderInput, "on_frame", spied)
    lines: list[str] = []
    names = {fw_frames.ODOM_POSE_X_ID: "ODOM_POSE_X", fw_frames.ODOM_POSE_Y_ID: "ODOM_POSE_Y"}
    with Fleet(config) as fleet:
        telemetry = RobotTelemetry(fleet.names[0], Geometry.of(profile), config.integrator,
                                   counter_bits=profile.counter_bits)

        def on_batch(batch: Batch) -> None:
            for _, frame in batch:
                telemetry.feed_frame(frame)
                t_s, can_id, data = frame_fields(frame)
                lines.append(f"({t_s:.6f}) vcan0 {can_id:03X}#{data.hex().upper()}\n")
                if can_id in names:
                    checker.pose(names[can_id], bytes(data))

        stats = asyncio.run(sim_fleet.run_realtime(fleet, duration_s=DURATION_S,
                                                   on_batch=on_batch))
    assert stats.skipped_releases == sum(late_ticks.values())  # the premise: early, late ticks
    return telemetry, "".join(lines), checker


def _verdicts(telemetry: RobotTelemetry, log: str) -> tuple[dict[str, Any], Any]:
    tracker = telemetry.tracker
    live = judge_robot(tracker.vs_reference, tracker.vs_truth,
                       beyond_allowance_m=tracker.max_beyond_allowance_m)
    offline = analyze(parse_candump(log.encode()), robot.load("kobuki"), "exact")
    return live, offline


def test_a_firmware_that_lost_frames_before_its_first_page_passes_both_judges(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    telemetry, log, checker = _drive(monkeypatch)
    assert len(checker.errors) > 100
    assert checker.unnamed < 10
    assert checker.received < round(DURATION_S / TICK_S)  # the premise: the firmware lost some
    assert checker.right(), max(checker.errors)  # and was right on the frames it had
    live, offline = _verdicts(telemetry, log)
    assert live["verdict"] == "PASS", live["reason"]  # was FAIL: 0.1124 mm, no allowance
    assert offline.report["reference_start"] == "power-up"  # ENC_E2E_OK + ENC_E2E_LOST prove it
    assert offline.passed
    assert telemetry.tracker.allowance_m(0) == 0.0  # the span starts at the primed frame 0
    assert telemetry.tracker.vs_reference.samples >= len(checker.errors) - 2


@pytest.mark.parametrize("chunk_frames", [7, 1 << 20])
def test_the_streamed_analysis_gives_the_first_page_its_allowance_too(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, chunk_frames: int,
) -> None:
    _, log, _ = _drive(monkeypatch)
    path = tmp_path / "late.log"
    path.write_text(log)
    whole = analyze(parse_candump(log.encode()), robot.load("kobuki"), "exact").report
    streamed = analyze_file(path, robot.load("kobuki"), "exact", chunk_frames=chunk_frames)
    assert streamed["reference_start"] == whole["reference_start"] == "power-up"
    assert streamed["onboard_vs_reference"] == pytest.approx(whole["onboard_vs_reference"],
                                                             abs=1e-12)
    assert whole["onboard_vs_reference"]["loss_allowance_m"] > 0.0


@pytest.mark.parametrize(("late_ticks", "x_lsb", "heading_lsb"), [
    (ONE_LATE_TICK, 2, 0),  # the first page's allowance is below one LSB: the position fails
    (LATE_TICKS, 0, 2),  # no allowance for the heading (a function of the counts)
])
def test_a_firmware_2_lsb_off_after_the_lost_frames_still_fails_both_judges(
    monkeypatch: pytest.MonkeyPatch, late_ticks: dict[int, int], x_lsb: int, heading_lsb: int,
) -> None:
    real = fw_frames.pack_odom_pose_x
    sent = [0]

    def off(counter: int, enc: int, x_100um: int, heading_bam16: int, errors: Any) -> bytes:
        sent[0] += 1
        wrong = sent[0] > WRONG_FROM_SAMPLE
        return real(counter, enc, x_100um + x_lsb * wrong,
                    (heading_bam16 + heading_lsb * wrong) & 0xFFFF, errors)

    monkeypatch.setattr(fw_frames, "pack_odom_pose_x", off)
    telemetry, log, checker = _drive(monkeypatch, late_ticks)
    assert not checker.right()  # the premise: 2 LSB off for the checker too
    assert telemetry.tracker.allowance_m() > 0.0  # the first page's span reached it
    live, offline = _verdicts(telemetry, log)
    assert offline.report["reference_start"] == "power-up"
    assert not offline.passed
    assert live["verdict"] == "FAIL", live["reason"]
