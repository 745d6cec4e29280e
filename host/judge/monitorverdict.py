"""The monitor's live verdict (``BusMonitor.health``'s ``state`` and ``why``; the order is the
``host.judge.monitor`` docstring's): moved out of ``monitor`` to keep it under 500 lines.

A watch left unjudged (``liverobot``: no ``--robot``, and the firmware's PROFILE page is not
the default robot's) compares nothing: its state is UNVERIFIED, saying why
(``LiveRobot.unjudged``: "the firmware runs a different profile than the default robot pmir:
give --robot") where a watch that compared nothing yet says so.

An OK vouches for the firmware's own state as much as for its pose: a firmware whose poses flow
again while its last ODOM_STATUS summary is older than ``NODE_TIMEOUT_CYCLES`` of its cycle (a
SIGCONT after a stall sends poses first; its DEGRADED comes with the next summary) is STALE, not
OK (``summary_stale_why``): the screen's firmware line then says STALE too, and an OK beside it
would contradict it.
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, Any

from odocan.host.judge.livestanding import placed_why, pose_wrong_why
from odocan.host.judge.monitorvalues import NODE_TIMEOUT_CYCLES
from odocan.host.judge.reasonwords import reason_text
from odocan.host.judge.sources import FIRMWARE_NODE

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


def verdict(model: BusMonitor, firmware: dict[str, Any] | None) -> tuple[str, list[str]]:
    """The state and why of ``model`` (``firmware``: its node's age, ``node_ages``'s)."""
    if firmware is None:
        return "NO FIRMWARE", [f"no cyclic {FIRMWARE_NODE} message heard"]
    if firmware["stale"] and not model.settle.held:  # held frames were heard (livesettle)
        return "STALE", [
            f"{FIRMWARE_NODE} silent for {firmware['age_s']:.2f} s (timeout "
            f"{firmware['timeout_s']:.2f} s); it last said {model.status.get('state', '?')}"
        ]
    if model.bus_time_s <= model.sources.conflict_until_s:
        return "CONFLICT", [str(model.events[-1]["detail"]) if model.events else "two sources"]
    reported = str(model.status.get("state", "?"))
    if reported != "OK":
        return reported_verdict(model, reported)
    if model.sources.conflict_from_s is not None:  # whose pose is it? (posewrongs: none judged)
        return "UNVERIFIED", [model.sources.conflict_text()]
    error = model.tracker.vs_reference.latest
    if not error and not model.ahead.count:  # nothing compared yet, or nothing is (liverobot)
        return "UNVERIFIED", [model.robot.unjudged
                              or "no on-board pose compared with the reference yet"]
    if model.tracker.awaiting_boot:
        return "UNVERIFIED", ["rebooted: waiting for the encoder frame it primed on"]
    for state, why in (("POSE WRONG", model.ahead.why),  # named before sent (liveahead)
                       ("POSE WRONG", partial(pose_wrong_why, model.tracker)),  # livestanding
                       ("POSE WRONG", model.first_after.wrong),  # livestallfirst
                       ("DISTANCE WRONG", model.distance.verdict),  # latched, in this order
                       ("TWIST WRONG", model.twist.verdict),  # LINEAR_VEL, ANGULAR_VEL
                       ("HELD", model.settle.why)):  # frames not judged yet: livesettle
        if reasons := why():
            return state, reasons
    return "OK", placed_why(model.tracker)


def reported_verdict(model: BusMonitor, reported: str) -> tuple[str, list[str]]:
    """The firmware's own state when not OK, with its REASON; but a pose, DISTANCE or twist
    found wrong (``livedistance``, ``livetwist``: latched once settled) outranks DEGRADED,
    which a latched REASON (COUNTER_RESET, POSE_UNCERTAIN) keeps until a set-pose: the
    judge's finding is not hidden behind it. The pose is wrong as it is beside an OK
    (``livestanding``: the latest sample, or an episode of the pose's current life)."""
    said = f"firmware reports {reported} ({reason_text(str(model.status.get('reason', '?')))})"
    if reported == "DEGRADED":
        for state, why in (("POSE WRONG", model.ahead.why()),  # liveahead
                           ("POSE WRONG", _pose_wrong_degraded(model)),
                           ("POSE WRONG", model.first_after.wrong()),  # livestallfirst
                           ("DISTANCE WRONG", model.distance.verdict()),
                           ("TWIST WRONG", model.twist.verdict())):
            if why:
                return state, [*why, said]
    return reported, [said]


def _pose_wrong_degraded(model: BusMonitor) -> list[str]:
    """``pose_wrong_why`` beside a DEGRADED; while no sample can be judged (two sources, a
    reboot's priming frame awaited), the episodes of the pose's current life alone."""
    if model.sources.conflict_from_s is not None or model.tracker.awaiting_boot:
        text = model.tracker.wrongs.standing_text()
        return [text] if text else []
    return pose_wrong_why(model.tracker)
