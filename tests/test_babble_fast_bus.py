"""A babbler on a fast bit-timed bus (issue #11): its burst overflows the firmware's mailbox.

``babble=12000:0x050:2:0.5,seed=0`` on pmir (seed 0): 6000 data frames per second from each
controller on ID 0x050,
below WHEEL_ENCODERS, from 2.0 to 2.5 s. At 1 Mbit/s the babbler's backlog holds the bus until
about 2.7 s; then the encoder frames that waited come out back to back (about 240 us apart), far
faster than the firmware drains its 32-slot mailbox once per 10 ms tick, so the mailbox drops
runs of them, 16 and more in a row. The 4-bit E2E COUNTER cannot count such a run: the next
frame whose COUNTER follows the last accepted one passes E2E as the very next frame.

Before the fix the firmware bounded that step by the periods the COUNTER advance said (1 to 3
periods for what were 17 to 19), refused it as implausible, took the next three frames (plausible
among themselves) for a counter restart (COUNTER_RESET), re-primed on them and never integrated
the distance the dropped frames carried: the pose ended 114 mm from the truth, FAIL. The counts
are absolute, so the step itself is exact: after frames dropped from the mailbox, the step's
plausibility bound is STEP_PERIODS_MAX periods (``EncoderInput.on_frame``).
"""

from __future__ import annotations

import itertools
import json
import math
import random
import subprocess
import sys
import uuid
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorFlag, Reason, State
from odocan.firmware.hal import MAILBOX_SLOTS
from odocan.host.judge.losses import OneSteps, drop_errors, run_errors, worst_runs_m
from odocan.host.judge.samples import Encoders
from odocan.sim.faults import FaultSpec
from odocan.sim.faultspec import two_handles
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests.independent_checker import Robot, _Odometry
from tests.test_babble_firmware import _analyze, _biased_x
from tests.test_ecu import Rig
from tests.test_judge_campaign import profile_of, robots

BABBLE = "babble=12000:0x050:2:0.5,seed=0"  # on the wire
DURATION_S = 6.0


def _firmware_at(bitrate: int) -> tuple[int, int, int]:
    """The firmware's error mask, mailbox overflows and rejected-as-implausible frames after the
    babble drive on a bus of ``bitrate`` bit/s."""
    faults, fw_faults = two_handles(FaultSpec.parse(BABBLE))  # as ``odocan run`` puts it
    config = RigConfig(load("pmir"), channel=f"fastbabble-{uuid.uuid4().hex}", faults=faults,
                       fw_faults=fw_faults, bitrate=bitrate, seed=0)
    with LockstepRig(config, []) as rig:
        for _ in range(round(DURATION_S * 100)):
            rig.step()
        ecu = rig.board.ecu
        return ecu.health.errors.bits, ecu.mailbox.overflows, ecu.encoders.frames_implausible


def test_a_burst_that_overflows_the_mailbox_is_no_counter_restart() -> None:
    errors, overflows, implausible = _firmware_at(1_000_000)
    print(f"\nerrors 0x{errors:x}, mailbox overflows {overflows}, implausible {implausible}")
    assert overflows > 100  # the burst did overflow the mailbox (the case under test)
    assert errors & ErrorFlag.MAILBOX_OVERFLOW
    assert not errors & ErrorFlag.COUNTER_RESET
    assert not errors & ErrorFlag.IMPLAUSIBLE_STEP
    assert implausible == 0


def _run(tmp_path: Path, bitrate: int, robot: str = "pmir") -> tuple[Path, dict[str, Any]]:
    log, report = tmp_path / f"b{bitrate}.log", tmp_path / f"b{bitrate}.json"
    subprocess.run(
        [sys.executable, "-m", "odocan", "run", "-b", str(bitrate), "--robot", robot,
         "--seed", "0", "--duration", str(DURATION_S), "--faults", BABBLE,
         "--log", str(log), "--report", str(report)],
        capture_output=True, text=True, timeout=300, check=False,
    )
    return log, json.loads(report.read_text())


