"""`odocan fleet` overloaded (the loop one tick in 10-30): a correct firmware is never FAILed.

Found under load 13-14 (``odocan fleet -n 50 --workers 2``, deadline_miss_ratio ~0.99): the
bridge's live judge FAILed correct firmwares (Python 15-50 of 50 robots, C 23-50 of 50; "heading
vs reference 62.81 mrad"). Reproduced here without load: a fake clock makes the fleet's loop
(``sim.fleet.run_realtime``) run on time for ``CALM_TICKS``, then every tick 9-29 releases
late. Each such tick comes 10-30 periods after the previous one, so every board runs it as a
halted MCU's (``sim.board.HALT_AFTER_S``: its receive FIFO keeps 3 frames, overruns the rest):
the firmware lost frames the bus carried, took the gaps as single steps and, seconds on, re-primed
on steps too long to read (COUNTER_RESET): its pose leaves the all-frames reference for the
loop's reasons, not its arithmetic.

Before the halts the evidence is whole: an independent float64 checker (``tests/
independent_checker.py``: cantools decoding, odometry of its own, never ``host.judge``) reads the
robot's frames up to the first halt and says whether the firmware was right there. The fleet's
verdict must then never be FAIL for the right firmware: PASS when the stretches between the
halts judged most samples (``host.mqtt.haltstretch``; ``test_fleet_overload_stretches.py``),
else as before the stretches (UNJUDGED with the overload's numbers, or PASS where the judge
followed it); FAIL for one 2 LSB off before the halts.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import pytest

from odocan.firmware import frames as fw_frames
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.sim.board import TICK_S
from tests.overloaded_fleet import (
    FIRMWARES,
    LateTicksClock,
    checked_before,
    ready,
    run_overloaded,
)

SEED = 2
ROBOTS = 3
CALM_TICKS = 300  # the loop on time for 3 s of bus time
DURATION_S = 30.0
LATE_RELEASES = (0, 29)  # then every tick 0-29 releases late (seeded): mostly halts
WRONG_FROM_SAMPLE = 100  # the wrong firmware: x 2 LSB off from its 100th ODOM_POSE_X (2 s)


class StarvedClock(LateTicksClock):
    """The loop on time for the first ``CALM_TICKS`` releases, then every tick 0-29 whole
    periods late (seeded)."""

    def __init__(self) -> None:
        super().__init__()
        self.rng = random.Random(SEED)

    def late(self) -> int:
        return self.rng.randint(*LATE_RELEASES) if self.k >= CALM_TICKS else 0


def _starved_fleet(
    monkeypatch: pytest.MonkeyPatch, firmware: str = "python"
) -> tuple[dict[str, Any], list[list[str]], list[float | None]]:
    """The fleet report's ``per_robot`` after the starved run, each robot's frames as candump
    lines, and the bus time of its first halted tick."""
    run = run_overloaded(monkeypatch, StarvedClock, robots=ROBOTS, seed=SEED,
                         duration_s=DURATION_S, firmware=firmware)
    assert run.skipped_releases > 1000  # the premise: starved
    return run.per_robot, run.lines, run.halted


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_a_starved_fleet_does_not_fail_its_correct_firmwares(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, firmware: str
) -> None:
    per_robot, lines, halted = _starved_fleet(monkeypatch, ready(firmware))
    off = 0
    for index, (name, entry) in enumerate(per_robot.items()):
        from_s = halted[index]
        assert from_s is not None
        assert CALM_TICKS * TICK_S - TICK_S <= from_s < 4.0, from_s  # soon after the calm
        right = checked_before(tmp_path, lines[index], from_s)
        assert right.samples > 100, right
        assert right.passed, right  # the firmware was right up to the first halt
        if entry["pose_vs_reference"]["max_dheading_rad"] > HEADING_LSB_RAD \
                or entry["max_dpos_beyond_allowance_m"] > POSITION_LSB_M:
            off += 1  # the judge did not follow it through the halts: never blamed for it
        assert entry["verdict"] in ("PASS", "UNJUDGED"), (name, entry["reason"])
        stretches = entry["halt_stretches"]
        assert stretches["first_wrong"] is None, stretches
        judged_most = stretches["samples_judged"] >= stretches["samples_after_first_halt"] / 2
        if entry["verdict"] == "PASS" and judged_most:  # the stretches between halts judged
            assert entry["reason"].startswith("PASS: no sample wrong before the loop first "
                                              f"halted the robot at {from_s:.2f} s"), \
                entry["reason"]
            continue
        assert not judged_most, stretches  # the halts too close: as before the stretches
        if entry["verdict"] == "PASS":  # followed throughout
            assert entry["reason"].startswith("PASS on the samples the judge could follow; "
                                              f"overloaded: from {from_s:.2f} s"), entry["reason"]
            continue
        assert entry["reason"].startswith(f"overloaded: from {from_s:.2f} s of bus time"), \
            entry["reason"]
        assert "periods apart" in entry["reason"]
        assert "releases skipped" in entry["reason"]
    assert off >= 1  # the premise: all samples judged alike, a correct firmware was FAILed


def test_a_firmware_2_lsb_off_before_the_halts_still_fails(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    real = fw_frames.pack_odom_pose_x
    sent = [0]

    def off(counter: int, enc: int, x_100um: int, heading_bam16: int, errors: Any) -> bytes:
        sent[0] += 1  # both robots' frames: from about the 50th of each
        wrong = 2 if sent[0] > WRONG_FROM_SAMPLE else 0
        return real(counter, enc, x_100um + wrong, heading_bam16, errors)

    monkeypatch.setattr(fw_frames, "pack_odom_pose_x", off)
    per_robot, lines, halted = _starved_fleet(monkeypatch)
    for index, entry in enumerate(per_robot.values()):
        from_s = halted[index]
        assert from_s is not None
        wrong = checked_before(tmp_path, lines[index], from_s)
        assert wrong.max_position_error_m > 1.5e-4, wrong  # the checker sees the 2 LSB
        assert entry["verdict"] == "FAIL", entry["reason"]
        assert entry["reason"].startswith(
            f"pose vs reference wrong before the loop halted the robot at {from_s:.2f} s"
        ), entry["reason"]
