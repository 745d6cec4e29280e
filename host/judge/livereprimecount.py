"""The first count page's ENC_E2E_LOST, live: the frames a re-prime at power-up took (issue #11;
the live half of ``host.judge.reprimecount``, for ``livereprime``).

A firmware halted at its power-up long enough to re-prime (COUNTER_RESET) sends its first
ENC_E2E_OK page after it resumed; its ENC_E2E_LOST is then the E2E counter's step from the last
frame ``f`` its FIFO kept into the frame ``r`` it re-primed on, ``(r - f - 1) mod 16``: a value
the firmware counted, which a recorder stamping ODOM_STATUS late cannot move. ``analyze`` keeps
the pairs (f, r) it allows (``reprimecount.kept_pairs``); live, the replay tried every pair from
the power-up pose on frame 0 and on frame 1 (a robot moving at power-up: frame 0 to 1 4.7 mm on
pmir's circle) and took the best, so which frame the firmware primed on stayed unknown where the
robot moved over them: the end verdicts UNJUDGED ("the encoder frame it primed on is not known",
``livefirst``) on the correct firmware (pmir moving on the circle at power-up, or spinning or on
the random drive from rest, halted 6 or 10 s). The pairs the count allows leave one step count
from each priming frame: the samples then tell the frame.

``PowerUpCount`` takes the page's value under ``analyze``'s preconditions only (its
``power_up_lost``, applied to every life): the life starts at the firmware's power-up (its first
ODOM_STATUS of its first cycle, its first summary UPTIME 0; its ENC_E2E_OK no more than the
frames heard since), one stall before the page (the one the hold replays) and no hole of the
encoder frames' sequence up to it. The watch's first life, and every life after a reboot whose
boot summary said UPTIME 0 (``PoseTracker.power_up`` takes a fresh count: before, only the first
life's was taken, and after a reboot every pair stayed open: a firmware whose poses followed a
pair its own count contradicts PASSed live, FAILed by ``analyze``); not a set-pose's life, nor
a reboot told past UPTIME 0. ``counted_replay`` then filters the replay's pairs by it, a hard
filter:

- pairs it allows fit the samples (``Replayed.within``): the best of them is judged (from the
  priming frame they name, ``CountedReplay.primed``, when they name one: the first pose judged,
  the start no longer unknown);
- none it allows fits: the best of those it allows, refused (POSE WRONG, FAIL), as ``analyze``
  keeps the pairs it allows and FAILs the poses they do not meet. Also when another pair
  would fit (``CountedReplay.against`` says which): the page passed its E2E check, so its count
  is the firmware's own claim, and the preconditions leave no frame the log lacks that could
  have moved it (no hole of the encoder frames' sequence, one stall, the page counting no more
  frames than heard; a recorder stamping late, dropping or delaying frames moves no value
  under a CRC). A count its own poses contradict is a wrong firmware output, whichever of the
  two is wrong (before: UNJUDGED, where ``analyze`` FAILed it);
- it allows none of the pairs tried: the best of all, judged as before.

A power-up its count page did not prove (a recorder stamping ODOM_STATUS 15-50 ms late moves the
page's tick bound past frames it counted; the count itself unmoved) is proven by that replay
when it pins the priming frame (``livereprime.ReprimeHold._pinned``); else its first pose stays
adopted unbounded, UNJUDGED, as before.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livewindow import Counted
from odocan.host.judge.nearthreshold import SUMMARY_PAGE
from odocan.host.judge.powerup import holds_first_cycle
from odocan.host.judge.reprimecount import lost_allows
from odocan.host.judge.reprimereplay import Odometry, Replayed, replays, score
from odocan.host.judge.samples import ENC_E2E_PAGE

# frames a power-up may have primed on (``stallpowerup``'s 0 .. lo): frame 0 was on the bus in
# its first tick, before or after its read; a FIFO drained there, it primed on frame 1
PRIMES = (0, 1)


class PowerUpCount:
    """The watch's first count page's ENC_E2E_LOST when ``analyze``'s preconditions hold
    (module docstring); ``lost`` None when they do not, or before the page."""

    __slots__ = ("base", "first_cycle", "holed", "lost", "over", "stalls", "uptime_zero")

    def __init__(self, base: int = 0) -> None:
        self.base = base  # seq of the latest frame at the life's summary (0: the watch's)
        self.first_cycle: bool | None = None  # the first ODOM_STATUS heard of the first cycle
        self.uptime_zero: bool | None = None  # the first summary said UPTIME 0
        self.holed = False  # a hole of the encoder frames' sequence heard (``PoseTracker``)
        self.stalls = 0  # stalls left out (``ReprimeHold.stalled``)
        self.over = False  # the first count page heard, or a reboot: nothing more to take
        self.lost: int | None = None

    def on_status(self, signals: dict[str, Any], heard: int) -> None:
        """An accepted ODOM_STATUS (raw signals), ``heard`` encoder frames heard before it: a
        count page whose ENC_E2E_OK counts more was made by a firmware that took frames the
        log lacks (not powered up at its start: no count taken)."""
        if self.over:
            return
        if self.first_cycle is None:
            self.first_cycle = holds_first_cycle(_int(signals.get("COUNTER")))
        page = _int(signals.get("PAGE"))
        if page == SUMMARY_PAGE and self.uptime_zero is None:
            self.uptime_zero = _int(signals.get("UPTIME")) == 0
        elif page == ENC_E2E_PAGE and "ENC_E2E_LOST" in signals:
            self.over = True
            if self.first_cycle and self.uptime_zero and not self.holed and self.stalls == 1 \
                    and _int(signals.get("ENC_E2E_OK")) in range(heard - self.base + 1):
                self.lost = int(signals["ENC_E2E_LOST"])

    def reboot(self) -> None:
        """A new firmware life: the watch no longer starts at its power-up (no count taken; a
        reboot at UPTIME 0 takes a fresh one: ``PoseTracker.power_up``)."""
        self.over, self.lost = True, None

    @property
    def awaited(self) -> bool:
        """Whether the page may still come with a count to take (a re-prime's release waits
        for it: ``livereprime``)."""
        return (not self.over and self.first_cycle is True and self.uptime_zero is not False
                and not self.holed and self.stalls == 1)


@dataclass(frozen=True)
class CountedReplay:
    """The replay judged (``replay``, None: the frames not held), the frame the power-up primed
    on that the count pins (``primed``, None: not pinned), and, refused, the pair that would
    have fit had the count allowed it (``against``: the words for the refusal's event)."""

    replay: Replayed | None
    primed: int | None = None
    against: str | None = None


def counted_replay(odometry: Odometry, anchors: list[FramePose],
                   frozen: Iterable[tuple[float, ...]], recent: list[Counted],
                   samples: list[FramePose], primed: bool, lost: int | None) -> CountedReplay:
    """The module docstring's rule over every pair's path from each of ``anchors`` (the power-up
    pose on each frame it may have primed on, or the firmware's pose before the stall) with
    ``reprimereplay.replays``' other arguments; ``lost``: the count (None: every pair, the best
    judged, as before)."""
    frozen = tuple(frozen)
    tries = [(anchor.seq, path) for anchor in anchors
             for path in replays(odometry, anchor, frozen, recent, samples, primed) or []]
    if not tries:
        return CountedReplay(None)
    best = min(tries, key=lambda t: score(t[1]))[1]
    if lost is None:
        return CountedReplay(best)
    counted = [(seq, path) for seq, path in tries if lost_allows(lost, path.f, path.r)]
    fits = [(seq, path) for seq, path in counted if path.within]
    if fits:
        primes = {seq for seq, _ in fits}
        chosen = min(fits, key=lambda t: score(t[1]))[1]
        return CountedReplay(chosen, primes.pop() if len(anchors) > 1 and len(primes) == 1
                             else None)
    if not counted:
        return CountedReplay(best)
    chosen = min(counted, key=lambda t: score(t[1]))[1]
    return CountedReplay(chosen, against=(
        f"; it fits only a pair (stepped to frame {best.f}, re-primed on {best.r}) its first "
        f"count page's ENC_E2E_LOST {lost} does not allow: its count or its pose is wrong"
    ) if best.within else None)


def primed_detail(counted: CountedReplay, lost: int | None) -> str:
    """The words of the ``power_up_primed_on`` event a pinned priming frame is told by."""
    replay = counted.replay
    assert replay is not None and counted.primed is not None
    return (f"the firmware primed on encoder frame {counted.primed} at its power-up: the only "
            f"one from which the frames it took (stepped to frame {replay.f}, re-primed on "
            f"{replay.r}, as its first count page's ENC_E2E_LOST {lost} says) put its first pose "
            "after the re-prime where it is")


def _int(value: Any) -> int | None:
    return None if value is None else int(value)
