"""A live watch's one verdict when it ends: PASS, FAIL or UNJUDGED, the same for ``odocan
monitor`` and ``odocan bridge`` (``host.mqtt.endverdict`` adds its profile mismatch and the
worst episode for the retained status).

FAIL: a stuck E2E COUNTER (``watchverdict.stuck_counters``, first: the host refused the frames
the rest would judge), then ``watchverdict.failures``, then a watch that judged nothing under
``--require-firmware``. UNJUDGED: the robot not judged (``liverobot``), nothing judged, the DBC's
cyclic ODOM_TWIST never heard or none of it judged (``watchverdict.twist_unheard``: a check on 0
samples is no pass), a start nothing bounds (``livereprime``, ``livefirst``, ``livekept``).
PASS: the samples judged right, counted. Before, the monitor printed no line on a PASS and
passed a watch that never heard ODOM_TWIST (an outside trial's firmware).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from odocan.host.judge.livefirst import unproven_why
from odocan.host.judge.livekept import coarse_why
from odocan.host.judge.livereprime import unbounded_why
from odocan.host.judge.watchverdict import (
    REQUIRE_FIRMWARE,
    failures,
    nothing_judged,
    stuck_counters,
    twist_unheard,
)

if TYPE_CHECKING:
    from cantools.database.can import Database

    from odocan.host.judge.livedistance import LiveDistance
    from odocan.host.judge.livekept import KeptWatch
    from odocan.host.judge.livetwist import LiveTwist
    from odocan.host.judge.sources import SourceWatch
    from odocan.host.judge.tracking import PoseTracker

VerdictName = Literal["PASS", "FAIL", "UNJUDGED"]
REQUIRED_SAYS = "(--require-firmware fails it)"  # after an UNJUDGED reason


@dataclass(frozen=True)
class Watched:
    """What a watch's judges hold at its end: ``heard`` the message names heard, ``counts``
    the E2E counts per message (``E2EMonitor.counts``), ``unjudged`` the robot's refusal
    (``LiveRobot.unjudged``), ``seconds`` how long it watched (None: not said)."""

    tracker: PoseTracker
    distance: LiveDistance
    twist: LiveTwist
    sources: SourceWatch
    kept: KeptWatch
    db: Database
    heard: Iterable[str]
    counts: dict[str, dict[str, int]]
    unjudged: str | None = None
    seconds: float | None = None
    ahead: tuple[str, ...] = ()  # a pose named a frame not yet sent (``liveahead.why``)


def watch_verdict(w: Watched, *, judged_as: str = "", require_firmware: bool = False
                  ) -> tuple[VerdictName, list[str]]:
    """The verdict and its reasons (FAIL: one each; else one), module docstring."""
    fails = [*w.ahead, *failures(w.tracker, w.distance, w.twist, w.sources, judged_as)]
    if stuck := stuck_counters(w.counts):
        fails.insert(0, stuck)
    heard = list(w.heard)
    compared = w.tracker.vs_reference.samples
    why = (w.unjudged or nothing_judged(w.db, heard, compared)
           or twist_unheard(w.db, heard, compared, w.seconds))
    if why and require_firmware:
        fails.append(f"{why} {REQUIRE_FIRMWARE}")
    if fails:
        return "FAIL", fails
    if why:
        return "UNJUDGED", [f"{why} {REQUIRED_SAYS}"]
    unbounded = unbounded_why(w.tracker) or unproven_why(w.tracker) or coarse_why(w.kept)
    if unbounded:
        return "UNJUDGED", [unbounded]
    distance, twist = w.distance.samples, w.twist.samples
    if not (distance or twist):  # ODOM_TWIST heard, nothing of it judged: no PASS either
        return "UNJUDGED", [f"the on-board pose right in {compared} samples, ODOM_TWIST judged "
                            "on none: twist and DISTANCE not judged"]
    return "PASS", [f"the on-board pose right in {compared} samples, ODOM_TWIST DISTANCE in "
                    f"{distance} and its speeds in {twist}"]