def test_the_correct_firmware_passes_at_1_mbit_and_a_3_lsb_wrong_one_fails(
    tmp_path: Path,
) -> None:
    """Rule 5 both ways on the same drive: PASS, on the truth at the end (it was 114 mm off);
    the same log with every X after the babble began 3 LSB off (CRC recomputed): FAIL."""
    log, report = _run(tmp_path, 1_000_000)
    print(f"\n{report['onboard_vs_reference']}\n{report['onboard_vs_truth']}")
    assert report["passed"] is True
    # 1.8 mm: the babble now reaches the bus (and the firmware) at its own time, not up to a
    # tick late, and the mailbox drops 37 encoder frames, not 19 (loss allowance 1.84 mm)
    assert report["onboard_vs_truth"]["final_position_error_m"] < 3e-3
    wrong = tmp_path / "wrong.log"
    assert _biased_x(log, wrong, lambda k, t: t > 2.0, 3) > 100
    code, wrong_report = _analyze(wrong, tmp_path)
    print(f"wrong: exit {code}, {wrong_report['onboard_vs_reference']}")
    assert code == 1
    assert wrong_report["passed"] is False


def _analyze_as(log: Path, tmp_path: Path, robot: str) -> tuple[int, dict[str, Any]]:
    report_path = tmp_path / f"{log.stem}.json"
    done = subprocess.run(
        [sys.executable, "-m", "odocan", "analyze", str(log), "--robot", robot,
         "--report", str(report_path)],
        capture_output=True, text=True, timeout=300, check=False,
    )
    return done.returncode, json.loads(report_path.read_text())


def _no_stall(report: dict[str, Any]) -> None:
    """The firmware integrated every frame it drained: no stall, the reference never placed
    again; the frames its mailbox dropped are reported and allowed."""
    assert report["samples"]["reference_restarts"] == 0
    assert {e["kind"] for e in report["events"]} == {"encoder_frames_lost_on_board"}


def _after(start_s: float, k: int, t_s: float) -> bool:
    """``_biased_x``'s pick: every frame sent after ``start_s``."""
    return t_s > start_s


def test_at_500_kbit_a_correct_firmware_passes_and_a_wrong_one_fails(tmp_path: Path) -> None:
    """At 500 kbit/s the queued encoder frames come out about 240 us apart, so one ENC_COUNTER
    recurs every 3.8 ms of bus time: the pose the firmware made at 3.41 s named encoder frame 277
    (its mailbox had dropped the later ones) while frame 293 of the same COUNTER was on the bus
    by the time the judge estimated it was made. Paired with 293 it was 32 mm off, a FAIL of a
    correct firmware; now a name that time cannot tell from one 16 frames away is left out.
    ODOM_TWIST was 17 times too fast after mailbox drops (fixed in the firmware, above).

    And the judge took the firmware for stalled: its poses named frame 200 for 1.4 s (queued,
    let out at 3.43 s) and the first one after them came 1.48 s after the first, with 7 encoder
    frames on time just before: the reference's position was placed again at 3.38 s, which
    hid any offset from there on (X 10 mm off from 3.5 s PASSed). Now the silence counts from
    the last pose sent, and only encoder frames that came on time count as heard. The pose is
    within one LSB of the reference beyond the allowance; 3 LSB off from the babble on, and 10 mm
    off from 3.5 s, FAIL."""
    log, report = _run(tmp_path, 500_000)
    print(f"\n{report['onboard_vs_reference']}\n{report['samples']}")
    assert report["passed"] is True
    assert report["onboard_twist_vs_reference"]["passed"] is True
    assert report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"] <= 1e-4
    assert report["onboard_vs_reference"]["max_heading_error_rad"] <= 1e-4
    assert report["samples"]["onboard"] > 200
    _no_stall(report)
    for name, start_s, lsb in (("early", 2.0, 3), ("late", 3.5, 100)):
        wrong = tmp_path / f"{name}.log"
        assert _biased_x(log, wrong, partial(_after, start_s), lsb) > 100
        code, wrong_report = _analyze(wrong, tmp_path)
        print(f"{name}: exit {code}, {wrong_report['onboard_vs_reference']}")
        assert code == 1
        assert wrong_report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"] > (
            lsb * 1e-4 / 2
        )


