"""`odocan fleet` overloaded: a firmware wrong at a halt's re-start FAILs (issue #11).

Found in the twelfth pass: each stretch between the loop's halts (``host.mqtt.haltstretch``)
re-started its reference at the firmware's pose 3 releases after the halt, so a firmware that
went wrong at the halt's re-start, or within the 3 releases after it, PASSed: the stretch began
from whatever pose it reported there. The frames the skipped releases sampled are all on the
bus, so the step across the halt is bounded by what the halted firmware could have done with
them (``host.mqtt.haltcross``): here X is 3 LSB off from the first or second release after a
halt (for good, or only for those two releases) and the robot FAILs, the halt named; the
correct firmware (Python and C) PASSes the same run with every sample after the halts judged
(``test_fleet_overload_stretches.py``, ``test_fleet_overload.py``).

Halts 10-30 releases long (``WideHaltingClock``) make the correct firmware refuse the first frame
or two after a halt and take the next as one step: a judge that knew only "merged or re-primed
on the first" FAILed it (seeds 1 and 4, ``x 13.53 LSB beyond ...``); the correct firmware must
PASS them with every sample after the first halt judged.

The independent proof that the firmware is wrong there and only there: the lockstep run is
deterministic, so its frames are the correct run's byte for byte but for the X signal (cantools
decoding), exactly 3 LSB more, from the injection on.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import pytest

from odocan.firmware import frames as fw_frames
from odocan.sim.board import HALT_AFTER_S, TICK_S
from tests.overloaded_fleet import (
    FIRMWARES,
    LateTicksClock,
    checked_before,
    ready,
    run_overloaded,
)
from tests.test_fleet_overload_stretches import (
    DURATION_S,
    ROBOTS,
    SEED,
    HaltingClock,
    x_off_times,
)

WRONG_LSB = 3


class RecordingClock(HaltingClock):
    """``HaltingClock`` that notes the loop tick of every halt (a tick run ``HALT_AFTER_S`` or
    more after the previous one) and tells the loop tick being run."""

    latest_recording: RecordingClock | None = None

    def __init__(self) -> None:
        super().__init__()
        self.halt_ticks: list[int] = []
        RecordingClock.latest_recording = self

    def late(self) -> int:
        late = super().late()
        if (late + 1) * TICK_S >= HALT_AFTER_S:
            self.halt_ticks.append(self.k + late)
        return late

    @property
    def running(self) -> int:
        """The loop tick being run (``now_s`` moved ``k`` past it)."""
        return self.k - 1


def recorded_run(monkeypatch: pytest.MonkeyPatch) -> Any:
    run = run_overloaded(monkeypatch, RecordingClock, robots=ROBOTS, seed=SEED,
                         duration_s=DURATION_S)
    assert run.halts >= 10, run.halts
    return run


@pytest.mark.parametrize(("halt", "first", "last"), [
    (0, 1, None),  # the first halt, from its first release on, for good
    (2, 2, None),  # the third halt, from its second release on, for good
    (2, 1, 2),  # the third halt, its first two releases only
    (4, 2, 3),  # the fifth halt, its second and third releases only (a pose frame each)
])
def test_a_firmware_wrong_at_a_halts_restart_fails(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, halt: int, first: int, last: int | None
) -> None:
    right = recorded_run(monkeypatch)
    real = fw_frames.pack_odom_pose_x

    def off(counter: int, enc: int, x_100um: int, heading_bam16: int, errors: Any) -> bytes:
        clock = RecordingClock.latest_recording
        wrong = 0
        if clock is not None and len(clock.halt_ticks) > halt:
            after = clock.running - clock.halt_ticks[halt]
            if first <= after and (last is None or after <= last):
                wrong = WRONG_LSB
        return real(counter, enc, x_100um + wrong, heading_bam16, errors)

    monkeypatch.setattr(fw_frames, "pack_odom_pose_x", off)
    wrong = recorded_run(monkeypatch)
    clock = RecordingClock.latest_recording
    assert clock is not None
    for index, entry in enumerate(wrong.per_robot.values()):
        from_s = wrong.halted[index]
        assert from_s is not None
        halt_s = (clock.halt_ticks[halt] - index % 2) * TICK_S  # robot 1 runs a tick late
        off_s = x_off_times(right.lines[index], wrong.lines[index], WRONG_LSB)
        assert off_s, "the injection reached no pose frame"
        assert halt_s < off_s[0] <= halt_s + (first + 1) * TICK_S + 0.002, (halt_s, off_s)
        if last is not None:
            assert off_s[-1] <= halt_s + (last + 1) * TICK_S + 0.002, (halt_s, off_s)
        assert checked_before(tmp_path, wrong.lines[index], from_s).passed
        assert list(right.per_robot.values())[index]["verdict"] == "PASS"
        assert entry["verdict"] == "FAIL", entry["reason"]
        assert entry["reason"].startswith(
            f"pose vs reference wrong after the loop halted the robot at {from_s:.2f} s: x "
        ), entry["reason"]
        assert f"across the halt at {halt_s:.2f} s" in entry["reason"], entry["reason"]


class WideHaltingClock(LateTicksClock):
    """On time for 3 s, then a halt 10-30 releases long every ``period`` ticks run and a tick
    1-8 late now and then (seeded by ``seed``)."""

    seed, period = 0, 40

    def __init__(self) -> None:
        super().__init__()
        self.ran = 0
        self.rng = random.Random(self.seed)

    def late(self) -> int:
        if self.k < 300:
            return 0
        self.ran += 1
        if self.ran % self.period == 1:
            return self.rng.randint(10, 30)
        return self.rng.randint(1, 8) if self.ran % 10 == 5 else 0


@pytest.mark.parametrize("firmware", FIRMWARES)
@pytest.mark.parametrize(("seed", "period"), [(1, 25), (4, 40)])
def test_a_correct_firmware_passes_long_halts_every_sample_judged(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, firmware: str, seed: int, period: int
) -> None:
    clock = type("Clock", (WideHaltingClock,), {"seed": seed, "period": period})
    run = run_overloaded(monkeypatch, clock, robots=ROBOTS, seed=seed, duration_s=10.0,
                         firmware=ready(firmware))
    assert run.halts >= 7, run.halts
    for index, entry in enumerate(run.per_robot.values()):
        from_s = run.halted[index]
        assert from_s is not None
        assert checked_before(tmp_path, run.lines[index], from_s).passed
        assert entry["verdict"] == "PASS", entry["reason"]
        stretches = entry["halt_stretches"]
        assert stretches["first_wrong"] is None, stretches
        assert stretches["samples_judged"] == stretches["samples_after_first_halt"], stretches
        assert stretches["restarts_judged"] >= stretches["restarts"] - 1, stretches
