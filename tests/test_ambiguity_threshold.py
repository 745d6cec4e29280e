"""A silence within a period of the ambiguity threshold: the judges follow the firmware (issue #11,
rule 3: a FAIL must never blame a correct firmware).

The firmware decides whether a step is too long to read (``firmware/ambiguity.py``) on its own
clock: the frames' COUNTER advance plus the whole COUNTER cycles nearest the ticks since the
last accepted frame. The judges count those ticks on bus time. A log's times jitter (a recorder's
stamps, a loaded host): 0.6 period off is enough for the judges to round the silence to the
other side of a half cycle, so near the threshold they re-primed where the firmware integrated,
or integrated where it re-primed, and FAILed a correct firmware either way.

The drives: the lockstep rig's straight drive on kobuki (16-bit counters, 84 counts a period
at most: ambiguous from 391 periods), its motor controller muted so the silence between two
encoder frames is the threshold's less one, the threshold and one more periods (its COUNTER
advances 1 across it); the log's times after the silence then moved 0.6 period towards the
other side. Python and C firmware. The test's own float64 checker: the firmware's rule on the
rig's exact periods (the lockstep clock is the bus's), the firmware's COUNTER_RESET in its
status (cantools) telling the same, float64 odometry (the step taken or not) matching its pose.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import pytest

from odocan.sim.board import TICK_S
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.dbc_typed import decode, number
from tests.fault_rig import FaultRig
from tests.test_silence_gap import ROBOT, _db, _least_ambiguous_periods, _verdicts

FROM_S = 3.0  # the silence starts (s)
DRIVE_S = 12.0
JITTER_PERIODS = 0.6  # the log's times after the silence moved by this (periods)
COUNTER_RESET_BIT = 1 << 9  # ERROR_MASK (the DBC's comment)


def _threshold() -> int:
    """The fewest elapsed periods (a COUNTER advance of 1) whose firmware bound, 1 + the whole
    16-period cycles nearest the rest, reaches the ambiguous step (float64 here)."""
    least = _least_ambiguous_periods(load(ROBOT))
    elapsed = 1
    while 1 + 16 * math.floor((elapsed - 1) / 16 + 0.5) < least:
        elapsed += 1
    return elapsed


def _drive(tmp: Path, elapsed: int, firmware: str, shift_periods: float) -> Path:
    """The straight drive, ``elapsed`` periods between the two encoder frames around the
    silence, the log's times from the silence on moved by ``shift_periods``."""
    profile = load(ROBOT)
    heard: list[Any] = []
    first = round(FROM_S / TICK_S)
    muted = range(first, first + elapsed - 1)
    plan = get_scenario("straight", profile, seed=0, duration_s=DRIVE_S)
    with FaultRig(robot=ROBOT, scenario=plan, seed=0, firmware=firmware) as rig:
        rig.observers.append(lambda _k, frames: heard.extend(frames))
        rig.mute_sim(muted)
        rig.run(DRIVE_S)
    shift_s = shift_periods * TICK_S
    path = tmp / f"{firmware}-{elapsed}-{shift_periods:+g}.log"
    path.write_text("".join(
        f"({m.timestamp + (shift_s if m.timestamp > FROM_S else 0.0):.6f}) vcan0 "
        f"{m.arbitration_id:03X}#{m.data.hex().upper()}\n" for m in heard))
    return path


def _premise(path: Path, shift_periods: float) -> tuple[int, bool]:
    """The silence's exact periods (the log's times less the shift) and whether the firmware
    set COUNTER_RESET after it (clear before), by cantools."""
    db = _db()
    stamps, masks = [], []
    for line in path.read_text().splitlines():
        stamp, _, frame = line.split()[:3]
        t_s = float(stamp.strip("()"))
        t_s -= shift_periods * TICK_S if t_s > FROM_S + shift_periods * TICK_S else 0.0
        head, payload = frame.split("#")
        name = db.get_message_by_frame_id(int(head, 16)).name
        if name == "WHEEL_ENCODERS":
            stamps.append(t_s)
        elif name == "ODOM_STATUS" and bytes.fromhex(payload)[1] >> 4 == 0:
            s = decode(db, int(head, 16), bytes.fromhex(payload), decode_choices=False)
            masks.append((t_s, int(number(s["ERROR_MASK"]))))
    gaps = [(b - a, a, b) for a, b in itertools.pairwise(stamps)]
    longest, _a_s, b_s = max(gaps)
    assert all(mask & COUNTER_RESET_BIT == 0 for t_s, mask in masks if t_s < b_s)
    after = [mask for t_s, mask in masks if t_s > b_s + 2 * TICK_S]
    return round(longest / TICK_S), bool(after[0] & COUNTER_RESET_BIT)


CASES = ((-1, JITTER_PERIODS), (0, -JITTER_PERIODS), (1, -JITTER_PERIODS), (0, JITTER_PERIODS))


@pytest.mark.parametrize("firmware", ["python", "c"])
@pytest.mark.parametrize(("offset", "shift"), CASES)
def test_a_silence_near_the_threshold_passes_a_correct_firmware(
        tmp_path: Path, firmware: str, offset: int, shift: float) -> None:
    threshold = _threshold()
    path = _drive(tmp_path, threshold + offset, firmware, shift)
    elapsed, reprimed = _premise(path, shift)
    assert elapsed == threshold + offset
    assert reprimed == (offset >= 0)  # the firmware's rule, float64: its status agrees
    verdicts = _verdicts(path, tmp_path)
    assert all(verdicts.values()), (path.name, verdicts)