def test_at_1_mbit_kobuki_passes_on_the_allowance_for_a_run_of_26_lost_frames(
    tmp_path: Path,
) -> None:
    """kobuki at 1 Mbit/s: the mailbox dropped frame 201 and then 25 in a row (247 .. 271), which
    the firmware took as one step: 0.65 mm from the fine reference on its curve, far more than
    the sum of 26 single-frame merge errors (6 um). The judge used to hide it behind a stall
    restart (with any offset after it); the allowance now takes the worst placement of the lost
    frames in runs (``losses.loss_allowance``), from the encoder frame the firmware had when it
    made the status page before (that page was queued: ``losses.firmware_losses``). 3 LSB off
    from the babble on: FAIL."""
    log, report = _run(tmp_path, 1_000_000, "kobuki")
    vs_ref = report["onboard_vs_reference"]
    print(f"\n{vs_ref}\n{report['events']}")
    assert report["passed"] is True
    _no_stall(report)
    assert vs_ref["max_position_error_m"] > 3e-4  # the merged run is real, the allowance counts
    assert vs_ref["max_position_error_m"] <= vs_ref["loss_allowance_m"] + 1e-4
    wrong = tmp_path / "wrong.log"
    assert _biased_x(log, wrong, lambda k, t: t > 2.0, 3) > 100
    code, wrong_report = _analyze_as(wrong, tmp_path, "kobuki")
    print(f"wrong: exit {code}, {wrong_report['onboard_vs_reference']}")
    assert code == 1


STEADY = (10, 12)  # counts per period of the left and right wheel: a steady arc


def _burst_rig(dropped: int) -> tuple[Rig, list[tuple[int, int, int]]]:
    """An ECU fed one frame a tick, then, in one tick, ``MAILBOX_SLOTS + dropped`` frames back
    to back (the mailbox keeps 32, drops the rest), then one a tick again; after each later tick:
    (LINEAR_VEL mm/s, ENC_E2E_LOST, frames implausible)."""
    rig = Rig()
    rig.drive(20, *STEADY)
    for _ in range(MAILBOX_SLOTS + dropped):
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rig.encoders(*STEADY))
    rig.ecu.tick()
    after = []
    for _ in range(40):
        rig.drive(1, *STEADY)
        enc = rig.ecu.encoders
        after.append((rig.ecu.twist.linear_mm_s, enc.rx.lost_frames, enc.frames_implausible))
    return rig, after


