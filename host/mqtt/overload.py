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

``after_halts``: the verdict of a robot the loop halted. FAIL when a sample before the first halt
was wrong (``host.judge.posewrongs``: beyond one LSB of position after its loss allowance, or one
LSB of heading), or when a stretch between two halts was (``host.mqtt.haltstretch``: each
stretch re-started at the firmware's pose once it took the frames after the halt, as a set-pose;
a pose step inside it that the reference does not make FAILs; the samples from the halt to the
re-start are judged on the stretch before the halt stepped with the frames sent during it, as
the halted MCU could have taken them, ``host.mqtt.haltcross``: a re-start no such way explains
FAILs too, the others are not judged). Else PASS when the stretches judged at least half the
samples since (``MIN_JUDGED_SHARE``), its ``reason`` saying how many and that the re-starts were
not. Without enough of them (the halts too close) the verdict is as before the stretches:
``rejudge`` (a FAIL of all its samples: UNJUDGED with the numbers, from which bus time, how many
halts, the longest gap) and ``noted`` (a PASS of all its samples says how far the loop starved
it: after a halt the tracker places its reference where the firmware is, within the merge
allowance of the frames the firmware took as one step, so an error that began during the halts
may not show).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

from odocan.host.judge.posewrongs import PoseWrongs
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.haltstretch import HaltStretches

# A PASS after halts needs the stretches to have judged this share of the samples since the
# first halt: halts a few ticks apart leave a stretch a sample or two (one tick in 7-30 at load
# 13-14 judged 1-4 of 40-60), too little to call the firmware right there.
MIN_JUDGED_SHARE = 0.5


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


def after_halts(entry: dict[str, Any], halted: Halted, tracker: PoseTracker,
                stretches: HaltStretches | None) -> dict[str, Any]:
    """``entry`` (a PASS or FAIL of ``fleetjudge.judge_robot``) of a robot the loop halted:
    FAIL when a sample before the first halt was wrong, or a stretch between halts was
    (``host.mqtt.haltstretch``); else PASS when a stretch judged a sample, saying what was not
    judged, as long as they judged at least ``MIN_JUDGED_SHARE`` of the samples since; else as
    before the stretches (``rejudge``, ``noted``)."""
    before = _wrongs_before(tracker, halted.from_s)
    if before.worst is not None:
        return _failed_before(entry, halted, before)
    if stretches is None:
        return rejudge(entry, halted, tracker) if entry["verdict"] == "FAIL" \
            else noted(entry, halted)
    entry = {**entry, "halt_stretches": {"halts": halted.halts, **stretches.as_dict()}}
    wrong = stretches.first_wrong
    if wrong is not None:
        return {**entry, "verdict": "FAIL",
                "reason": f"pose vs reference wrong after the loop halted the robot at "
                          f"{halted.from_s:.2f} s: {wrong.text()} ({stretches.tally()})"}
    if stretches.judged < MIN_JUDGED_SHARE * stretches.after or not stretches.judged:
        return rejudge(entry, halted, tracker) if entry["verdict"] == "FAIL" \
            else noted(entry, halted)
    return {**entry, "verdict": "PASS", "reason": _stretches_text(halted, stretches)}


def _stretches_text(halted: Halted, stretches: HaltStretches) -> str:
    """A PASS after halts: what was judged, what was not."""
    return (f"PASS: no sample wrong before the loop first halted the robot at {halted.from_s:.2f} "
            f"s, nor inside the {stretches.stretches} stretches between its {halted.halts} halts "
            f"(up to {halted.longest_gap_periods} periods apart; {stretches.judged} of "
            f"{stretches.after} samples since judged, each stretch re-started at the firmware's "
            f"pose), nor across {stretches.restarts_judged} of the {stretches.restarts_seen} "
            "re-starts (the stretch before each halt stepped with the frames sent during it, as "
            "the halted MCU could have taken them); the other re-starts are not judged (the "
            "halted MCU lost frames the bus carried: the rig's fault, not the firmware's)")


def _failed_before(entry: dict[str, Any], halted: Halted, before: PoseWrongs) -> dict[str, Any]:
    return {**entry, "verdict": "FAIL",
            "reason": f"pose vs reference wrong before the loop halted the robot at "
                      f"{halted.from_s:.2f} s: {before.summary()}"}


def rejudge(entry: dict[str, Any], halted: Halted, tracker: PoseTracker) -> dict[str, Any]:
    """``entry`` (a FAIL of ``fleetjudge.judge_robot``) judged on the samples before
    ``halted.from_s`` only (module docstring); the tracker is left as it was."""
    before = _wrongs_before(tracker, halted.from_s)
    if before.worst is not None:
        return _failed_before(entry, halted, before)
    return {**entry, "verdict": "UNJUDGED",
            "reason": f"{halted.text()}; no sample before was wrong ({entry['reason']} after)"}


def noted(entry: dict[str, Any], halted: Halted) -> dict[str, Any]:
    """``entry`` (a PASS of ``fleetjudge.judge_robot``) with the overload in its ``reason``."""
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
