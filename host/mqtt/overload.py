"""A robot's pose verdict when the fleet's loop starved it (``host.mqtt.fleetrun``).

On an overloaded machine the fleet's real-time loop (``sim.fleet.run_realtime``) falls whole
periods behind and skips releases. The motor controllers' samples of the skipped releases are
sent late, one per release (``sim.fleet.Fleet.step``), but the firmware boards run no tick for
them: a tick that comes ``sim.board.HALT_AFTER_S`` (9.5 periods) or more after the previous one
is a halted MCU's (its receive FIFO kept 3 frames and overran the rest, TIME_LOST). Then the
firmware lost frames the bus carried, and which ones no frame tells: it took the gap as one step,
and after seconds of such halts its steps became too long to read (COUNTER_RESET: the motion
lost, as ``firmware.ambiguity`` rules). Its pose leaves the reference for reasons that are the
loop's, not its arithmetic: with the loop one tick in 7-30 (load 13-14), a correct firmware
FAILed with "heading vs reference 62.81 mrad". The loop knows when it first halted the boards
(``Fleet.halted_from_s``): the samples before are judged as ever; from then on they are not.

``rejudge``: the verdict of a robot that FAILed on all its samples once the loop halted it. FAIL
when a sample before the first halt was wrong (``host.judge.posewrongs``: beyond one LSB of
position after its loss allowance, or one LSB of heading); else UNJUDGED, saying so with the
numbers (from which bus time, how many halts, the longest gap). A robot that PASSed on all its
samples stays PASS (no sample was wrong: the judge's stall rules followed it through the halts),
its ``reason`` saying how far the loop starved it (``noted``): after a halt the judge places its
reference where the firmware is, within the merge allowance of the frames the firmware took as
one step, so an error that began during the halts may not show (a firmware 2 LSB off from then
PASSed in ``tests/test_fleet_overload.py``'s drive).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

from odocan.host.judge.posewrongs import PoseWrongs
from odocan.host.judge.tracking import PoseTracker


@dataclass(frozen=True)
class Halted:
    """How the fleet's loop starved one robot: the bus time (s, its own clock) of its first
    halted tick, the ticks that halted the boards, the most periods between two ticks run, and
    the releases the loop skipped in all."""

    from_s: float
    halts: int
    longest_gap_periods: int
    skipped_releases: int

    def text(self) -> str:
        """``overloaded: from 0.19 s of bus time the fleet's loop ran 12 ticks up to 30
        periods apart (5400 releases skipped)``."""
        return (f"overloaded: from {self.from_s:.2f} s of bus time the fleet's loop ran "
                f"{self.halts} ticks up to {self.longest_gap_periods} periods apart "
                f"({self.skipped_releases} releases skipped), each a halt of the robot's MCU "
                "(TIME_LOST, its receive FIFO overran): the frames its firmware lost are not on "
                "the bus, so its pose is not judged from then")


def rejudge(entry: dict[str, Any], halted: Halted, tracker: PoseTracker) -> dict[str, Any]:
    """``entry`` (a FAIL of ``fleetrun.judge_robot``) judged on the samples before
    ``halted.from_s`` only (module docstring); the tracker is left as it was."""
    before = _wrongs_before(tracker, halted.from_s)
    if before.worst is not None:
        return {**entry, "verdict": "FAIL",
                "reason": f"pose vs reference wrong before the loop halted the robot at "
                          f"{halted.from_s:.2f} s: {before.summary()}"}
    return {**entry, "verdict": "UNJUDGED",
            "reason": f"{halted.text()}; no sample before was wrong ({entry['reason']} after)"}


def noted(entry: dict[str, Any], halted: Halted) -> dict[str, Any]:
    """``entry`` (a PASS of ``fleetrun.judge_robot``) with the overload in its ``reason``."""
    return {**entry, "reason": f"PASS on the samples the judge could follow; overloaded: from "
                               f"{halted.from_s:.2f} s of bus time the loop ran {halted.halts} "
                               f"ticks up to {halted.longest_gap_periods} periods apart, each a "
                               "halt of the robot's MCU: a pose wrong since may not show"}


def _wrongs_before(tracker: PoseTracker, from_s: float) -> PoseWrongs:
    """The tracker's POSE WRONG episodes of the samples whose ODOM_POSE_Y came before
    ``from_s``, those still waiting for a page judged with the allowance they have (a copy:
    the tracker's own goes on)."""
    wrongs = copy.deepcopy(tracker.wrongs)
    wrongs.unjudgeable_from(from_s)
    wrongs.finish(tracker.allowance_m)
    return wrongs
