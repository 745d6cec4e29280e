"""TURNS is judged with HEADING (issue #11): a log whose ODOM_POSE_Y TURNS was edited (+1, +3,
-7, the E2E CRC recomputed) from some time on used to PASS ``analyze`` (whole and streamed), and
the monitor and the bridge said OK while the unwrapped heading they showed was 2 pi k off. Now
the heading error every judge compares with its one-LSB limit is the unwrapped one.

The logs are written by ``tests/synth_log.py`` (the firmware's exact outputs): a spinning drive
of hundreds of turns, both senses, through a reboot. Each verdict's truth is the checker below,
written for this test: cantools decodes every frame, float64 gives the cumulative heading from
the wheel counts (phi = 2 pi (r_R N_R - r_L N_L) / (PPV b), counts since the life's start), and
the on-board unwrapped heading TURNS * 2 pi + HEADING must lie within one LSB of it.

Sampled (``tests.sweeps``): the grid of TURNS edits (delta x from frame); pinned, each delta
(+1, +3, -7) and each side of the reboot (frame 3 000 and 11 000) once.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.host.io.logs import parse_candump_line, read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import RobotProfile, load
from tests.dbc_typed import load_can_dbc, numbers
from tests.independent_checker import Robot
from tests.sweeps import sample
from tests.synth_log import ENCODER_PERIOD_S, Synth, synthesize
from tests.test_judge_campaign import profile_of, robots

HEADING_LSB_RAD = 2.0 * math.pi / 65536.0
DB = load_can_dbc(DBC_PATH)
SPIN_STEPS = 6_000  # about 210 turns forward, then back: ~300 turns the other way after ...
REBOOT = 6_500  # ... the reboot here
STEPS = 15_000


# --- the checker written for this test ---------------------------------------------------------


def _lines(path: Path) -> list[tuple[float, int, bytes, str]]:
    out = []
    for line in path.read_text().splitlines():
        stamp, _, frame = line.split()
        can_id, data = frame.split("#")
        out.append((float(stamp.strip("()")), int(can_id, 16), bytes.fromhex(data), line))
    return out


def checker(path: Path, profile: RobotProfile, lives_from_t_s: list[float]) -> list[
        tuple[float, float]]:
    """(time s, |on-board unwrapped heading - float64 cumulative heading| rad) per on-board
    sample: each pose pair names the encoder frame just before it (the synthesizer's), the
    counts are counted from each life's first encoder frame (0 and the reboots' times)."""
    enc = DB.get_message_by_name("WHEEL_ENCODERS")
    px, py = DB.get_message_by_name("ODOM_POSE_X"), DB.get_message_by_name("ODOM_POSE_Y")
    half = 1 << (min(profile.counter_bits, 24) - 1)  # the wire's low bits of the counters
    k_left = 2 * math.pi * profile.wheel_radius_left_m / profile.counts_per_rev
    k_right = 2 * math.pi * profile.wheel_radius_right_m / profile.counts_per_rev
    prev: tuple[int, int] | None = None
    n_left = n_right = 0
    heading_x: float | None = None
    out = []
    starts = sorted(lives_from_t_s)
    for t_s, can_id, data, _ in _lines(path):
        if can_id == enc.frame_id:
            s = numbers(DB, can_id, data)
            counts = (int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))
            if starts and t_s >= starts[0] - 1e-9:  # a new life primes on this frame
                starts.pop(0)
                prev, n_left, n_right = counts, 0, 0
            assert prev is not None
            n_left += (counts[0] - prev[0] + half) % (2 * half) - half
            n_right += (counts[1] - prev[1] + half) % (2 * half) - half
            prev = counts
        elif can_id == px.frame_id:
            heading_x = float(numbers(DB, can_id, data)["HEADING"])
        elif can_id == py.frame_id and heading_x is not None:
            turns = int(numbers(DB, can_id, data)["TURNS"])
            onboard = turns * 2 * math.pi + heading_x
            phi = (k_right * n_right - k_left * n_left) / profile.wheelbase_m
            out.append((t_s, abs(onboard - phi)))
    return out


def checker_passes(errors: list[tuple[float, float]]) -> bool:
    return max(e for _, e in errors) <= HEADING_LSB_RAD


# --- the drives ------------------------------------------------------------------------------


def spinning_drive(profile: RobotProfile) -> Synth:
    """Spin ~210 turns one way (creeping forward), then, past a reboot, ~300 the other way."""
    rng = np.random.default_rng(11)
    spin = 300 + rng.integers(-5, 6, size=STEPS)
    sense = np.where(np.arange(STEPS) < SPIN_STEPS, 1, -1)
    creep = rng.integers(0, 4, size=STEPS)
    return synthesize(profile, "exact", creep - sense * spin, creep + sense * spin,
                      reboot_at=REBOOT)


def turns_edited(lines: list[str], from_t_s: float, delta: int) -> list[str]:
    """ODOM_POSE_Y's TURNS + ``delta`` from ``from_t_s`` on, re-packed (E2E CRC recomputed)."""
    out = []
    for line in lines:
        msg = parse_candump_line(line.encode())
        if msg is not None and msg.arbitration_id == fr.ODOM_POSE_Y_ID \
                and msg.timestamp >= from_t_s:
            s = numbers(DB, msg.arbitration_id, msg.data, scaling=False)
            data = fr.pack_odom_pose_y(int(s["COUNTER"]), int(s["ENC_COUNTER"]), int(s["Y"]),
                                       int(s["TURNS"]) + delta, ErrorMask())
            line = f"({msg.timestamp:.6f}) vcan0 {msg.arbitration_id:03X}#{data.hex().upper()}\n"
        out.append(line)
    return out