@pytest.mark.parametrize("dropped", [1, 11, 14, 15, 16, 17, 31, 40])
def test_after_frames_its_mailbox_dropped_the_twist_is_right_and_every_one_is_counted(
    dropped: int,
) -> None:
    """The frame after a run the mailbox dropped carries the counts of all of them: the
    firmware takes it at once (its E2E window widened fully), as a step of ``dropped`` + 1
    periods (the drop count, not the 4-bit COUNTER, gives the whole cycles), so ODOM_TWIST stays
    the steady speed, and ENC_E2E_LOST counts every dropped frame. Before, the window stayed
    narrow: it refused the frames until the COUNTER came round and took a 17-period step for one
    period (17 times the speed), or (16 dropped) took the 17th frame as the next; and
    ENC_E2E_LOST counted none of it (the judge allowed them nothing)."""
    steady = Rig()  # every frame, one a tick
    steady.drive(20 + MAILBOX_SLOTS + dropped + 40, *STEADY)
    rig, after = _burst_rig(dropped)
    speed = steady.ecu.twist.linear_mm_s
    assert speed > 0
    assert [a[0] for a in after] == [speed] * len(after)
    # After 15 (mod 16) dropped, the next frame has the last accepted COUNTER: E2E refuses it as
    # REPEATED, and the step that merges it is one frame longer.
    refused = 1 if dropped % 16 == 15 else 0
    assert after[-1][1:] == (dropped + refused, 0)
    assert rig.ecu.encoders.rx.count_repeated == refused
    assert rig.ecu.mailbox.overflows == dropped
    assert not rig.ecu.errors.bits & (ErrorFlag.COUNTER_RESET | ErrorFlag.IMPLAUSIBLE_STEP)
    # recovered from MAILBOX_OVERFLOW; unless the merged step's worst case (its path is
    # unknowable: firmware.uncertainty) passed the tolerance: latched until a set-pose
    uncertain = rig.ecu.errors.has(ErrorFlag.POSE_UNCERTAIN)
    assert uncertain == (dropped >= 31)  # 32 periods at this speed: a bound past 50 mm
    assert rig.state() is (State.DEGRADED if uncertain else State.OK)
    assert rig.ecu.reason is (Reason.POSE_UNCERTAIN if uncertain else Reason.NONE)
    # the pose: the same arc as with every frame (the exact integrator's steps merge exactly)
    odo, ref = rig.ecu.odometry, steady.ecu.odometry
    assert odo.heading_bam64 == ref.heading_bam64
    assert abs(odo.x_q40_m - ref.x_q40_m) < 1 << 12  # 4 nm
    assert abs(odo.y_q40_m - ref.y_q40_m) < 1 << 12


