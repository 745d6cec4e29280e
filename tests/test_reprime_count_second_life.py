"""A re-primed power-up in the log's second life: the live judges take its first count page's
ENC_E2E_LOST as ``analyze`` takes every life's (issue #11; ``host.judge.livereprimecount``,
``reprimecount.power_up_lost``).

The rig: pmir drives from tick 0 (the log's first life), its MCU is reset at tick ``at`` (the
receive FIFO cleared with it: nothing to prime on in its first tick) and halted ``halted`` ticks
while the sim drives on. The new firmware primes on frame ``at + 1``, steps ``at + 2`` and
re-primes on the resumed frame ``at + halted + 2``: its first count page's ENC_E2E_LOST is
``(halted - 1) mod 16``. The evidence: the tests' float64 odometry
(``tests.independent_checker._Odometry``) of cantools-decoded frames.

Before, live took the count in the first life only (``PowerUpCount.reboot`` closed it for good):
after a reboot every pair (f, r) stayed open, and a firmware whose poses after the re-prime
follow a pair its own count contradicts (re-primed one frame late: r - f - 1 one more, 0.4 to
0.5 mm and 3 mrad from the frames it counted) PASSed the monitor, the bridge and the fleet while
``analyze`` FAILed it. A count no fitting pair allows is a wrong firmware output (the page
passed its E2E check: the firmware's own claim), so it FAILs live as in ``analyze``, which keeps
the pairs the count allows (``test_reprime_count_live``'s page moved by 8: FAIL, no longer
UNJUDGED).
"""

from __future__ import annotations

import itertools
import math
from functools import cache
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.independent_checker import _Odometry
from tests.test_first_second_reboot import _decoded, _reencoded, _written, _wrong
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live
from tests.test_stall_beyond_window import PMIR, _end_verdicts

CASES = [("circle", 500, 600), ("circle", 700, 1000), ("random", 500, 600), ("spin", 300, 600)]
MOVING = [c for c in CASES if c != ("circle", 700, 1000)]  # (at rest there: every r alike)
_TURN = 65536  # HEADING LSBs a turn


