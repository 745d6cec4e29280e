"""`odocan fleet` overloaded now and then: the stretches between the loop's halts are judged.

Found in the eleventh pass's trial (one robot in three): a firmware that went wrong only after
the loop's first halt still PASSed, or was UNJUDGED, because only the samples before the first
halt were judged (``host.mqtt.overload``), and after a halt the reference re-starts where the
firmware is. Here a fake clock runs the fleet's loop (``sim.fleet.run_realtime``) on time for
``CALM_TICKS``, then halts every board once every ``PERIOD_TICKS`` ticks (a tick 12-20 releases
late: ``sim.board.HALT_AFTER_S``), with a few late ticks short of a halt in between (skipped
releases whose encoder samples go out late, which the firmware takes one by one).

- A correct firmware (Python and C) is never FAILed: PASS, with the stretches between the
  halts judged (a sample of each compared), the firmware right before the first halt by an
  independent float64 checker (``tests/independent_checker.py``).
- A firmware whose X goes 3 LSB off in the middle of the second stretch (well after the first
  halt) FAILs, naming the stretch. The independent proof that it is wrong there and only there:
  the lockstep run is deterministic, so its frames are the correct run's byte for byte but for
  the X signal, exactly 3 LSB more from the injection on.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import pytest

from odocan.firmware import frames as fw_frames
from odocan.sim.board import TICK_S
from odocan.sim.contract import DBC_PATH
from tests.dbc_typed import load_can_dbc, numbers
from tests.overloaded_fleet import (
    FIRMWARES,
    LateTicksClock,
    checked_before,
    ready,
    run_overloaded,
)

SEED = 5
ROBOTS = 2
CALM_TICKS = 300  # on time for 3 s of bus time
PERIOD_TICKS = 40  # then a halt every 40 ticks run
HALT_LATE = (12, 20)  # releases late: a halted MCU (>= 9.5 periods)
SHORT_LATE = (1, 8)  # a few ticks late short of a halt, between the halts
DURATION_S = 12.0
WRONG_FROM = PERIOD_TICKS + PERIOD_TICKS // 2  # ticks run after the calm: mid second stretch
WRONG_LSB = 3


class HaltingClock(LateTicksClock):
    """The loop on time for ``CALM_TICKS``, then a halt every ``PERIOD_TICKS`` ticks run and a
    few late ticks short of one between (module docstring)."""

    latest: HaltingClock | None = None

    def __init__(self) -> None:
        super().__init__()
        self.ran = 0  # ticks run after the calm
        self.rng = random.Random(SEED)
        HaltingClock.latest = self

    def late(self) -> int:
        if self.k < CALM_TICKS:
            return 0
        self.ran += 1
        if self.ran % PERIOD_TICKS == 1:
            return self.rng.randint(*HALT_LATE)
        return self.rng.randint(*SHORT_LATE) if self.ran % 10 == 5 else 0


def _run(monkeypatch: pytest.MonkeyPatch, firmware: str = "python"
         ) -> tuple[dict[str, Any], list[list[str]], list[float | None]]:
    """The fleet report's ``per_robot``, each robot's frames as candump lines, the bus time
    of its first halted tick."""
    HaltingClock.latest = None
    run = run_overloaded(monkeypatch, HaltingClock, robots=ROBOTS, seed=SEED,
                         duration_s=DURATION_S, firmware=firmware)
    assert run.halts >= 10, run.halts  # the premise: halted again and again
    return run.per_robot, run.lines, run.halted


def _right_before(tmp_path: Path, lines: list[str], until_s: float) -> bool:
    """The independent checker: the robot's pose right on its frames before ``until_s``."""
    verdict = checked_before(tmp_path, lines, until_s)
    return verdict.samples > 100 and verdict.passed


