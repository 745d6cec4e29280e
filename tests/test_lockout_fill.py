"""Gaps the firmware's E2E lock-out makes keep no worst-case allowance: the log holds their
frames (issue #11, rule 5; ``host.judge.gapfill``).

With frames held back 20 ms (``--faults delay=0.1:20``) the firmware sometimes takes a late
frame after refusing the on-time one that overtook it; its window, reset on the late frame,
widens one a tick while the COUNTER runs one a tick ahead, so it refuses every on-time frame
until the COUNTER comes round (up to 16 periods on one pose). The host's copy of the E2E check
refuses them as the firmware does, and they are on the bus, CRC good: the counts of every period
of such a gap are known. The judges placed them from the last accepted frame (the late one),
put their COUNTER 16 periods back, and bounded the gap as one of unknown frames (``gapbound``:
135 mm on the kobuki drive below, against 0.5 mm now); a firmware adding 1 mm of X at every step
it took after a lock-out passed ``run``, both ``analyze`` and the live judge (which knew nothing
of the refused frames).

The checker is the test's own: python-can reads the log, cantools checks the Profile 2 CRC and
decodes COUNTER; the firmware's receiver is modelled from its specification (it drains the
frames on the bus 1 ms after each 10 ms slot; COUNTER +1, or +2 .. +window with the window reset
on a frame taken and widened one a tick); a frame's sender number is the one of its COUNTER at
most 15 periods before its slot on the sender's 10 ms grid (the lockstep rig sends on it).
"""

from __future__ import annotations

import itertools
import json
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import can
import cantools.autosar
import pytest

from odocan.host.cli.app import main
from tests.dbc_typed import dbc_attribute, load_can_dbc
from tests.firmware_patch import LOCKED_OUT, after_lock_outs, edited_after, x_added
from tests.test_gap_fill import DBC, X_LSB_Q40, _verdicts

DRIVE = ["--duration", "10", "--seed", "305", "--faults", "delay=0.1:20,seed=305",
         "--firmware", "python"]  # the patched Python firmware, never auto's C
TICK_S, RECEIVE_LAG_S, WINDOW_MAX = 0.01, 0.001, 15
WRONG_LSB = 10  # 1 mm of X added after each lock-out


def _adds_after_lock_outs(lsb: int) -> AbstractContextManager[list[int]]:
    """The Python firmware, but ``lsb`` LSB of X added at each encoder step it takes after
    refusing ``LOCKED_OUT`` or more frames in a row; yields the list the count is kept in."""
    return edited_after(after_lock_outs, x_added(lsb * X_LSB_Q40), sticky=False)


def _drive(tmp: Path, lsb: int) -> dict[str, Any]:
    robot = "kobuki"
    log, report = tmp / f"drive{lsb}.log", tmp / f"report{lsb}.json"
    with _adds_after_lock_outs(lsb) as steps:
        code = main(["run", "--robot", robot, *DRIVE, "--log", str(log),
                     "--report", str(report)])
    return {"run": code, "log": log, "robot": robot, "steps": steps[0],
            "report": json.loads(report.read_text())}


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> dict[int, dict[str, Any]]:
    """The drive by the right firmware (0) and by one adding WRONG_LSB after lock-outs."""
    tmp = tmp_path_factory.mktemp("lockout")
    return {lsb: _drive(tmp, lsb) for lsb in (0, WRONG_LSB)}


def _lock_out_gaps(log: Path) -> tuple[int, int]:
    """(lock-out gaps, of them filled): gaps of ``LOCKED_OUT`` + 1 or more periods between the
    frames the firmware's receiver takes, and of them those whose every missing frame the log
    holds, CRC good, on the bus before the frame that ends the gap."""
    message = load_can_dbc(DBC).get_message_by_name("WHEEL_ENCODERS")
    ids = [int(v) for v in dbc_attribute(message, "E2EDataIDs").split(",")]
    frames: list[tuple[float, int]] = []  # (bus time, sender number)
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            data = bytes(msg.data)
            if msg.arbitration_id == message.frame_id and cantools.autosar.check_profile2_crc(
                    data, ids[data[1] & 0xF]):
                first_s = frames[0][0] if frames else msg.timestamp
                slot = int((msg.timestamp - first_s) / TICK_S + 1e-6)
                frames.append((msg.timestamp, slot - ((slot - (data[1] & 0xF)) % 16)))
    taken, window, last, i = [], 0, -1, 0
    for tick in range(1, round(frames[-1][0] / TICK_S) + 3):
        window = min(WINDOW_MAX, window + 1)
        while i < len(frames) and frames[i][0] <= (tick - 1) * TICK_S + RECEIVE_LAG_S:
            delta = (frames[i][1] - last) % 16
            if last < 0 or delta == 1 or 2 <= delta <= window:
                taken.append(i)
                window, last = 0, frames[i][1]
            i += 1
    gaps = filled = 0
    for before, after in itertools.pairwise(taken):
        lacking = set(range(frames[before][1] + 1, frames[after][1]))
        if len(lacking) >= LOCKED_OUT:
            gaps += 1
            filled += lacking <= {seq for _, seq in frames[:after]}
    return gaps, filled


def test_the_drive_has_lock_outs_the_log_fills(drives: dict[int, dict[str, Any]]) -> None:
    """The premise: lock-out gaps, every one filled by the log, and the wrong firmware added
    its 1 mm after many of them."""
    gaps, filled = _lock_out_gaps(drives[0]["log"])
    assert gaps >= 20
    assert filled == gaps, (gaps, filled)
    assert drives[WRONG_LSB]["steps"] >= 20


def test_the_right_firmware_passes_everywhere_with_small_gap_allowances(
        drives: dict[int, dict[str, Any]]) -> None:
    verdicts = _verdicts(drives[0])
    assert all(verdicts.values()), verdicts
    assert drives[0]["report"]["reference_breaks"]["gap_offset_allowance_m"] < 0.01


def test_a_firmware_adding_1_mm_after_lock_outs_fails_everywhere(
        drives: dict[int, dict[str, Any]]) -> None:
    verdicts = _verdicts(drives[WRONG_LSB])
    assert not any(verdicts.values()), verdicts
