"""The live DISTANCE judge across a reboot: the new firmware's first twists are not the old
life's (issue #11, item 5).

pmir on the circle, its MCU reset at tick 30 (0.3 s, ``test_first_second_reboot.drive``). The new
firmware's first tick sends an ODOM_TWIST (DISTANCE from its own power-up) before the summary
that tells the reboot. Once an ending life's wrong was kept at the reboot (before, it was lost
unless a status had asked for the verdict first: a DISTANCE 10 mm long in a life ended by a reboot
PASSed live), that twist, judged against the old life's path, made the monitor model and the
bridge say DISTANCE WRONG by 83.852 mm for the correct firmware. ``LiveDistance.new_life`` now
takes the bus time the new firmware's frames start from (as ``LiveTwist.new_life``): the twists
heard from then are not judged in the old life. Independent of the judges: the frames decoded
with cantools (the twist's DISTANCE falling back at the reset). A DISTANCE 10 mm long in either
life still FAILs ``analyze`` and the live judges.
"""

from __future__ import annotations

from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.sim.board import TICK_S
from tests.test_first_second_reboot import DB, PMIR, _decoded, _live, _reencoded, _written, drive
from tests.test_stall_beyond_window import _end_verdicts

RESET_TICK = 30
TAMPERS = {"old life": (0.15, RESET_TICK * TICK_S - 0.005), "new life": (1.0, 10.0)}
LONG_MM = 10  # the tamper: DISTANCE 10 mm long


def _twists(messages: tuple[can.Message, ...]) -> list[tuple[float, int]]:
    """(bus time, raw DISTANCE mm) of every ODOM_TWIST, by cantools."""
    return [(m.timestamp, int(_decoded(m)["DISTANCE"])) for m in messages
            if m.arbitration_id == fr.ODOM_TWIST_ID]


def _before_status(messages: tuple[can.Message, ...], t_s: float) -> list[int]:
    """Raw DISTANCE (mm) of the ODOM_TWISTs heard from ``t_s`` on, before the first ODOM_STATUS
    frame heard from then (in the bus's order: the same stamp may follow)."""
    later = [m for m in messages if m.timestamp >= t_s]
    status = next(k for k, m in enumerate(later) if m.arbitration_id == fr.ODOM_STATUS_ID)
    return [int(_decoded(m)["DISTANCE"]) for m in later[:status]
            if m.arbitration_id == fr.ODOM_TWIST_ID]


def _long(messages: tuple[can.Message, ...], span_s: tuple[float, float]) -> tuple[
        can.Message, ...]:
    """ODOM_TWIST's DISTANCE ``LONG_MM`` longer in the bus times ``span_s`` (re-sealed)."""
    out = []
    for m in messages:
        if m.arbitration_id == fr.ODOM_TWIST_ID and span_s[0] <= m.timestamp < span_s[1]:
            signals: dict[str, Any] = _decoded(m)
            signals["DISTANCE"] = (signals["DISTANCE"] + LONG_MM) % 65536
            m = _reencoded(m, signals, fr.ODOM_TWIST_DATA_IDS)
        out.append(m)
    return tuple(out)


def test_the_new_firmwares_first_twist_is_not_judged_in_the_old_life() -> None:
    """The reset seen by cantools (a twist's DISTANCE back below the last before the reset,
    heard before the next ODOM_STATUS); the monitor and the bridge find no DISTANCE wrong."""
    messages = drive(RESET_TICK)
    assert DB.get_message_by_name("ODOM_TWIST").frame_id == fr.ODOM_TWIST_ID
    reset_s = RESET_TICK * TICK_S
    before = [mm for t, mm in _twists(messages) if t < reset_s]
    early = _before_status(messages, reset_s)
    assert before[-1] > 50
    assert early == [0]  # the new firmware's, from its power-up
    monitor, bridge = _live(messages)
    for distance in (monitor.distance, bridge.distance):
        assert distance.samples > 100
        assert distance.verdict() == []  # before: off by 83.852 mm
        assert distance.wrong_lives == 0
    assert monitor.health(messages[-1].timestamp)["state"] == "OK"
    assert _end_verdicts(bridge) == ("PASS", "PASS")


@pytest.mark.parametrize("life", sorted(TAMPERS))
def test_a_distance_10_mm_long_in_either_life_fails_every_judge(life: str, tmp_path: Any) -> None:
    """DISTANCE 10 mm long in the old life (its last 0.15 s: judged at the reboot) or in the
    new one: ``analyze`` FAILs it, the monitor says DISTANCE WRONG, the bridge's and the
    fleet's end verdicts FAIL."""
    messages = _long(drive(RESET_TICK), TAMPERS[life])
    assert sum(mm != right for (_, mm), (_, right)
               in zip(_twists(messages), _twists(drive(RESET_TICK)), strict=True)) > 5
    whole = analyze(read_log(_written(messages, tmp_path / "long.log")), PMIR, "exact")
    assert not whole.passed
    monitor, bridge = _live(messages)
    for distance in (monitor.distance, bridge.distance):
        assert distance.verdict()
        assert distance.worst_excess_m > 5e-3  # 10 mm less the slack
    assert monitor.health(messages[-1].timestamp)["state"] == "DISTANCE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")
