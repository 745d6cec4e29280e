"""Pose frames held back 100-150 ms on the bus (issue #11: a FAIL must never blame a correct
firmware).

``odocan run --seed 1 --duration 10 --faults delay=0.5:150`` FAILed the correct firmware by
47.0 mm (pmir) and 44.2 mm (kobuki): the Python firmware's every step, watched and integrated
again in float64 (``tests.fw_watch``), is within 1/1000 LSB, and it integrated exactly the
encoder frames the judge's reference steps through. The judge's fault was the pairing: a pose
frame's ENC_COUNTER was resolved against the encoder frames heard before the frame *arrived*;
held back 150 ms (15 encoder periods) it named the frame 16 after its own, and was paired with
an on-time half naming that one (X of 3.52 s with Y of 3.67 s: 47.2 mm, 195 mrad). Now a pose
or twist frame known late is resolved where it was sent (``host.judge.latenames``), also when
it follows a late one in its sender's sequence and ``sent_times`` reads it in order (pmir seed
2: 0.57 mm FAILed on main, 26.2 mm with the first rule alone). Seeds 1-6 x {pmir, kobuki} x
{0.5:100, 0.3:150, 0.5:150}, 10 s, every firmware within 1/1000 LSB (``tests.fw_watch``): 22 of
36 FAILed the correct firmware on main 20d0d696 (both judges), now 5, by both judges alike: the
2 pinned below, and at 0.5:150 pmir seed 5 (0.75 mm on main; then 86 mm: a lone ODOM_POSE_Y of
4.941 s, heard in order and named where heard, 87 mm off the reference at its frame: not the
naming), kobuki seeds 5 and 6 (128 and 61 mm on main; 75 and 82 mm then). They PASS since the
doubt of a step counts from the frame the firmware took before (``tests/test_doubt_taken_before``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.latenames import late_sends
from odocan.host.protocol.busfacts import POSE_PERIOD_S
from tests.fw_watch import Watch, watched
from tests.judges_cli import both_analyses, raise_x_10_mm, x_10_mm_off_fails

Drive = tuple[Path, Watch, int]  # the log, the firmware's watch, run's exit code

DRIVES = {  # name: (robot, seed, faults), each FAILed on main
    "pmir_1": ("pmir", 1, "delay=0.5:150"),  # 46.96 mm beyond the allowance
    "pmir_2": ("pmir", 2, "delay=0.5:150"),  # 0.57 mm (a late chain read in order)
    "kobuki_1": ("kobuki", 1, "delay=0.5:150"),  # 44.2 mm
    "kobuki_2": ("kobuki", 2, "delay=0.5:150"),  # 7.4 mm; then 0.097 mm at a resume (below)
    "kobuki_3": ("kobuki", 3, "delay=0.5:150"),  # 3.8 mm; then 17.0 mm (a skip the bound's)
    "kobuki_6": ("kobuki", 6, "delay=0.5:100"),  # 58.8 mm
}
# Was a strict xfail (kobuki seed 3, delay=0.5:150): ODOM_TWIST DISTANCE 17.0 mm off. After the
# on-time COUNTER 2 of 4.18 s (LEFT 39871) the firmware's E2E check took the late 3 (4.18 s, sent
# 4.03 s, 40589) and 5 (4.20 s, sent 4.05 s, 40491), its bound refused both steps, it REPEATED
# the on-time 5 (4.21 s, 39732) and stepped +329 left counts to the late 11 of 4.26 s (40200).
# The poses prove the late 5 skipped; the host read that as an E2E refusal, took the on-time 5
# and stepped 39871 -> 39732 -> 40200 (-139, +468): the same pose, 278 counts more path. The
# readings' one window (2) takes the late 5 after a frame the firmware's check took last (the 3,
# one on from the proven 2): the skip is the bound's (``e2e_evidence._bound_skip``). With the poses'
# chain mended past late pose frames alone (the on-time 5 then proven skipped too), the pose
# FAILed by 57.3 mm: the late 15 of 5.75 s, so read as the check's, left the host's refusal run
# at two frames where the firmware's three re-primed it (COUNTER_RESET) on the late stream.
# Was a strict xfail (kobuki seed 2, delay=0.5:150): the first sample after a hold, at 5.14 s,
# 0.097 mm beyond the resume rule's every candidate (stallfirst.resume_across). The firmware
# re-primed twice across the hold (COUNTER_RESET on the first of three late frames, 150 ms old,
# then back on the on-time ones when the late ran out), two steps left out where the rule
# modelled one; the reference's own steps (reference_path.firmware_steps) are now a candidate.
def _drive(root: Path, robot: str, seed: int, faults: str) -> Drive:
    log = root / f"{robot}.log"
    with watched(robot) as watch:
        code = main(["run", "--robot", robot, "--seed", str(seed), "--duration", "10",
                     "--faults", faults, "--firmware", "python", "--log", str(log)])
    return log, watch, code


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Drive:
    robot, seed, faults = DRIVES[request.param]
    return _drive(tmp_path_factory.mktemp(request.param), robot, seed, faults)


def _run_and_judges(drive: Drive, capsys: pytest.CaptureFixture[str]) -> list[int]:
    log, _, code = drive
    codes = [code, *both_analyses(log)]
    capsys.readouterr()
    return codes


def test_the_firmware_integrates_the_frames_it_took(drive: Drive) -> None:
    _, watch, _ = drive
    assert watch.steps > 400, watch.steps
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)


def test_the_correct_firmware_passes(drive: Drive, capsys: pytest.CaptureFixture[str]) -> None:
    assert _run_and_judges(drive, capsys) == [0, 0, 0]


@pytest.mark.parametrize("name", ["pmir_1", "kobuki_1", "kobuki_3"])
def test_a_pose_10_mm_off_fails_by_its_position(
        name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    robot, seed, faults = DRIVES[name]
    log, _, _ = _drive(tmp_path, robot, seed, faults)
    wrong = x_10_mm_off_fails(log, tmp_path / "t.log", 5.0, 100)
    capsys.readouterr()
    assert wrong == []


# X raised 10 mm from 5.0 s on a correct drive: name: robot, seed, faults; each once PASSed
TAMPERED_AT_5_S = {
    # the hold from 4.76 s ends at the sample of 5.14 s, which the firmware reached over two
    # re-primes (``stallresume``: the reference's steps are a candidate): the placement after
    # the hold absorbs the 10 mm (0.08 mm beyond the allowance), the resume rule does not (6.99
    # mm beyond, as on main)
    "double_reprime_kobuki_2": ("kobuki", 2, "delay=0.5:150"),
    # 109 gaps of refused frames, each placement's gap bound summed to 2275 mm absorbed it;
    # FAILs since the thirty-third pass's gap and late-naming rules (``gap445``, ``run698``)
    "refused_gaps_pmir_2": ("pmir", 2, "delay=0.5:100"),
    # frames held back 150 ms, 15 periods, carry a COUNTER one on from the on-time frame heard
    # with them: the E2E check took some as the next frame and, one period before the sender's
    # grid, they became the least late anchor of ``gapfill``'s numbering (``lap_less_one``),
    # which numbered every refused frame one ahead, and the window (est - 15, est + 1] put a
    # frame held 15 periods a lap ahead: the frames 482, 483 (heard 4.98, 4.99 s) went to 498,
    # 499, the gap before encoder frame 271 kept ``gapbound``'s 12.35 mm and the one before 273
    # was filled with counts 16 periods old (3.18 mm): the placement at 273 took the 9.94 mm
    "lap_less_one_pmir_4": ("pmir", 4, "delay=0.5:150"),
}


@pytest.mark.parametrize("name", sorted(TAMPERED_AT_5_S))
def test_a_pose_10_mm_off_from_5_s_fails(name: str, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """X raised 10 mm from 5.0 s FAILs both analyses (each case in ``TAMPERED_AT_5_S``)."""
    robot, seed, faults = TAMPERED_AT_5_S[name]
    log, _, code = _drive(tmp_path, robot, seed, faults)
    tampered = tmp_path / "t.log"
    assert raise_x_10_mm(log, tampered, 5.0) > 100
    codes = [code, *both_analyses(tampered)]
    capsys.readouterr()
    assert codes == [0, 1, 1]


def test_a_frame_after_a_late_one_is_late_when_its_counter_says_so() -> None:
    """ODOM_POSE_Y as pmir seed 2 heard them: 7 in order at 8.801 s, then 0, 1, 5, 6 (sent
    8.661-8.781 s, each heard 150 ms on) and 8, 9 (sent 8.821, 8.841 s): ``sent_times`` reads
    8 and 9 in order, heard when sent; they follow late ones and their COUNTER step from 7
    puts their sends 7.5 periods before their stamps."""
    heard = np.array([8.801, 8.811, 8.831, 8.911, 8.931, 8.971, 8.991])
    counter = np.array([7, 0, 1, 5, 6, 8, 9], dtype=np.int64)
    late, sent = late_sends(heard, counter, POSE_PERIOD_S)
    assert late.tolist() == [False, True, True, True, True, True, True]
    assert np.allclose(sent, [8.801, 8.661, 8.681, 8.761, 8.781, 8.821, 8.841])


def test_a_frame_after_a_silence_continues_no_late_run() -> None:
    """A late frame, then the sender silent 2 s (an MCU halt; kobuki circle seed 7163,
    ``delay=0.1:150,stall=8:2``, FAILed 77.6 mm when a step from the last frame heard in order
    read the first send after the halt as held back): that send is on time."""
    heard = np.array([7.981, 7.991, 10.021, 10.041])
    counter = np.array([3, 2, 5, 6], dtype=np.int64)
    late, sent = late_sends(heard, counter, POSE_PERIOD_S)
    assert late.tolist() == [False, True, False, False]
    assert np.array_equal(sent[2:], heard[2:])


def test_frames_stamped_late_in_bus_order_keep_their_place() -> None:
    """A recorder that stamps a burst late keeps the bus order: nothing is late there, however
    far the stamps run behind the COUNTER."""
    heard = np.array([1.001, 1.021, 1.201, 1.2011, 1.2012, 1.221])
    counter = np.array([0, 1, 2, 3, 4, 5], dtype=np.int64)
    late, sent = late_sends(heard, counter, POSE_PERIOD_S)
    assert not late.any()
    assert np.array_equal(sent, heard)


# The drives pinned here as still FAILing a correct firmware after ``distfall`` (pmir seed 5,
# kobuki seeds 5, 6, 8 and 10 at delay=0.5:150: 86.0, 75.7 mm, DISTANCE 1.16 mm, 847 and 72.2 mm
# beyond) PASS since a step's doubt counts from the frame the firmware took before:
# ``tests/test_doubt_taken_before.py``.