def _encoders(robot: Robot, steps: list[tuple[int, int]]) -> Encoders:
    """Encoder frames, one per period, carrying the counts of ``steps`` from 0."""
    wire = 1 << min(robot.counter_bits, 24)
    left = np.concatenate(([0], np.cumsum([s[0] for s in steps])))
    right = np.concatenate(([0], np.cumsum([s[1] for s in steps])))
    n = len(left)
    return Encoders(index=np.arange(n), counter=np.arange(n) & 0xF, seq=np.arange(n),
                    left=left % wire, right=right % wire,
                    timestamp_s=np.arange(n, dtype=np.float64) * 0.01, cycle_s=0.01)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    robot=robots(),
    integrator=st.sampled_from(["euler", "rk2", "exact"]),
    steps=st.lists(st.tuples(st.integers(-40, 40), st.integers(-40, 40)), min_size=3,
                   max_size=24),
    data=st.data(),
)
def test_the_merge_error_of_a_run_of_lost_frames_is_the_checkers(
    robot: Robot, integrator: str, steps: list[tuple[int, int]], data: st.DataObject
) -> None:
    """``run_errors(j, r)``: how far the pose ends when frames j .. j + r - 1 are lost (the
    r + 1 steps taken as one), against the checker's float64 odometry driving the same counts
    both ways; r = 1 is ``drop_errors``."""
    enc = _encoders(robot, steps)
    n = len(enc.seq)
    j = data.draw(st.integers(1, n - 2), label="first lost frame")
    r = data.draw(st.integers(1, n - 1 - j), label="frames lost")
    got = float(run_errors(OneSteps.of(enc, profile_of(robot), integrator), np.array([j]), r)[0])
    every, lost = _Odometry(robot, integrator), _Odometry(robot, integrator)
    merged = [0, 0]
    for k, (d_left, d_right) in enumerate(steps):
        assume(abs(d_right * every.m_right - d_left * every.m_left) / every.b < 0.9 * math.pi)
        every.step(d_left, d_right)
        merged = [merged[0] + d_left, merged[1] + d_right]
        if j - 1 <= k < j + r - 1:
            continue  # frame k + 1 lost: its step waits for the next one
        # a merged step of half a turn or more: the firmware reads its turn wrapped, which this
        # plain checker does not (tests/test_stall_bound.py has that case's own regression test)
        assume(abs(merged[1] * lost.m_right - merged[0] * lost.m_left) / lost.b < 0.9 * math.pi)
        lost.step(*merged)
        merged = [0, 0]
    want = math.hypot(every.x - lost.x, every.y - lost.y)
    scale = sum(abs(a) + abs(b) for a, b in steps) * every.m_left
    assert abs(got - want) <= 1e-9 * max(scale, 1e-3), (got, want)
    if r == 1:
        assert got == pytest.approx(drop_errors(enc, profile_of(robot), integrator)[j], abs=1e-12)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    robot=robots(),
    steps=st.lists(st.tuples(st.integers(-40, 40), st.integers(-40, 40)), min_size=4,
                   max_size=11),
    data=st.data(),
)
def test_the_loss_allowance_is_the_worst_placement_of_the_lost_frames(
    robot: Robot, steps: list[tuple[int, int]], data: st.DataObject
) -> None:
    """``worst_runs_m``: the largest sum of run errors over every set of at most n lost frames
    in the span (named frames never lost; a run error need not grow with the run, so at most n
    is the safe side), by brute force over all the sets: runs of consecutive lost frames merge
    into one step each."""
    enc = _encoders(robot, steps)
    n_frames = len(enc.seq)
    one = OneSteps.of(enc, profile_of(robot), "rk2")
    first = data.draw(st.integers(0, n_frames - 2), label="first")
    last = data.draw(st.integers(first, n_frames - 1), label="last")
    lost_ok = np.array(data.draw(st.lists(st.booleans(), min_size=n_frames,
                                          max_size=n_frames), label="may be lost"))
    n = data.draw(st.integers(0, 5), label="lost")
    candidates = [k for k in range(max(first, 1), min(last, n_frames - 2) + 1) if lost_ok[k]]
    best = 0.0
    for size in range(min(n, len(candidates)) + 1):
        for chosen in itertools.combinations(candidates, size):
            total, k = 0.0, 0
            while k < len(chosen):  # maximal runs of consecutive lost frames
                end = k
                while end + 1 < len(chosen) and chosen[end + 1] == chosen[end] + 1:
                    end += 1
                total += float(run_errors(one, np.array([chosen[k]]), end - k + 1)[0])
                k = end + 1
            best = max(best, total)
    assert worst_runs_m(one, lost_ok, first, last, n) == pytest.approx(best, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize(("foreign", "real"), [(1, 0), (1, 1), (7, 0), (3, 17)])
def test_a_babblers_frames_on_the_encoder_id_are_not_taken_for_dropped_encoder_frames(
    foreign: int, real: int
) -> None:
    """A babbler on the WHEEL_ENCODERS ID fills the mailbox with frames E2E refuses (a bad CRC)
    and the ring drops ``foreign`` more of them, with ``real`` encoder frames: the ISR counts
    only the dropped frames whose CRC holds (``isr_dropped``). Taken for encoder frames, one
    forged drop made the next step 17 periods instead of 1 (the twist 17 times too low: kobuki
    60 s under babble=8000 FAILed on it). The twist stays steady, ENC_E2E_LOST counts the real
    drops only."""
    steady = Rig()
    steady.drive(60 + real, *STEADY)
    rig = Rig()
    rig.drive(20, *STEADY)
    for _ in range(MAILBOX_SLOTS + foreign):
        bad = bytearray(rig.encoders(*STEADY))
        rig.counter = (rig.counter - 1) % 16  # not the motor controller's frame: no COUNTER
        rig.left, rig.right = rig.left - STEADY[0], rig.right - STEADY[1]
        bad[0] ^= 0xFF  # a CRC the E2E check refuses
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, bytes(bad))
    for _ in range(real):
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rig.encoders(*STEADY))  # dropped
    rig.ecu.tick()
    speeds = []
    for _ in range(40):
        rig.drive(1, *STEADY)
        speeds.append(rig.ecu.twist.linear_mm_s)
    assert speeds == [steady.ecu.twist.linear_mm_s] * len(speeds)
    assert rig.ecu.encoders.rx.lost_frames == real
    assert rig.ecu.encoders.frames_dropped == real  # the babbler's bad CRCs are not counted
    assert rig.ecu.odometry.heading_bam64 == steady.ecu.odometry.heading_bam64


