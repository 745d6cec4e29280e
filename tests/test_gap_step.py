"""A firmware 1 mm off after one gap of a delay drive FAILs every judge (issue #11, rule 5).

Under ``--faults delay`` the accepted encoder sequence has a gap at nearly every frame held back
(about 90 in 10 s on kobuki), and each gap's placement re-places the reference where the
firmware is, within an allowance. The bound was the allowances summed since the start: by 5 s
on kobuki, seed 2, ``delay=0.1:15`` 1.86 mm, most of it from the E2E lock-out gaps of 15 to 18
periods (0.25 to 0.76 mm each, ``gapfill``'s twice the merge allowance over their frames), so a
log edited to add 1 mm of X from 5 s on PASSed the whole-log, the streamed and the live judge:
the gap at the edit asked 1.04 mm against 1.96 mm. What one gap can move the firmware is that
gap's own allowance: each placement's step from the placement before is now bounded by the
allowances between them (``breaks.placed_step``).

The wrong firmware is the Python firmware with 1 mm of X added once, at the encoder step it
takes right after the ``AFTER_GAPS``-th gap it saw (E2E OKSOMELOST). The checker is the test's
own: python-can reads both logs of a pair (the same seed: the same drive), cantools checks the
Profile 2 CRCs and decodes ODOM_POSE_X; the wrong firmware's X is the right one's until the
step and exactly 10 LSB (1 mm) more from there on, and the right one's log PASSes everywhere.
"""

from __future__ import annotations

from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import can
import cantools.autosar
import pytest

from odocan.host.cli.app import main
from tests.dbc_typed import dbc_attribute, load_can_dbc
from tests.firmware_patch import after_gap, edited_after, x_added
from tests.test_gap_fill import DBC, X_LSB_Q40, _verdicts

WRONG_LSB = 10  # 1 mm of X
SEEDS = (2, 3, 7)
AFTER_GAPS = (25, 45)  # the wrong step follows the 25th or the 45th gap the firmware saw
ROBOTS = ("kobuki", "pmir")


def _adds_once_after_a_gap(lsb: int, after: int) -> AbstractContextManager[list[int]]:
    """The Python firmware, but ``lsb`` LSB of X added once, at the encoder step it takes right
    after the ``after``-th frame its encoder receiver accepted as OKSOMELOST (a gap); yields a
    list that holds 1 once the step was made."""
    return edited_after(after_gap(after), x_added(lsb * X_LSB_Q40))


def _drive(tmp: Path, robot: str, seed: int, after: int | None) -> dict[str, Any]:
    log = tmp / f"{robot}-{seed}-{after}.log"
    args = ["run", "--robot", robot, "--duration", "10", "--seed", str(seed),
            "--faults", f"delay=0.1:15,seed={seed}", "--log", str(log), "--firmware", "python"]
    with _adds_once_after_a_gap(WRONG_LSB if after else 0, after or 0) as done:
        code = main(args)
    return {"run": code, "log": log, "robot": robot, "steps": done[0]}


def _pose_x_raw(log: Path) -> list[tuple[float, int]]:
    """(bus time, raw X) of the log's ODOM_POSE_X frames whose CRC holds (cantools)."""
    db = load_can_dbc(DBC)
    message = db.get_message_by_name("ODOM_POSE_X")
    ids = [int(v) for v in dbc_attribute(message, "E2EDataIDs").split(",")]
    out = []
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            data = bytes(msg.data)
            if msg.arbitration_id == message.frame_id and cantools.autosar.check_profile2_crc(
                    data, ids[data[1] & 0xF]):
                signals = message.decode(data, decode_choices=False, scaling=False)
                assert isinstance(signals, dict)
                x_raw = signals["X"]
                assert isinstance(x_raw, int)
                out.append((msg.timestamp, x_raw))
    return out


@pytest.fixture(scope="module", params=ROBOTS)
def pairs(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> list[tuple[dict[str, Any], list[dict[str, Any]]]]:
    """Per seed, the right firmware's drive and the wrong ones' (one per ``AFTER_GAPS``)."""
    tmp = tmp_path_factory.mktemp(f"gapstep-{request.param}")
    return [(_drive(tmp, request.param, seed, None),
             [_drive(tmp, request.param, seed, after) for after in AFTER_GAPS])
            for seed in SEEDS]


def test_the_wrong_firmware_is_1_mm_off_from_one_step_on(
        pairs: list[tuple[dict[str, Any], list[dict[str, Any]]]]) -> None:
    """The premise, by the test's own checker: the same drive, X 0 LSB apart before the step
    and exactly 10 LSB apart from some pose frame on."""
    for right, wrongs in pairs:
        ok = _pose_x_raw(right["log"])
        for wrong in wrongs:
            assert wrong["steps"] == 1, wrong["log"]
            bad = _pose_x_raw(wrong["log"])
            assert [t for t, _ in bad] == [t for t, _ in ok]
            apart = [b - a for (_, a), (_, b) in zip(ok, bad, strict=True)]
            first = apart.index(WRONG_LSB)
            assert set(apart[:first]) == {0}
            assert set(apart[first:]) == {WRONG_LSB}
            assert 0.1 * len(apart) < first < 0.9 * len(apart)  # mid-drive


def test_the_right_firmware_passes_every_judge(
        pairs: list[tuple[dict[str, Any], list[dict[str, Any]]]]) -> None:
    for right, _ in pairs:
        verdicts = _verdicts(right)
        assert all(verdicts.values()), (right["log"], verdicts)


def test_a_firmware_1_mm_off_after_one_gap_fails_every_judge(
        pairs: list[tuple[dict[str, Any], list[dict[str, Any]]]]) -> None:
    for _, wrongs in pairs:
        for wrong in wrongs:
            verdicts = _verdicts(wrong)
            assert not any(verdicts.values()), (wrong["log"], verdicts)
