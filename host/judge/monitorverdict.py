"""Parts of ``BusMonitor``'s verdict (``host.judge.monitor``): the firmware's own state when not
OK, and the summary that must be fresh for an OK.

An OK vouches for the firmware's own state as much as for its pose: a firmware whose poses flow
again while its last ODOM_STATUS summary is older than ``NODE_TIMEOUT_CYCLES`` of its cycle (a
SIGCONT after a stall sends poses first; its DEGRADED comes with the next summary) is STALE, not
OK: the screen's firmware line then says STALE too, and an OK beside it would contradict it."""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livestanding import pose_wrong_why
from odocan.host.judge.monitorvalues import NODE_TIMEOUT_CYCLES
from odocan.host.judge.reasonwords import reason_text

if TYPE_CHECKING:
    from odocan.host.judge.monitor import BusMonitor

SUMMARY_MESSAGE = "ODOM_STATUS"


def summary_stale_why(monitor: BusMonitor, now_s: float) -> list[str]:
    """Why the firmware's own state is unknown now: its last accepted summary is older than
    ``NODE_TIMEOUT_CYCLES`` x ODOM_STATUS's DBC cycle (``now_s``: local monotonic time, as
    ``feed``'s); [] while it is fresh (or none was heard: the verdict is not OK then)."""
    heard_s = monitor.summary_heard_s
    cycle_ms = monitor.db.get_message_by_name(SUMMARY_MESSAGE).cycle_time
    if heard_s is None or not cycle_ms:
        return []
    timeout_s = NODE_TIMEOUT_CYCLES * cycle_ms / 1e3
    age_s = now_s - heard_s
    if age_s <= timeout_s:
        return []
    return [f"no {SUMMARY_MESSAGE} summary for {age_s:.2f} s (timeout {timeout_s:.2f} s): the "
            f"firmware's own state is unknown; it last said {monitor.status.get('state', '?')}"]


def reported_verdict(monitor: BusMonitor, reported: str) -> tuple[str, list[str]]:
    """The firmware's own state when not OK, with its REASON; but a pose, DISTANCE or twist
    found wrong (``livedistance``, ``livetwist``: latched once settled) outranks DEGRADED,
    which a latched REASON (COUNTER_RESET, POSE_UNCERTAIN) keeps until a set-pose: the
    judge's finding is not hidden behind it. The pose is wrong as it is beside an OK
    (``livestanding``: the latest sample, or an episode of the pose's current life)."""
    said = f"firmware reports {reported} ({reason_text(str(monitor.status.get('reason', '?')))})"
    if reported == "DEGRADED":
        for verdict, why in (("POSE WRONG", pose_wrong_degraded(monitor)),
                             ("DISTANCE WRONG", monitor.distance.verdict()),
                             ("TWIST WRONG", monitor.twist.verdict())):
            if why:
                return verdict, [*why, said]
    return reported, [said]


def pose_wrong_degraded(monitor: BusMonitor) -> list[str]:
    """``pose_wrong_why`` beside a DEGRADED; while no sample can be judged (two sources, a
    reboot's priming frame awaited), the episodes of the pose's current life alone."""
    if monitor.sources.conflict_from_s is not None or monitor.tracker.awaiting_boot:
        text = monitor.tracker.wrongs.standing_text()
        return [text] if text else []
    return pose_wrong_why(monitor.tracker)