@cache
def drive(scenario: str, at: int, halted: int) -> tuple[can.Message, ...]:
    """The module docstring's log, from tick 0 to 5 s after the MCU resumed."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario(scenario, PMIR, duration_s=60.0)) as rig:
        def reset(k: int) -> None:
            if k == at:
                rig.board.reboot()
                while rig.fw_bus.recv(0) is not None:  # the reset clears the receive FIFO
                    pass
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(reset)
        rig.halted = lambda k: at < k <= at + halted
        rig.run((at + halted) * TICK_S + 5.0)
    return tuple(heard)


def _encoders(messages: tuple[can.Message, ...]) -> list[dict[str, float]]:
    return [_decoded(m) for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]


def _after_reprime(messages: tuple[can.Message, ...], at: int
                   ) -> list[tuple[int, can.Message, can.Message]]:
    """The new life's pose pairs after the MCU resumed: (the encoder frame each names, the
    latest heard before it with its ENC_COUNTER; its ODOM_POSE_X, its ODOM_POSE_Y), in bus
    order."""
    counters: list[int] = []
    out: list[tuple[int, can.Message, can.Message]] = []
    pending: can.Message | None = None
    for m in messages:
        if m.arbitration_id == fr.WHEEL_ENCODERS_ID:
            counters.append(int(_decoded(m)["COUNTER"]))
        elif m.timestamp < (at + 2) * TICK_S:
            continue
        elif m.arbitration_id == fr.ODOM_POSE_X_ID:
            pending = m
        elif m.arbitration_id == fr.ODOM_POSE_Y_ID and pending is not None:
            enc = int(_decoded(m)["ENC_COUNTER"])
            out.append((max(k for k in range(len(counters) - 16, len(counters))
                            if counters[k] == enc), pending, m))
    return out


def _path(encoders: list[dict[str, float]], primed: int, f: int, r: int, to: int) -> _Odometry:
    """The checker's odometry primed on ``primed``, stepped frame by frame to ``f``, re-primed
    on ``r`` (no step into it: the stall's motion left out) and stepped on to ``to``."""
    odo = _odometry(encoders, list(range(primed, f + 1)))
    for a, b in itertools.pairwise(range(r, to + 1)):
        odo.step(*(round((encoders[b][side] - encoders[a][side] + 32768) % 65536 - 32768)
                   for side in ("LEFT_COUNT", "RIGHT_COUNT")))
    return odo


def _off(messages: tuple[can.Message, ...], at: int, f: int, r: int, k: int
         ) -> tuple[float, float]:
    """How far (m, rad) the ``k``-th pose after the re-prime on ``r`` (0: its first, the
    frame ``r`` itself) lies from the checker's odometry (``_path``: primed on ``at + 1``)."""
    named, x, y = _after_reprime(messages, at)[k]
    odo, sx, sy = _path(_encoders(messages), at + 1, f, r, named), _decoded(x), _decoded(y)
    turn = math.remainder(odo.heading - sx["HEADING"] * math.tau / _TURN, math.tau)
    return math.hypot(odo.x - sx["X"] * 1e-4, odo.y - sy["Y"] * 1e-4), abs(turn)


def _late_pair(messages: tuple[can.Message, ...], at: int, halted: int
               ) -> tuple[can.Message, ...]:
    """The new life's poses from the first after the re-prime on, moved by what a re-prime one
    frame later takes (the checker's odometry over ``at + 1``, ``at + 2``, then ``r + 1`` on,
    less its odometry over the frames the firmware took, ``r`` on): a firmware whose poses
    follow the pair (at + 2, r + 1), which its own count (r - f - 1 mod 16) contradicts."""
    encoders, r = _encoders(messages), at + halted + 2
    moved: dict[int, can.Message] = {}
    for named, x, y in _after_reprime(messages, at):
        late, right = (_path(encoders, at + 1, at + 2, q, named) for q in (r + 1, r))
        sx, sy = _decoded(x), _decoded(y)
        heading = int(sy["TURNS"]) * _TURN + int(sx["HEADING"]) + round(
            (late.heading - right.heading) * _TURN / math.tau)
        sx["X"] += round((late.x - right.x) * 1e4)
        sy["Y"] += round((late.y - right.y) * 1e4)
        sx["HEADING"], sy["TURNS"] = heading % _TURN, heading // _TURN
        moved[id(x)] = _reencoded(x, sx, fr.ODOM_POSE_X_DATA_IDS)
        moved[id(y)] = _reencoded(y, sy, fr.ODOM_POSE_Y_DATA_IDS)
    return tuple(moved.get(id(m), m) for m in messages)


def _count(messages: tuple[can.Message, ...], at: int) -> int:
    pages = [_decoded(m) for m in messages if m.arbitration_id == fr.ODOM_STATUS_ID
             and m.timestamp >= at * TICK_S]
    return next(int(p["ENC_E2E_LOST"]) for p in pages if "ENC_E2E_LOST" in p)


@pytest.mark.parametrize(("scenario", "at", "halted"), CASES)
def test_the_correct_firmware_passes_every_judge(scenario: str, at: int, halted: int,
                                                 tmp_path: Path) -> None:
    """The checker: primed on ``at + 1``, stepped ``at + 2``, re-primed on the resumed frame,
    as the page counts, within an LSB over its first poses; live takes that count in the
    second life and PASSes, as ``analyze`` does."""
    messages, r = drive(scenario, at, halted), at + halted + 2
    assert (r - (at + 2) - 1) % 16 == _count(messages, at)
    for k in (0, 1, 20):
        pos_m, turn_rad = _off(messages, at, at + 2, r, k)
        assert pos_m <= POSITION_LSB_M
        assert turn_rad <= HEADING_LSB_RAD
    assert analyze(read_log(_written(messages, tmp_path / "right.log")), PMIR, "exact").passed
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] != "POSE WRONG"
    assert _end_verdicts(bridge) == ("PASS", "PASS")
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.reprime.count.lost == _count(messages, at)  # taken in the second life
        assert [e["encoder_frame"] for e in tracker.restarts.events
                if e["kind"] == "stall_reprime"] == [r + 2]
        assert tracker.wrongs.as_dict()["episodes"] == 0


@pytest.mark.parametrize(("scenario", "at", "halted"), MOVING)
def test_poses_of_a_pair_the_count_contradicts_fail_every_judge(
        scenario: str, at: int, halted: int, tmp_path: Path) -> None:
    """The poses after the re-prime follow the pair (at + 2, r + 1): more than an LSB from the
    checker's odometry of the frames the firmware took (and within an LSB of the late pair's,
    which its count does not allow). Before, the live judges chose that pair, not bound by the
    count in a second life: OK and PASS; now POSE WRONG and FAIL, as ``analyze``."""
    r = at + halted + 2
    wrong = _late_pair(drive(scenario, at, halted), at, halted)
    pos_m, turn_rad = _off(wrong, at, at + 2, r, 1)
    assert pos_m > POSITION_LSB_M or turn_rad > HEADING_LSB_RAD
    pos_m, turn_rad = _off(wrong, at, at + 2, r + 1, 1)
    assert pos_m <= POSITION_LSB_M
    assert turn_rad <= HEADING_LSB_RAD
    assert not analyze(read_log(_written(wrong, tmp_path / "late.log")), PMIR, "exact").passed
    monitor, bridge, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")


@pytest.mark.parametrize(("scenario", "at", "halted"), CASES[:2])
@pytest.mark.parametrize("bias_lsb", [100, 3, -3])
def test_a_wrong_firmware_fails_every_judge(scenario: str, at: int, halted: int,
                                            bias_lsb: int, tmp_path: Path) -> None:
    """X ``bias_lsb`` off from the first pose after the re-prime on: beyond an LSB of the
    checker's odometry; every judge FAILs it."""
    wrong = _wrong(drive(scenario, at, halted), at + 2, bias_lsb, 0)
    assert _off(wrong, at, at + 2, at + halted + 2, 1)[0] > POSITION_LSB_M
    assert not analyze(read_log(_written(wrong, tmp_path / "wrong.log")), PMIR, "exact").passed
    monitor, bridge, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")

