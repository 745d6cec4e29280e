"""figure8 under ``--faults delay=0.5:150,drop=0.1``, 10 s: ODOM_TWIST DISTANCE where the
reference refused frames the firmware took (issue #11, rule 5: a FAIL never blames a correct
firmware, a PASS never hides a wrong pose or DISTANCE).

A 150 ms delay is 15 encoder periods: half the frames arrive with a COUNTER one ahead of the
on-time frame beside them, and the host's E2E and the firmware's may take different chains.

* pmir seed 7: the host took a late frame of COUNTER 9 (sent 7.61 s, heard 7.76 s) where the
  firmware took the on-time one (7.77 s, refused by the host as a repeat); the reference then
  refused the next two frames (COUNTER 10 and 11: 57 counts in a period from the late frame)
  and stepped 84/128 counts into COUNTER 2 at 7.86 s. The firmware had taken 10 and 11; its
  twist naming COUNTER 10 (7.93 s) read 67.4 mm above the reference's path there, and the next
  (7.86 s frame, 8.01 s) on it again: the interval of allowed offsets went empty by 66.28 mm
  (``run``, both analyses; the live judges 66.89 mm).
* kobuki seed 2: the firmware re-primed on a counter restart one frame (3.96 mm) before the
  reference's restart run (on a frame the host never accepted) and named a frame of that run,
  11.9 mm above it: DISTANCE 7.02 mm beyond.
* kobuki seeds 7 and 2, the pose: the poses proved an on-time encoder frame skipped (seed 7: the
  COUNTER 4 of 7.72 s, LEFT_COUNT 30313, 715 counts from the late 2 taken at 7.69 s) that every
  reading of the E2E window took (3, 3, 2 periods); the host read the skip as the E2E check's,
  took the late 6, 8 and 9 the firmware refused (out of sequence from 4) and re-primed its counter
  restart on the 10 after, where the firmware re-primed on that 4: 5.98 mrad of heading and
  0.150 mm of position beyond the allowance (seed 2: 7.862 mm) off a correct firmware. A skip
  whose step the plausibility bound refuses is the bound's (``host.protocol.e2e_bound``): after,
  0.048 mm / 0.048 mrad (seed 7) and 0.042 mm / 0.048 mrad (seed 2) off the reference.

The reference's own state machine refused those frames, so a firmware that took its chain
never names one: such a sample names the firmware's chain, not the reference's, and is left out
(``host.judge.refusednames``); the samples around still pin DISTANCE (10 mm from 7 s on pmir,
4 s on kobuki, FAILs). What stays wrong is in the strict xfails below, with its figures.

The live judges (monitor, bridge) named a twist held back 150 ms where it was heard (its 4-bit
ENC_COUNTER resolved a lap late) and carried that name along a run holding its ENC_COUNTER;
they name it where it was sent now, by send times, as ``analyze`` does
(``host.judge.livelatetwists``), and leave out a twist naming a frame their step gate refused
(``refusednames``, as ``analyze``): their DISTANCE passes all three drives.

The firmware is watched at every step (``tests.fw_watch``, float64): a FAIL of an untampered
drive blames a correct one.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from odocan.host.io.logs import read_log
from odocan.host.judge.e2estepbound import bound_of
from odocan.host.judge.reference_path import Steps
from odocan.host.judge.refusednames import refused_frames
from odocan.host.protocol.e2e import check_frames
from odocan.host.protocol.e2e_bound import step_bound
from odocan.sim.robot import load
from tests.fw_watch import Watch
from tests.judges_cli import (
    TEN_MM_LSB,
    both_analyses,
    live_judges,
    raise_x_10_mm,
    raw_signals,
    reported_analyses,
    watched_run,
    x_10_mm_off_fails,
)
from tests.log_edit import raise_raw

FAULTS = "delay=0.5:150,drop=0.1"
DURATION_S = 10
DISTANCE_SPAN = (6, 2)  # ODOM_TWIST DISTANCE: bytes 6..7, 1 mm
DRIVES = {"pmir7": ("pmir", 7), "kobuki2": ("kobuki", 2), "kobuki7": ("kobuki", 7)}
X_FROM_S = {"pmir7": 8.5, "kobuki2": 4.0, "kobuki7": 5.0}  # X +10 mm from then on
DISTANCE_FROM_S = {"pmir7": 7.0, "kobuki2": 4.0}  # DISTANCE +10 mm, across the sample left out
Drive = tuple[str, Path, Watch, int]
LIVE_BLIND_DISTANCE_CASES = {("pmir7", 1), ("pmir7", -1), ("kobuki7", 1)}  # (drive, sign)

LIVE_POSE = pytest.mark.xfail(strict=True, reason=(
    "kobuki 2: the live pose judges (monitor = bridge) POSE WRONG, position 65.54 mm beyond "
    "the allowance at 4.59 s (run and both analyses PASS it: host.protocol.e2e_bound); its live "
    "DISTANCE passes. Untraced; on 20 s drives the live judges' E2E was seen taking frames of "
    "the late chain among the on-time ones where analyze's took the on-time chain alone (pmir "
    "4 at 11.70-11.76 s: 71.2 mm DISTANCE beyond; pmir 2 at 5.36 s: POSE 25.6 mm beyond)"))

LIVE_BLIND_DISTANCE = pytest.mark.xfail(strict=True, reason=(
    "DISTANCE 10 mm off (pmir 7 from 8.5 s either way, kobuki 7 +10 mm from 5 s): both live judges "
    "PASS it (0.0 mm excess) where both analyses FAIL it: their allowances between samples grow "
    "with every gap (drop=0.1) and the pages withdraw too few of them live (pmir 7: up to "
    "9.7 m above, 1.0 m below by 9 s); pmir 1, 20 s, from 10 s too. Main FAILed these logs "
    "untampered already (66.9, 110.4 mm), so it told nothing either"))
LIVE_BLIND_POSE = pytest.mark.xfail(strict=True, reason=(
    "pmir 7: X 10 mm off from 8.5 s (or 5 s): both live pose judges judge no sample beyond its "
    "allowance (0.0 mm), as on main: untraced"))


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Drive:
    name = str(request.param)
    log = tmp_path_factory.mktemp(name) / "drive.log"
    robot, seed = DRIVES[name]
    watch, code = watched_run(log, robot, "figure8", seed, DURATION_S, FAULTS)
    return name, log, watch, code


def test_the_firmware_is_right_at_every_step(drive: Drive) -> None:
    name, _, watch, _ = drive
    assert watch.steps > 300, (name, watch.steps)
    assert watch.within_a_thousandth_lsb(), (name, watch.worst_m, watch.worst_rad)


def test_both_analyses_pass_its_distance(drive: Drive, tmp_path: Path) -> None:
    """Before: pmir 7 66.277 mm beyond, kobuki 2 7.020 mm (both analyses)."""
    name, log, _, _ = drive
    for stream, _, report in reported_analyses(log, tmp_path):
        distance = report["onboard_distance_vs_reference"]
        assert distance["samples"] > 90, (name, stream, distance)
        assert distance["passed"], (name, stream, distance)


@pytest.mark.parametrize("judge", ["run", "analyze"])
def test_run_and_both_analyses_pass_it(drive: Drive, judge: str) -> None:
    """Before (strict xfails): kobuki 2 position 7.862 mm beyond the allowance, 16.29 mrad
    (and the stall-resume rule 11.69 mm at 4.44 s), kobuki 7 0.150 mm and 5.98 mrad (run and
    both analyses). After: 0.042 mm / 0.048 mrad and 0.048 mm / 0.048 mrad."""
    name, log, _, code = drive
    if judge == "run":
        assert code == 0, name
    else:
        assert both_analyses(log) == [0, 0], name


def test_the_live_judges_pass_it(drive: Drive, request: pytest.FixtureRequest) -> None:
    """Before (the live judges naming a twist held back 150 ms where heard, a frame 16 on, and
    a run holding its ENC_COUNTER from there; and a twist naming a frame their step gate
    refused): DISTANCE 66.89 (pmir 7), 63.66 (kobuki 2), 63.93 mm (kobuki 7) beyond."""
    name, log, _, _ = drive
    judges = live_judges(DRIVES[name][0], log)
    assert [judge.distance.verdict() for judge in judges] == [[], []], name
    if name == "kobuki2":
        request.applymarker(LIVE_POSE)
    assert [judge.tracker.wrongs.count for judge in judges] == [0, 0], name


@pytest.mark.parametrize("lsb", [TEN_MM_LSB // 10, -TEN_MM_LSB // 10], ids=["+10", "-10"])
def test_distance_10_mm_off_fails_the_live_judges(drive: Drive, lsb: int, tmp_path: Path,
                                                  request: pytest.FixtureRequest) -> None:
    """DISTANCE 10 mm off from ``X_FROM_S``: both live judges FAIL it by more than 5 mm (the
    late twists named where sent, those naming a refused frame left out, hide no such
    error)."""
    name, log, _, _ = drive
    if (name, 1 if lsb > 0 else -1) in LIVE_BLIND_DISTANCE_CASES:
        request.applymarker(LIVE_BLIND_DISTANCE)
    tampered = tmp_path / "t.log"
    assert raise_raw(log, tampered, "ODOM_TWIST", DISTANCE_SPAN, lsb, X_FROM_S[name],
                     wrap=True) > 50
    for judge in live_judges(DRIVES[name][0], tampered):
        assert judge.distance.verdict() != [], name
        assert judge.distance.worst_excess_m > 5e-3, (name, judge.distance.worst_excess_m)


def test_x_10_mm_off_fails_the_live_judges(drive: Drive, tmp_path: Path,
                                           request: pytest.FixtureRequest) -> None:
    """X 10 mm off from ``X_FROM_S``: both live judges' pose FAIL it by more than 5 mm."""
    name, log, _, _ = drive
    if name == "pmir7":
        request.applymarker(LIVE_BLIND_POSE)
    tampered = tmp_path / "t.log"
    assert raise_x_10_mm(log, tampered, X_FROM_S[name]) > 50
    for judge in live_judges(DRIVES[name][0], tampered):
        assert judge.tracker.max_beyond_allowance_m > 5e-3, name


