"""A live watch's verdict at its end (``odocan monitor``, ``odocan bridge``; issue #11: the rig
never shows OK while the pose it reports is wrong).

``failures`` are the watch's FAIL reasons, one line each, in the monitor's words: two firmwares
on one bus (``SourceWatch.conflict_text``), the on-board pose wrong at any time of the watch
(``posewrongs.PoseWrongs.summary``: every POSE WRONG episode latched, even one right again by
the end), ODOM_TWIST DISTANCE (``LiveDistance.verdict``) or its speeds (``LiveTwist.verdict``)
wrong once. ``nothing_judged``: why a watch judged nothing (no firmware heard, no on-board pose
compared with the reference), which ``--require-firmware`` makes a FAIL (a CI watch that judged
nothing is no pass). Call them after ``watchend.end_watch``: what still waited is judged then.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

from odocan.host.judge.sources import FIRMWARE_NODE
from odocan.host.judge.verdictfacts import TWIST, not_advancing, stuck_text

if TYPE_CHECKING:
    from cantools.database.can import Database, Message

    from odocan.host.judge.livedistance import LiveDistance
    from odocan.host.judge.livetwist import LiveTwist
    from odocan.host.judge.sources import SourceWatch
    from odocan.host.judge.tracking import PoseTracker

REQUIRE_FIRMWARE = "(--require-firmware)"  # said after a ``nothing_judged`` reason's FAIL


def failures(tracker: PoseTracker, distance: LiveDistance, twist: LiveTwist,
             sources: SourceWatch, judged_as: str = "") -> list[str]:
    """The watch's FAIL reasons (module docstring), [] when it passes; ``judged_as`` follows a
    wrong pose's line (``; judged as robot 'kobuki' (--robot)``: a firmware set up for another
    robot reads as wrong)."""
    fails: list[str] = []
    conflict = sources.conflict_text()  # two firmwares: a FAIL, no pose judged after
    if conflict:
        fails.append(conflict)
    if tracker.wrongs.count:  # the pose was wrong at some time, even if right again since
        fails.append(tracker.wrongs.summary() + judged_as)
    fails += distance.verdict()[:1]  # ODOM_TWIST DISTANCE wrong in some life
    fails += twist.verdict()[:1]  # ODOM_TWIST LINEAR_VEL / ANGULAR_VEL wrong once
    return fails


def nothing_judged(db: Database, heard: Iterable[str], poses_compared: int) -> str:
    """Why the watch judged nothing: no cyclic ``FIRMWARE_NODE`` message among the message
    names ``heard`` (``db``'s), or no on-board pose compared with the reference; "" when it
    judged something."""
    if not any(_firmware_cyclic(db.get_message_by_name(name)) for name in heard):
        return f"no firmware heard (no cyclic {FIRMWARE_NODE} message): nothing judged"
    if not poses_compared:
        return "no on-board pose compared with the reference: nothing judged"
    return ""


def twist_unheard(db: Database, heard: Iterable[str], poses_compared: int,
                  seconds: float | None = None) -> str:
    """Why the twist and DISTANCE checks judged nothing though the pose was judged: the DBC's
    cyclic ODOM_TWIST never heard (``verdictfacts.unheard``, ``analyze``'s words; ``seconds``:
    the watch's, None: not said); "" else. The end verdict is then UNJUDGED, never a PASS."""
    names = {m.name for m in db.messages}
    if not poses_compared or TWIST not in names or TWIST in set(heard):
        return ""
    if not _firmware_cyclic(db.get_message_by_name(TWIST)):
        return ""
    during = "in the watch" if seconds is None else f"in {seconds:.1f} s"
    return f"no {TWIST} frame {during}: twist and DISTANCE not judged"


def stuck_counters(counts: dict[str, dict[str, int]]) -> str:
    """Most frames of a message E2E REPEATED (``verdictfacts.not_advancing``): a FAIL reason
    (the sender's E2E COUNTER does not advance), "" when none."""
    stuck = not_advancing(counts)
    return stuck_text(stuck) if stuck else ""


def _firmware_cyclic(message: Message) -> bool:
    """A cyclic message the firmware sends (as ``monitorvalues.node_ages`` tells its nodes)."""
    return bool(message.send_type == "Cyclic" and message.cycle_time and message.senders
                and message.senders[0] == FIRMWARE_NODE)