def live(profile: RobotProfile, lines: list[str], until_t_s: float) -> tuple[
        BusMonitor, RobotTelemetry, list[dict[str, Any]], str]:
    """The monitor model and the bridge fed the frames; the bridge's error publications and the
    monitor's state at ``until_t_s`` (before the rest is fed)."""
    monitor = BusMonitor(profile)
    bridge = RobotTelemetry("r", Geometry.of(profile), "exact",
                            counter_bits=profile.counter_bits, publish_hz=1_000)
    errors = []
    state_before = ""
    for line in lines:
        msg = parse_candump_line(line.encode())
        if msg is None:
            continue
        if not state_before and msg.timestamp >= until_t_s:
            state_before = monitor.health(until_t_s)["state"]
        assert isinstance(msg, can.Message)
        monitor.feed(msg, now_s=msg.timestamp)
        errors += [payload for leaf, payload in bridge.feed(msg) if leaf == "error"]
    return monitor, bridge, errors, state_before


# --- the tests -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def kobuki_spin() -> tuple[RobotProfile, Synth]:
    # 300 counts a period is a 2.6 m/s rim: a kobuki bounded at 4 m/s (its own 0.7 refuses it)
    profile = dataclasses.replace(load("kobuki"), max_wheel_speed_m_s=4.0)
    return profile, spinning_drive(profile)


def test_a_correct_spinning_drive_passes_every_judge(
    tmp_path: Path, kobuki_spin: tuple[RobotProfile, Synth]
) -> None:
    """Hundreds of turns both ways, through a reboot: PASS whole and streamed, OK live, and the
    checker agrees (the on-board unwrapped heading within one LSB everywhere)."""
    profile, synth = kobuki_spin
    path = synth.write(tmp_path / "spin.log")
    turns = [s.heading_turns for s in synth.state]
    assert max(turns) > 200  # hundreds of turns, both senses
    assert min(turns[REBOOT:]) < -290
    assert checker_passes(checker(path, profile, [0.0, REBOOT * ENCODER_PERIOD_S]))
    whole = analyze(read_log(path), profile)
    assert whole.passed, whole.report["onboard_vs_reference"]
    assert analyze_file(path, profile, chunk_frames=4_096)["passed"]
    end_s = STEPS * ENCODER_PERIOD_S
    monitor, bridge, errors, _ = live(profile, synth.lines(), end_s)
    assert monitor.health(end_s + 0.005)["state"] == "OK"
    assert not [e for e in errors if e["pose_wrong"]]
    assert bridge.tracker.vs_reference.max_dheading_rad <= HEADING_LSB_RAD


EDITS = [(1, 3_000), (3, 3_000), (-7, 3_000), (1, 11_000), (-7, 11_000)]  # (delta, from frame)


@pytest.mark.parametrize(("delta", "from_frame"),
                         sample(EDITS, 3, [(3, 3_000), (-7, 3_000), (1, 11_000)]))