def test_x_10_mm_off_fails_both_analyses(drive: Drive, tmp_path: Path) -> None:
    name, log, _, _ = drive
    assert x_10_mm_off_fails(log, tmp_path / "t.log", X_FROM_S[name], 50) == [], name


@pytest.mark.parametrize("lsb", [TEN_MM_LSB // 10, -TEN_MM_LSB // 10], ids=["+10", "-10"])
def test_distance_10_mm_off_across_the_left_out_sample_fails(drive: Drive, lsb: int,
                                                              tmp_path: Path) -> None:
    """DISTANCE raised or lowered 10 mm from before the sample left out: each analysis FAILs
    it by more than 5 mm (so leaving it out hides no such error)."""
    name, log, _, _ = drive
    if name not in DISTANCE_FROM_S:
        pytest.skip("no twist left out on this drive")
    tampered = tmp_path / "t.log"
    assert raise_raw(log, tampered, "ODOM_TWIST", DISTANCE_SPAN, lsb, DISTANCE_FROM_S[name],
                     wrap=True) > 100
    for stream, code, report in reported_analyses(tampered, tmp_path):
        excess_m = report["onboard_distance_vs_reference"]["max_excess_m"]
        assert code == 1, (name, stream, excess_m)
        assert excess_m > 5e-3, (name, stream, excess_m)


def test_the_frames_inside_a_refusal_run_are_the_ones_marked() -> None:
    """``refused_frames``: frames after the one taken before a run up to the one taken after
    (a run open at the end reaches the last frame); the others, and frame 0, are not."""
    zero = np.zeros(9, dtype=np.int64)
    steps = Steps(zero, zero.copy(), taken_before={5: 2, 10: 7})
    assert refused_frames(steps, 10).tolist() == [
        False, False, False, True, True, False, False, False, True, True]


def test_a_skip_the_bound_explains_is_taken_by_the_e2e_check(drive: Drive) -> None:
    """kobuki 7: the on-time COUNTER 4 of 7.72 s (LEFT_COUNT 30313) after the late 2 of 7.69 s
    (29598) that the firmware's check took last: 715 counts, where the robot's bound (0.7 m/s,
    computed here in float64 from the profile) allows 84 a period, so 420 over the widest
    window (3 periods) plus its COUNTER step (2). The host's check takes it with the robot's bound
    in force (the firmware's check took it; its bound refused the step) and refused it without."""
    name, log, _, _ = drive
    if name != "kobuki7":
        pytest.skip("traced on kobuki 7")
    frames = [(t, s) for t, _, s in raw_signals(log, ("WHEEL_ENCODERS",))]
    late2 = next(k for k, (t, s) in enumerate(frames) if abs(t - 7.69) < 1e-6)
    on_time4 = next(k for k, (t, s) in enumerate(frames) if abs(t - 7.72) < 1e-6)
    (_, two), (_, four) = frames[late2], frames[on_time4]
    assert (two["COUNTER"], two["LEFT_COUNT"], four["COUNTER"], four["LEFT_COUNT"]) == (
        2, 29598, 4, 30313)
    p = load("kobuki").firmware_params()
    m_per_count = 2 * math.pi * p["wheel_radius_left_nm"] * 1e-9 / p["counts_per_rev"]
    per_period = math.ceil(0.7 * 0.01 / m_per_count) + 1
    assert per_period == 84
    assert four["LEFT_COUNT"] - two["LEFT_COUNT"] > per_period * (3 + 2)
    arrays = read_log(log)
    at = int(np.flatnonzero(np.isclose(arrays.timestamp_s, 7.72)
                            & (arrays.can_id == 0x100))[0])
    with step_bound(bound_of(load("kobuki"))):
        assert check_frames(arrays)[1][at]
    assert not check_frames(arrays)[1][at]
