"""The live judge on captures of delayed drives, jittered or not, judges the E2E lock-out's gaps
as ``analyze`` does (issue #11: one judge; rule 5: a FAIL never blames a correct firmware, a
PASS never hides a wrong pose).

A ``delay`` fault holds encoder frames back; after taking a late frame the firmware's E2E
lock-out refuses the on-time frames until the COUNTER comes round (``host.judge.gapfill``). On a
capture whose stamps are 0..3 ms late (``test_capture_jitter``) the host's window, widened by
the capture tolerance, takes some lock-out frames the firmware refused, and the firmware holds
its pose over them (a hold, ``stalls._frozen``) between the lock-out's gaps. There:

- the live judge, placing the reference for the lock-out's gaps, left the hold's allowance out
  (``analyze`` adds it): the correct firmware FAILed live (pmir, seed 7, ``delay=0.1:15``,
  jitter seed 5: 0.177 mm; ``tracking``);
- the hold's allowance was ``gapbound``'s worst case over the whole span (0.6 m), although the
  log fills every gap in it: a firmware adding 1 mm of X after each lock-out PASSed ``analyze``
  (kobuki, seed 305, ``delay=0.1:20``, jitter seed 2; ``spanfill``).

The wrong firmware is ``test_lockout_fill``'s (1 mm of X at each step it takes after refusing 4
or more frames in a row); the jitter is ``test_capture_jitter``'s.
"""

from __future__ import annotations

from contextlib import nullcontext
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.sim.robot import load
from tests.test_capture_jitter import _jittered, _live_passes
from tests.test_lockout_fill import WRONG_LSB, _adds_after_lock_outs

DURATION_S = 6
MIN_HIDDEN = 5  # the wrong firmware's 1 mm steps a drive must hold (else it is not wrong)
Drive = tuple[str, int, int]  # robot, seed, delay (ms)
drives = st.tuples(st.sampled_from(["kobuki", "pmir"]), st.integers(0, 1000),
                   st.sampled_from([15, 20]))
jitters = st.one_of(st.none(), st.integers(0, 2**32 - 1))  # None: the capture as recorded
SWEEP = settings(max_examples=4, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.too_slow,
                                        HealthCheck.function_scoped_fixture])


def _verdicts(tmp_path: Path, drive: Drive, hiding: bool, jitter_seed: int | None,
              duration_s: int = DURATION_S) -> tuple[dict[str, bool], int]:
    """PASS (True) or FAIL of the whole-log ``analyze``, the streamed one (the CLI's) and the
    live judge on ``drive``'s log (jittered by ``jitter_seed``), and the 1 mm steps the wrong
    firmware took (``hiding``; 0 for the right one)."""
    robot, seed, delay_ms = drive
    log, moved = tmp_path / "drive.log", tmp_path / "moved.log"
    argv = ["run", "--robot", robot, "--duration", str(duration_s), "--seed", str(seed),
            "--faults", f"delay=0.1:{delay_ms},seed={seed}", "--log", str(log)]
    with _adds_after_lock_outs(WRONG_LSB) if hiding else nullcontext([0]) as steps:
        main(argv)
    if jitter_seed is None:
        moved = log
    else:
        _jittered(log, moved, jitter_seed)
    return {
        "whole": analyze(read_log(moved), load(robot)).passed,
        "streamed (CLI)": main(["analyze", str(moved), "--robot", robot]) == 0,
        "live": _live_passes(moved, robot),
    }, steps[0]


@SWEEP
@given(drive=drives, jitter_seed=jitters)
@example(drive=("pmir", 7, 15), jitter_seed=5)  # the hold left out live (was 0.177 mm)
def test_the_live_verdict_is_the_whole_ones_for_a_correct_firmware(
        tmp_path: Path, drive: Drive, jitter_seed: int | None) -> None:
    verdicts, _ = _verdicts(tmp_path, drive, False, jitter_seed)
    assert verdicts["live"] == verdicts["whole"], verdicts
    assert all(verdicts.values()), verdicts


@SWEEP
@given(delay_ms=st.sampled_from([15, 20]), jitter_seed=jitters)
@example(delay_ms=20, jitter_seed=2)  # the hold over filled gaps: PASSed analyze
def test_a_firmware_hiding_1_mm_after_each_lock_out_fails_everywhere(
        tmp_path: Path, delay_ms: int, jitter_seed: int | None) -> None:
    """On ``test_lockout_fill``'s drive (kobuki, seed 305, 10 s), jittered or not."""
    verdicts, hidden = _verdicts(tmp_path, ("kobuki", 305, delay_ms), True, jitter_seed, 10)
    assert hidden >= MIN_HIDDEN  # the premise: lock-outs, and the wrong firmware hid its mm
    assert not any(verdicts.values()), verdicts


def test_a_firmware_hiding_1_mm_fails_live_where_the_last_frame_of_a_gap_is_late(
        tmp_path: Path) -> None:
    """Found by the sweep's domain (the capture as recorded): ``analyze`` FAILed the wrong
    firmware, the live judge PASSed it: the gap was placed before its held-back frame was heard,
    with gapbound's allowance (24.9 mm). The live placer's late refill (``liveplace._refill``:
    the step's bound takes the fill's allowance when the frame comes; the budget from the start
    keeps the old one, which the start fit's corrections need) makes it FAIL live."""
    verdicts, _ = _verdicts(tmp_path, ("kobuki", 7, 15), True, None)
    assert not verdicts["live"], verdicts


@pytest.mark.xfail(strict=True, reason="open: on this capture the host's E2E model (capture "
                   "tolerance) takes 499 encoder frames where the firmware took 347, 139 poses "
                   "match none, and the hold's allowance (2 x merge over 58 frames) is 17.5 mm")
def test_a_firmware_hiding_1_mm_fails_where_the_host_took_the_lock_outs_frames(
        tmp_path: Path) -> None:
    """Found by the sweep's domain (pmir and kobuki, seed 3, jitter seed 0): all three judges
    PASS the wrong firmware (on main too). Not the live judge's: ``analyze`` PASSes it."""
    verdicts, _ = _verdicts(tmp_path, ("pmir", 3, 15), True, 0)
    assert not any(verdicts.values()), verdicts