def test_an_edited_turns_fails_every_judge_from_its_time(
    tmp_path: Path, kobuki_spin: tuple[RobotProfile, Synth], delta: int, from_frame: int
) -> None:
    """TURNS off by ``delta`` from encoder frame ``from_frame`` on (before or after the reboot):
    FAIL whole and streamed, POSE WRONG live, the bridge's ``pose_wrong`` never before it."""
    profile, synth = kobuki_spin
    from_t_s = from_frame * ENCODER_PERIOD_S
    path = tmp_path / "edited.log"
    path.write_text("".join(turns_edited(synth.lines(), from_t_s, delta)))
    errors = checker(path, profile, [0.0, REBOOT * ENCODER_PERIOD_S])
    assert checker_passes([e for e in errors if e[0] < from_t_s])
    assert not checker_passes(errors)
    whole = analyze(read_log(path), profile)
    assert not whole.passed
    assert whole.report["onboard_vs_reference"]["max_heading_error_rad"] == pytest.approx(
        2 * math.pi * abs(delta), abs=HEADING_LSB_RAD)
    assert not analyze_file(path, profile, chunk_frames=4_096)["passed"]
    monitor, _, published, before = live(profile, path.read_text().splitlines(True), from_t_s)
    assert before == "OK"
    end_s = STEPS * ENCODER_PERIOD_S
    assert monitor.health(end_s + 0.005)["state"] == "POSE WRONG"
    flagged = [e for e in published if e["pose_wrong"]]
    assert flagged
    assert min(e["t_s"] for e in flagged) >= from_t_s


def boundary_drive(profile: RobotProfile) -> tuple[Synth, int]:
    """Spin to just short of 3 whole turns, then creep to and fro by single counts of one wheel
    (a heading step of 0.004 LSB on this fine robot) across 3 x 2 pi less half an LSB, where
    the rounded HEADING carries TURNS. Returns the drive and the encoder frame the creep starts."""
    k = 2 * math.pi * profile.wheel_radius_right_m / profile.counts_per_rev / profile.wheelbase_m
    carry = round((3 * 2 * math.pi - 0.5 * HEADING_LSB_RAD) / k)  # right-wheel counts there
    spin, d_right = 40_000, []
    n = 0
    while n + spin < carry - 40:
        d_right.append(spin)
        n += spin
    d_right.append(carry - 40 - n)
    creep_from = len(d_right) + 1
    d_right += ([1] * 80 + [-1] * 80) * 6
    return synthesize(profile, "exact", [0] * len(d_right), d_right), creep_from


def test_headings_at_a_multiple_of_two_pi_are_judged_either_side(tmp_path: Path) -> None:
    """Crossing 3 x 2 pi to and fro, the rounded HEADING carries TURNS: the firmware sends
    (3, HEADING near 0) and (2, HEADING near 2 pi) within a count of each other; every judge
    accepts both (the checker too), and a TURNS one off at the boundary still fails."""
    profile = RobotProfile("fine", 1 << 20, 0.035, 0.035, 0.5, 32)
    synth, creep_from = boundary_drive(profile)
    path = synth.write(tmp_path / "boundary.log")
    creep_t_s = creep_from * ENCODER_PERIOD_S
    sides = {int(numbers(DB, can_id, data)["TURNS"]) for t_s, can_id, data, _ in _lines(path)
             if can_id == fr.ODOM_POSE_Y_ID and t_s >= creep_t_s}
    assert sides == {2, 3}  # both sides of the boundary were sent
    assert checker_passes(checker(path, profile, [0.0]))
    assert analyze(read_log(path), profile).passed
    assert analyze_file(path, profile, chunk_frames=1_000)["passed"]
    end_s = len(synth.state) * ENCODER_PERIOD_S
    monitor, _, published, _ = live(profile, synth.lines(), end_s)
    assert monitor.health(end_s)["state"] == "OK"
    assert not [e for e in published if e["pose_wrong"]]
    # at the boundary, TURNS 2 where the firmware said 3 (HEADING near 0 kept): 2 pi off
    first_three = next(t for t, can_id, data, _ in _lines(path) if can_id == fr.ODOM_POSE_Y_ID
                       and int(numbers(DB, can_id, data)["TURNS"]) == 3 and t >= creep_t_s)
    wrong = tmp_path / "wrong.log"
    wrong.write_text("".join(turns_edited(synth.lines(), first_three, -1)))
    assert not checker_passes(checker(wrong, profile, [0.0]))
    assert not analyze(read_log(wrong), profile).passed
    assert not analyze_file(wrong, profile, chunk_frames=1_000)["passed"]