@pytest.mark.parametrize("firmware", FIRMWARES)
def test_a_correct_firmware_passes_every_stretch_between_halts(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, firmware: str
) -> None:
    per_robot, lines, halted = _run(monkeypatch, ready(firmware))
    for index, entry in enumerate(per_robot.values()):
        from_s = halted[index]
        assert from_s is not None
        assert CALM_TICKS * TICK_S - TICK_S <= from_s < 3.5, from_s
        assert _right_before(tmp_path, lines[index], from_s)
        assert entry["verdict"] == "PASS", entry["reason"]
        stretches = entry["halt_stretches"]
        assert stretches["first_wrong"] is None, stretches
        assert stretches["halts"] >= 10, stretches
        # a stretch after every halt (the last may leave no sample before the run's end)
        assert stretches["stretches"] >= stretches["halts"] - 1, stretches
        assert stretches["samples_judged"] > stretches["samples_after_first_halt"] // 2
        assert entry["reason"].startswith("PASS: no sample wrong before the loop first halted "
                                          f"the robot at {from_s:.2f} s"), entry["reason"]


def test_a_firmware_wrong_after_the_first_halt_fails(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    right, right_lines, _ = _run(monkeypatch)
    real = fw_frames.pack_odom_pose_x

    def off(counter: int, enc: int, x_100um: int, heading_bam16: int, errors: Any) -> bytes:
        clock = HaltingClock.latest
        wrong = WRONG_LSB if clock is not None and clock.ran >= WRONG_FROM else 0
        return real(counter, enc, x_100um + wrong, heading_bam16, errors)

    monkeypatch.setattr(fw_frames, "pack_odom_pose_x", off)
    wrong, wrong_lines, halted = _run(monkeypatch)
    for index, entry in enumerate(wrong.values()):
        from_s = halted[index]
        assert from_s is not None
        wrong_from_s = _x_off_from(right_lines[index], wrong_lines[index])
        assert wrong_from_s > from_s + PERIOD_TICKS * TICK_S  # well after the first halt
        assert _right_before(tmp_path, wrong_lines[index], from_s)
        assert list(right.values())[index]["verdict"] == "PASS"
        assert entry["verdict"] == "FAIL", entry["reason"]
        assert entry["reason"].startswith(
            f"pose vs reference wrong after the loop halted the robot at {from_s:.2f} s: x "
        ), entry["reason"]
        assert "inside the stretch re-started at" in entry["reason"]


def _x_off_from(right: list[str], wrong: list[str]) -> float:
    """Bus time (s) from which the wrong run's X is exactly ``WRONG_LSB`` more than the right
    run's, every other signal of every frame the same (cantools decoding)."""
    times = x_off_times(right, wrong)
    assert times
    return times[0]


def x_off_times(right: list[str], wrong: list[str], lsb: int = WRONG_LSB) -> list[float]:
    """Bus times (s) of the wrong run's frames that differ from the right run's: each an
    ODOM_POSE_X whose X is exactly ``lsb`` more, every other signal the same (cantools)."""
    times = []
    for t_s, x_right, x_wrong in x_changes(right, wrong):
        assert x_wrong - x_right == lsb, (t_s, x_right, x_wrong)
        times.append(t_s)
    return times


def x_changes(right: list[str], other: list[str]) -> list[tuple[float, int, int]]:
    """``(t_s, X right, X other)`` (raw) of each frame where two runs differ: each an
    ODOM_POSE_X at the same time, every signal but X and CHECKSUM the same (cantools)."""
    db = load_can_dbc(DBC_PATH)
    assert len(right) == len(other)
    changes = []
    for a, b in zip(right, other, strict=True):
        if a == b:
            continue
        (t_a, id_a, data_a), (t_b, id_b, data_b) = candump_fields(a), candump_fields(b)
        assert (t_a, id_a) == (t_b, id_b), (a, b)
        assert db.get_message_by_frame_id(id_a).name == "ODOM_POSE_X", (a, b)
        sig_a, sig_b = (numbers(db, id_a, d, scaling=False) for d in (data_a, data_b))
        assert {k: v for k, v in sig_a.items() if k not in ("X", "CHECKSUM")} == \
            {k: v for k, v in sig_b.items() if k not in ("X", "CHECKSUM")}
        changes.append((t_a, int(sig_a["X"]), int(sig_b["X"])))
    return changes


def candump_fields(line: str) -> tuple[float, int, bytes]:
    t_s = float(line[1:line.index(")")])
    can_id, data = line.split()[-1].split("#")
    return t_s, int(can_id, 16), bytes.fromhex(data)
