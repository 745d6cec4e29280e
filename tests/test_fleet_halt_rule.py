"""`odocan fleet` overloaded: the halt judges against the judges' one LSB (issue #11).

The DBC gives the pose signals' resolution (0.1 mm, 2 pi / 65536 rad), not how a firmware gets
there: ours rounds to nearest; another may round otherwise and stay within one LSB of its pose,
which the main judges' limit (one LSB: ``analyze``, the live tracker, the tests' checker)
passes. The halt judges (``host.mqtt.haltpath``) allow each sample only the rounding's half LSB
(+ 0.01): a firmware whose X is rounded and then moved 0.35 LSB away from zero (X within 0.85
LSB of its pose, Y within 0.5: within 0.99 LSB) FAILs across the fleet's halts where X changes
sign ("x 0.04 LSB beyond the pose signals' rounding"), where its samples before the halts pass
the tests' independent checker: a FAIL that blames a firmware within the judges' limit, kept
here as a strict xfail. Allowing one LSB a sample (and a base) fixes it, but the halt's ways
(FIFO, merged, primed: up to 0.8 LSB of X apart) are then no longer told apart by the samples,
and a drift hides in their choice halt after halt: X 0.09 LSB a halt over 60 s (7 LSB off by the
end) PASSed (``test_fleet_halt_carry``, 4 of 15 with three times its shifts); measured again
(``haltpath``'s half LSB made one, base and sample alike): this test PASSes, the 2 LSB and 10 mm
firmwares still FAIL, but 14 of ``test_fleet_halt_carry``'s 15 drifts PASS as they stand (X
0.15 LSB a halt, 13 halts in 12 s, ~2 LSB off by the end; X 0.03 over 60 s, 78 halts, ~2 LSB;
HEADING 0.1 alone still FAILs). With one LSB a sample, a stretch's samples pin its offset to
some 1 LSB, wider than the ways' spread, and a sequence of ways then explains the drift within
one LSB a sample: from the bus alone, such a drift cannot be told from a one-LSB firmware that
took other ways. Left for a rule that keeps the ways apart by other evidence (or a decision on
which contract the halts judge). A firmware 2 LSB or 10 mm off from a halt on FAILs.

The independent proof: the lockstep run is deterministic, so the runs' frames are the correct
run's byte for byte but for ODOM_POSE_X's X (cantools), 0 or 1 LSB away from zero for the
first, exactly 2 more from the halt on for the second.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from odocan.firmware import frames as fw_frames
from odocan.firmware import reports as fw_reports
from tests.overloaded_fleet import checked_before
from tests.test_fleet_halt_edges import RecordingClock, recorded_run
from tests.test_fleet_overload_stretches import x_changes, x_off_times

AWAY_PERCENT = 35  # the first firmware's X: rounded, then 0.35 LSB away from zero


def _x_away_from_zero(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every robot's X signal rounded after moving it ``AWAY_PERCENT`` % of an LSB away from
    zero (``reports`` converts X, then Y, each pose: the odd calls are X's)."""
    calls = [0]

    def convert(value: int, scale: int, shift: int, errors: Any) -> int:
        calls[0] += 1
        product = value * scale
        away = (AWAY_PERCENT << shift) // 100 if calls[0] % 2 else 0
        return (product + (1 << (shift - 1)) + (away if product >= 0 else -away)) >> shift

    monkeypatch.setattr(fw_reports, "mul_shr_round_i64", convert)


def _x_moved(right: list[str], moved: list[str]) -> set[int]:
    """The moved run's X minus the right run's, times the sign of X (LSB): every other frame
    and signal the same (cantools)."""
    return {(x_moved - x_right) * (1 if x_moved >= 0 else -1)
            for _t_s, x_right, x_moved in x_changes(right, moved)}


@pytest.mark.xfail(strict=True, reason="halt judges allow the rounding's half LSB, not the "
                   "judges' one (module docstring): a firmware within one LSB (X 0.85, Y 0.5) "
                   "FAILs, x 0.04 LSB beyond; one LSB a sample and a base PASSes it but hides "
                   "14 of test_fleet_halt_carry's 15 drifts (X 0.15 LSB a halt, ~2 LSB off by "
                   "12 s; X 0.03 over 60 s, 78 halts): the ways a halt allows (up to 0.8 LSB "
                   "apart) are no longer told apart")
def test_a_firmware_within_one_lsb_passes_the_halts(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    right = recorded_run(monkeypatch)
    _x_away_from_zero(monkeypatch)
    moved = recorded_run(monkeypatch)
    assert _x_moved(right.lines[0], moved.lines[0]) == {1}  # X moved 1 LSB away, when it is
    for index, entry in enumerate(moved.per_robot.values()):
        from_s = moved.halted[index]
        assert from_s is not None
        before = checked_before(tmp_path, moved.lines[index], from_s)
        assert before.passed, before  # within one LSB before the halts, from power-up
        assert before.max_position_error_m > 0.6e-4  # beyond the rounding's half LSB
        assert list(right.per_robot.values())[index]["verdict"] == "PASS"
        assert entry["verdict"] == "PASS", entry["reason"]


@pytest.mark.parametrize("off_lsb", [2, 100])  # 0.2 mm; 10 mm
def test_a_firmware_beyond_one_lsb_from_a_halt_fails(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, off_lsb: int
) -> None:
    right = recorded_run(monkeypatch)
    real = fw_frames.pack_odom_pose_x

    def off(counter: int, enc: int, x_100um: int, heading_bam16: int, errors: Any) -> bytes:
        clock = RecordingClock.latest_recording
        after_halt = clock is not None and bool(clock.halt_ticks) and \
            clock.running - clock.halt_ticks[0] >= 1
        return real(counter, enc, x_100um + (off_lsb if after_halt else 0), heading_bam16,
                    errors)

    monkeypatch.setattr(fw_frames, "pack_odom_pose_x", off)
    wrong = recorded_run(monkeypatch)
    for index, entry in enumerate(wrong.per_robot.values()):
        from_s = wrong.halted[index]
        assert from_s is not None
        assert x_off_times(right.lines[index], wrong.lines[index], off_lsb)
        assert checked_before(tmp_path, wrong.lines[index], from_s).passed
        assert entry["verdict"] == "FAIL", entry["reason"]
        assert entry["reason"].startswith(
            f"pose vs reference wrong after the loop halted the robot at {from_s:.2f} s: x "
        ), entry["reason"]