@pytest.mark.parametrize(("foreign", "real"), [(1, 0), (1, 1), (7, 0), (3, 17)])
def test_forged_frames_whose_crc_holds_dropped_on_the_encoder_id_are_absorbed(
    foreign: int, real: int
) -> None:
    """The ring full of frames E2E refuses, then ``foreign`` forged frames whose CRC holds (a
    copy of the next encoder frame: ``isr_dropped`` cannot tell them) and ``real`` encoder
    frames are dropped: d counts both, the advance nearest to d + 1 with the COUNTER is the
    real one while the forged ones number 7 or fewer (``_counter_advance``)."""
    steady = Rig()
    steady.drive(60 + real, *STEADY)
    rig = Rig()
    rig.drive(20, *STEADY)
    for _ in range(MAILBOX_SLOTS):
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, bytes(8))  # a CRC the E2E check refuses
    for _ in range(foreign):
        forged = rig.encoders(*STEADY)
        rig.counter = (rig.counter - 1) % 16  # not the motor controller's frame: no COUNTER
        rig.left, rig.right = rig.left - STEADY[0], rig.right - STEADY[1]
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, forged)  # dropped, counted
    for _ in range(real):
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rig.encoders(*STEADY))  # dropped
    rig.ecu.tick()
    speeds = []
    for _ in range(40):
        rig.drive(1, *STEADY)
        speeds.append(rig.ecu.twist.linear_mm_s)
    assert speeds == [steady.ecu.twist.linear_mm_s] * len(speeds)
    assert rig.ecu.encoders.rx.lost_frames == real
    assert rig.ecu.encoders.frames_dropped == foreign + real
    assert rig.ecu.odometry.heading_bam64 == steady.ecu.odometry.heading_bam64


def test_a_flood_of_random_payloads_dropped_on_the_encoder_id_leaves_the_twist_steady() -> None:
    """Each tick: the encoder frame, the ring filled with frames E2E refuses, then 45 random
    payloads on the ID, all dropped (the 8 000 frames/s flood of tests/test_health_rig.py
    ``run_forgery``). Counted as encoder frames, the 45 drops made each one-period step span ~45
    periods (LINEAR_VEL ~1/45 of the truth); only the ~1 in 256 whose CRC holds are counted
    (``isr_dropped``), fewer than the 8 of miscount the nearest COUNTER advance absorbs: the
    twist and the pose are those of the same drive without the flood, tick by tick."""
    rng = random.Random(11)
    ticks, per_tick = 200, 45
    steady = Rig()
    steady.drive(20, *STEADY)
    rig = Rig()
    rig.drive(20, *STEADY)
    for _ in range(ticks):
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rig.encoders(*STEADY))
        for _ in range(MAILBOX_SLOTS - 1):
            rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, bytes(8))  # CRC of zeros: refused
        for _ in range(per_tick):
            rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rng.randbytes(8))  # dropped
        rig.ecu.tick()
        steady.drive(1, *STEADY)
        assert rig.ecu.twist.linear_mm_s == steady.ecu.twist.linear_mm_s
        assert rig.ecu.twist.angular_mrad_s == steady.ecu.twist.angular_mrad_s
    counted = rig.ecu.encoders.frames_dropped
    assert 0 < counted < ticks * per_tick // 64  # ~35 expected: the CRC path is exercised
    assert rig.ecu.odometry.heading_bam64 == steady.ecu.odometry.heading_bam64
    assert rig.ecu.encoders.rx.lost_frames == 0
