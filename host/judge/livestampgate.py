"""The live judges' one-frame gate for glitched stamps (issue #11, one judge): the monitor
(``BusMonitor.feed``) and the bridge (``RobotTelemetry.feed``) set aside the frames the log's
readers set aside (``host.io.stampglitch``: one frame stamped far off both its neighbours, its
neighbours in order), by the very rule (``host.io.stamprule``), so a correct drive with one
encoder frame stamped 1000 s ahead PASSes live as in ``analyze`` (it said DISTANCE WRONG, 1.621
mm beyond its tolerance: a 998.7 s "silence", a re-prime).

A frame within ``JUMP_S`` of the frame before it passes at once (``passes``: no latency, one
comparison). One more than ``JUMP_S`` off it is held (``take``) until the next frame tells:
glitched (``stamprule.lone``), it is set aside, never judged (its COUNTER's gap counted lost, as
``analyze`` counts it), with one event naming it (``kind`` ``stamp_glitch``, its detail the
readers' warning, its count kept up to date); else it is released before the next (a real
silence, a paused recorder: its frames come on from the jump). At most ``MAX_SET_ASIDE``, as the
readers. The frame held at the watch's end is judged (``flush``: no next, no glitch). One frame
is held at most: the memory is the frame's.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any, Generic, TypeVar

from odocan.host.io.stamprule import JUMP_S, MAX_SET_ASIDE, lone, off, set_aside_text

T = TypeVar("T")
R = TypeVar("R")
KIND = "stamp_glitch"  # the event's kind


class StampGate(Generic[T]):
    """One bus's frames through the gate (module docstring); ``T``: what the caller holds of a
    frame (its message, the local time it came)."""

    def __init__(self, events: deque[dict[str, Any]]) -> None:
        """``events``: the judge's events, where the set-aside's event goes (once)."""
        self.events = events
        self.before_s = math.nan  # the stamp of the latest frame heard (s; nan: none yet)
        self.frames = 0  # frames heard
        self.count = 0  # frames set aside
        self.event: dict[str, Any] | None = None  # the set-aside's event, once one was
        self._held: T | None = None  # the frame off the one before, its next not heard yet
        self._held_s = math.nan  # its stamp (s)
        self._held_before_s = math.nan  # the stamp of the frame before it (s)

    def passes(self, t_s: float) -> bool:
        """A frame stamped ``t_s`` (s) passes at once (none held, within ``JUMP_S`` of the frame
        before): counted heard; else (false) the caller gives it to ``take``."""
        if self._held is None and not abs(t_s - self.before_s) > JUMP_S:  # (nan: the first)
            self.before_s = t_s
            self.frames += 1
            return True
        return False

    def through(self, t_s: float, frame: T) -> list[T] | tuple[T]:
        """``frame`` stamped ``t_s`` (s): the frames to judge now, in bus order (``frame``
        alone when it ``passes``; else ``take``'s)."""
        return (frame,) if self.passes(t_s) else self.take(t_s, frame)

    def take(self, t_s: float, frame: T) -> list[T]:
        """``frame`` stamped ``t_s`` (s), not ``passes``: the frames to judge now, in bus order
        (the one held, unless glitched; then ``frame``, unless held in its turn)."""
        out: list[T] = []
        held = self._held
        if held is not None:
            self._held = None
            if self.count < MAX_SET_ASIDE and lone(self._held_before_s, self._held_s, t_s):
                self._set_aside(t_s)
            else:
                out.append(held)
        before_s, self.before_s = self.before_s, t_s
        self.frames += 1
        if off(before_s, t_s):  # (nan: the first frame, none before: never glitched)
            self._held, self._held_s, self._held_before_s = frame, t_s, before_s
        else:
            out.append(frame)
        return out

    def flush(self) -> list[T]:
        """The watch ends: the frame held, if any (no next: judged, as the readers' last)."""
        held, self._held = self._held, None
        return [] if held is None else [held]

    def _set_aside(self, next_s: float) -> None:
        """The frame held is glitched: counted, its event made (the first) or counted on."""
        self.count += 1
        if self.event is None:
            self.event = {"t_s": self._held_before_s, "kind": KIND, "number": self.frames,
                          "stamp_s": self._held_s, "between_s": [self._held_before_s, next_s]}
            self.events.append(self.event)
        event = self.event
        event["count"] = self.count
        event["detail"] = set_aside_text(self.count, int(event["number"]), event["stamp_s"],
                                         *event["between_s"])


def judged(frames: list[T], judge: Callable[[T], list[R]]) -> list[R]:
    """What ``judge`` makes of each of ``frames`` (``take``'s, ``flush``'s), in order (the
    bridge's publications)."""
    out: list[R] = []
    for frame in frames:
        out += judge(frame)
    return out
