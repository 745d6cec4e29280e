"""The live judges' start of a life whose boot summary the bus held back past its tick
(``heldtick``, ``heldboot``), as ``analyze`` starts it (issue #11: "a FAIL must never blame a
correct firmware").

``analyze`` starts such a life at ``heldboot.held_start``: UPTIME 0 and not INIT, the latest
encoder frame heard before the tick (of those stamped with it, the one a fresh E2E check
draining them at once takes: ``heldboot.fresh_last``), whatever the whole log's E2E check said
of it; INIT, the first heard after the tick. Its first count page does not override that (sent
a cycle on and held back too, it counts back from a frame heard as late); a power-up pose naming
a later frame does. The live judges waited for that page instead, or, when it was heard before
the summary told the reboot, for ``BOOT_COUNT_WAIT_S``, then started the life on the latest
frame heard at the summary: kobuki and pmir random 692, 8 s, ``reboot=0.5:0.3,delay=0.1:150``:
the new firmware, up at 0.801 s, primed on COUNTER 1 sent at 0.65 s, held back and heard at
0.800 s right before the on-time COUNTER 0 (the host's sequence took the 0 and refused the 1);
its power-up pose, summary and page held back to 0.951 s, its first count page (0.901 s) heard
before them. The live start, on COUNTER 15 of 0.950 s, 15 frames late, left the monitor and
the bridge 23.87 mm (kobuki) and 56.5 mm (pmir) beyond the allowance from 1.92 s on (POSE
WRONG) while run and both analyses PASSed.

Now such a reboot (``SourceWatch.held_tick_s``) starts at once at the frame ``held_start``
names among the frames heard: the window's (the host's sequence took them) and the latest it
refused (``BootTick.recent``). A refused one is the start's first frame, numbered as the
window's frame after it; the window's frames from there that a fresh check refuses behind it
(their COUNTER not 1 .. 7 steps on from it: behind, or repeating it) are left out, as the new
firmware left them out.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.heldboot import STAMP_S, fresh_last
from odocan.host.judge.livewindow import HALF_LAP, Counted, window_counts
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

Heard = tuple[float, Counted]  # bus order (seq; a refused frame's: the taken one's before + 0.5)


def held_counts(tracker: PoseTracker, tick_s: float, primed_now: bool) -> list[Counted] | None:
    """The encoder frames the life whose held summary's tick was heard at bus time ``tick_s``
    takes from its start (``Counted``: the first primes; ``primed_now``: its summary said not
    INIT; module docstring); None when no frame fits in the window."""
    heard = _heard(tracker)
    if primed_now:
        before = [h for h in heard if h[1][6] < tick_s]
        if not before:
            return None
        last_s = max(h[1][6] for h in before)
        together = [h for h in before if h[1][6] >= last_s - STAMP_S]
        first = _retaken(tracker, together) or together[
            fresh_last(np.array([h[1][1] for h in together], dtype=np.int64))]
    else:
        after = [h for h in heard if h[1][6] > tick_s]
        if not after:
            return None
        first = after[0]
    return _taken_from(tracker, first)


def _retaken(tracker: PoseTracker, together: list[Heard]) -> Heard | None:
    """The frame of ``together`` the host's sequence retook after refusing it (its power-up
    pose named it: ``livefreshboot``), if one: the new firmware primed on it, whatever the
    window's order after it (the retake appended it behind the frames the host took in its tick
    before the pose came: kobuki random 908, ``reboot=1.5:0.3,delay=0.1:200``, COUNTER 0 held
    back to 1.800 s, retaken behind the on-time COUNTER 4 of 1.800 s, which ``fresh_last`` then
    named: 49.8 mm beyond)."""
    bound = tracker.boot_tick.bound
    retaken = None if bound is None else bound[0].retaken
    if retaken is None:
        return None
    mine = [h for h in together if h[1][1] == retaken[1] and h[1][6] == retaken[2]
            and h[0] == float(h[1][0])]  # the window's (taken) copy
    return mine[-1] if mine else None


def _heard(tracker: PoseTracker) -> list[Heard]:
    """The window's frames and the latest refused ones (``BootTick.recent``) in bus order."""
    window = tracker.window
    if not len(window):
        return []
    heard: list[Heard] = [(float(f[0]), f) for f in window_counts(window, -1)]
    for (counter, left, right, t_s, uptime), taken in tracker.boot_tick.recent:
        heard.append((taken + 0.5, (taken + 1, counter, left, right, 1, uptime, t_s)))
    return sorted(heard, key=lambda h: h[0])


def _taken_from(tracker: PoseTracker, first: Heard) -> list[Counted]:
    """The frames from ``first`` on: the window's; from a refused one, it and the window's
    after it but those a fresh check refuses right after it (module docstring)."""
    order, frame = first
    counts = window_counts(tracker.window, frame[0])
    if order == float(frame[0]):  # a frame of the window
        return counts
    k = 0
    while k < len(counts) and not 0 < (counts[k][1] - frame[1]) & ENC_COUNTER_MASK < HALF_LAP:
        k += 1
    return [frame, *counts[k:]]
