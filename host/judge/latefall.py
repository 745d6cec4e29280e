"""A looked-ahead boot summary told by a DISTANCE fall heard after the summary that continues it
(issue #11: a FAIL must never blame a correct firmware).

``bootticks.boot_ahead`` may take a summary (UPTIME 0, COUNTER 0, breaking the ODOM_STATUS
sequence) for a power-up tick whose pose the bus lost when its first pose heard restarts a small
COUNTER and a twist's DISTANCE fell (``distfall``), tied to the summary by the next summary
(``bootticks.tied_to_boot``). A reset 32 k ticks into the firmware's first second whose first
pose pair and first 6 twists the bus lost leaves its first twist heard (COUNTER 6, 120 ms on)
after that next summary, which had already said no: the correct firmware FAILed by 93 mm (tick
32), 0.25 m (tick 64) in every judge.

A fall is impossible within one life (a single life's DISTANCE never decreases), so the first
twist heard since the summary falling below the last one heard before it says a new life began
between the two; the summary says where. Tied here (``tied_late``) when that twist comes by the
second summary after the boot summary (``LATE_FALL_S``), its COUNTER no more than the time since
the summary allows (ODOM_TWIST shares the pose's cycle: COUNTER c comes c pose periods after the
power-up twist, never sooner), the twist before it heard before the summary (a fall after a
twist of the new life would be yet another life's), and both summaries after continuing the boot
summary's sequence (``continues_summary``, ``continues_twice``: UPTIME 0, COUNTER 2 then 4; a
boot summary in between is no continuation). The live judges hold the looked-ahead summary one
cycle longer (to that second summary) and then withdraw what they judged since it, as they do a
cycle sooner; the streamed ``analyze`` holds the events after it across chunks, as before.

Where the first twist heard comes later still, or no longer falls (the new life drove farther than
the old one had: its first 10 twists lost at tick 32, DISTANCE 99 mm over the old life's 84),
NAV_STATUS's COUNTER restarting tells it (``navrestart``, read with the falls by the same ties);
without that either, the summary's evidence alone (one message's sequence broken) does not
restart a reference, and the correct firmware still FAILs there.
"""

from __future__ import annotations

from odocan.host.judge.distfall import Falls, any_tied
from odocan.host.protocol import busfacts

STATUS_CYCLE_S, POSE_PERIOD_S = busfacts.STATUS_CYCLE_S, busfacts.POSE_PERIOD_S  # 100, 20 ms
SLACK_S = busfacts.POSE_CYCLE_MS / 4000  # a quarter of a pose cycle (``bootticks``' slack)
LATE_SUMMARIES = 2  # the fall is read at the second summary after the boot summary
LATE_FALL_S = LATE_SUMMARIES * STATUS_CYCLE_S + SLACK_S  # 205 ms: by that summary
# the COUNTER of the second summary after the boot summary (COUNTER 0): 4
TWICE_COUNTER = LATE_SUMMARIES * busfacts.STATUS_FRAMES_PER_CYCLE % busfacts.STATUS_COUNTER_LAP


def tied_late(t_s: float, counter: int, before_s: float, summary_s: float) -> bool:
    """Whether a twist (bus time ``t_s``, E2E ``counter``) whose DISTANCE fell below the twist
    heard at ``before_s`` ties to a power-up tick at the summary at ``summary_s`` (module
    docstring): the twist before it heard before the summary, this one after it by
    ``LATE_FALL_S`` at most, with no more twists counted than the time since allows."""
    since_s = t_s - summary_s
    return bool(before_s < summary_s and 0.0 < since_s <= LATE_FALL_S
                and counter * POSE_PERIOD_S <= since_s + SLACK_S)


def fell_late(falls: Falls, summary_s: float, until_s: float) -> bool:
    """Whether a twist's DISTANCE fell (``distfall.fall_times``, bus times in order) where it
    ties late to the summary at ``summary_s`` (``tied_late``), heard by ``until_s`` (the second
    summary after it, where the live judges read it)."""
    return any_tied(falls, summary_s, min(until_s, summary_s + LATE_FALL_S),
                    lambda t_s, counter, before_s: tied_late(t_s, counter, before_s, summary_s))


def continues_twice(summary_s: float, t_s: float, uptime_s: int, counter: int) -> bool:
    """Whether a summary (bus time ``t_s``, UPTIME ``uptime_s``, E2E ``counter``) is the second
    after a boot summary at ``summary_s`` in its sequence: UPTIME 0, ``TWICE_COUNTER``, within
    three cycles (``bootticks.continues_summary`` the cycle before)."""
    return (uptime_s == 0 and counter == TWICE_COUNTER
            and 0.0 < t_s - summary_s < (LATE_SUMMARIES + 1) * STATUS_CYCLE_S)
