"""Lone pose halves in the live judge (issue #11), as ``analyze`` judges them
(``host.judge.lonehalves``): an ODOM_POSE_X or ODOM_POSE_Y half whose partner naming the same
encoder frame never came (a later sample was paired first: ``livehalves.HalfPairs``) is judged on
what it carries, completed by the reference at its frame (an X half's Y is the reference's and
its TURNS the whole turns nearest it; a Y half's HEADING the angle in the turn TURNS names
nearest the reference's). It was dropped unsaid: a lone X raised 10 m left the monitor and the
bridge OK. Its error counts as a resend's (``liveresent``): in the largest errors and the loss
allowance's record (``LiveAllowance.record``, the POSE WRONG episodes), not as a sample.

Judged only where the reference at its frame is the last sample's: after the latest sample,
which was compared (of this life), sent less than ``QUIET_S`` after it (a half after a silence
is a stall's first pose, ``stallfirst``'s: its name may be a backlog frame's), no placement
due (a gap or a stall since: ``StallPlacer.due``), and no alias of its COUNTER possible
(``liveresent.may_alias_live``); else it is left, as ``analyze`` leaves a lone half it cannot
tell (``lone_halves_unjudged``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livepose import FramePose
from odocan.host.judge.liveresent import may_alias_live, record_error
from odocan.host.judge.livewindow import CYCLE_S, Half
from odocan.host.judge.samples import HEADING_LSB_RAD, SILENCE_CYCLES
from odocan.sim.pose import TURN_RAD

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

QUIET_S = (SILENCE_CYCLES - 0.5) * CYCLE_S  # sent this long after the latest sample: a silence


def judge_lone_live(name: str, seq: int, half: Half, tracker: PoseTracker) -> bool:
    """Judge half ``name`` ("x" or "y") naming frame ``seq`` without its partner; whether it
    was judged (module docstring)."""
    last = tracker.last_pair
    if (last is None or seq <= last[0].seq or tracker.stall.last_compared != last[0].seq
            or tracker.pose is None or tracker.pose.seq != last[0].seq  # the latest sample's
            or half.t_s - tracker.pose_t_s >= QUIET_S  # after a silence: a stall's first pose
            or tracker.stall.place_at_next or tracker.placer.due(seq)
            or may_alias_live(seq, half.t_s, tracker)):
        return False
    raw = tracker.raw.at.get(seq)
    if raw is None:
        return False
    ref = tracker.fit.correct(raw)
    if name == "x":  # half.extra: HEADING (rad, one turn)
        turns = round((ref.heading_rad - half.extra) / TURN_RAD)
        pose = FramePose(seq, half.value, ref.y_m, turns * TURN_RAD + half.extra)
    else:  # half.extra: TURNS
        within = min(max(ref.heading_rad - half.extra * TURN_RAD, 0.0),
                     TURN_RAD - HEADING_LSB_RAD)
        pose = FramePose(seq, ref.x_m, half.value, half.extra * TURN_RAD + within)
    record_error(tracker, seq, pose, ref, half.t_s)
    return True