# --- a campaign on random robots ----------------------------------------------------------------


def random_spin(robot: Robot, steps: int, seed: int) -> tuple[list[int], list[int]]:
    """Spins of both senses (switching every 50 .. 400 steps, creeping a little), each step
    within the firmware's plausibility bound, below 0.45 turn and half the wire's range."""
    rng = np.random.default_rng(seed)
    m_left = 2 * math.pi * robot.wheel_radius_left_nm * 1e-9 / robot.counts_per_rev
    m_right = 2 * math.pi * robot.wheel_radius_right_nm * 1e-9 / robot.counts_per_rev
    b_m = robot.wheelbase_nm * 1e-9
    most = min(0.8 * 4.0 * ENCODER_PERIOD_S / max(m_left, m_right),
               0.45 * 2 * math.pi * b_m / (m_left + m_right),
               0.4 * (1 << (min(robot.counter_bits, 24) - 1)))
    spin = max(1, int(most))
    runs = rng.integers(50, 400, size=steps // 50 + 2)
    sense = np.repeat(rng.choice([-1, 1], size=len(runs)), runs)[:steps]
    size = rng.integers(max(1, spin // 2), spin + 1, size=steps)
    creep = rng.integers(0, max(1, spin // 20) + 1, size=steps)
    return (creep - sense * size).tolist(), (creep + sense * size).tolist()


@settings(max_examples=int(os.environ.get("ODOCAN_CAMPAIGN_EXAMPLES", "12")) // 2 + 2,
          deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                                HealthCheck.function_scoped_fixture])
@given(robot=robots(), integrator=st.sampled_from(["euler", "rk2", "exact"]),
       reboot=st.booleans(), delta=st.sampled_from([0, 0, 1, 3, -7, -1, 12_345]),
       edit_at=st.floats(0.2, 0.9), seed=st.integers(0, 2**32 - 1))
def test_random_robots_spinning_agree_with_the_checker(
    tmp_path_factory: pytest.TempPathFactory, robot: Robot, integrator: str, reboot: bool,
    delta: int, edit_at: float, seed: int,
) -> None:
    """Random robots spinning both ways (through a reboot or not): a correct firmware PASSes
    every judge; TURNS off by ``delta`` from some time FAILs every judge, live never before it;
    the checker agrees each time."""
    steps = 2_000
    profile = profile_of(robot)
    d_left, d_right = random_spin(robot, steps, seed)
    reboot_at = steps // 2 if reboot else None
    synth = synthesize(profile, integrator, d_left, d_right, reboot_at=reboot_at)
    from_t_s = round(edit_at * steps) * ENCODER_PERIOD_S + 0.0005
    lines = turns_edited(synth.lines(), from_t_s, delta) if delta else synth.lines()
    path = tmp_path_factory.mktemp("spin") / "spin.log"
    path.write_text("".join(lines))
    lives = [0.0] + ([reboot_at * ENCODER_PERIOD_S] if reboot_at else [])
    right = checker_passes(checker(path, profile, lives))
    assert right == (delta == 0)
    whole = analyze(read_log(path), profile, integrator)
    assert whole.passed == right, whole.report["onboard_vs_reference"]
    assert analyze_file(path, profile, integrator, chunk_frames=2_000)["passed"] == right
    end_s = steps * ENCODER_PERIOD_S
    monitor = BusMonitor(profile, integrator)
    bridge = RobotTelemetry("r", Geometry.of(profile), integrator,
                            counter_bits=profile.counter_bits, publish_hz=1_000)
    flagged = []
    for line in lines:
        msg = parse_candump_line(line.encode())
        if msg is not None:
            monitor.feed(msg, now_s=msg.timestamp)
            flagged += [p for leaf, p in bridge.feed(msg) if leaf == "error" and p["pose_wrong"]]
    assert monitor.health(end_s + 0.005)["state"] == ("OK" if right else "POSE WRONG")
    assert bool(flagged) != right
    assert all(p["t_s"] >= from_t_s for p in flagged)
