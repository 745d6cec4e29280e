"""A live hold's frames as a log's arrays, made once per hold and grown as frames come
(``host.judge.livesettle``; ``host.judge.liveearly`` reads its evidence every ``RETRY_S``).

Each read judges the frames judged before the hold (its context, up to ``CONTEXT_FRAMES``) and
those held so far, whole (``check_frames``). Their arrays were made anew at each read, a Python
append per frame: 10 % of a live judge's time on a ``delay=0.5:150`` drive. Within a hold the
context does not change (the frames judged before it are the same objects, the state it is
made from the same: ``ContextKey``) and the frames held only grow, in order; so the context's
arrays are made once and the frames held since the last read appended to them. The arrays are
the very ones ``FrameCollector`` makes of the whole list (it only appends, in order): anything
else (a new hold, a context re-made, frames held anew after a release) makes them anew.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import can

    from odocan.host.io.collector import FrameCollector
    from odocan.host.io.logs import FrameArrays

# What a hold's context is made from besides the frames judged before it (compared with ==):
# the message's last frame taken before the hold, E2EMonitor.retaken
ContextKey = tuple[object, ...]


class HoldArrays:
    """The arrays of a hold's context and frames held (module docstring)."""

    __slots__ = ("_collector", "_context_len", "_held", "_key", "_recent")

    def __init__(self) -> None:
        self._recent: list[object] = []  # the entries of ``recent`` the context was made of
        self._key: ContextKey = ()
        self._collector: FrameCollector | None = None  # the context's frames, then the held
        self._context_len = 0  # frames of the context in the collector
        self._held: list[can.Message] = []  # the frames held in the collector, in order

    def arrays(self, recent: Sequence[object], key: ContextKey,
               context: Callable[[], list[can.Message]], held: Sequence[can.Message]
               ) -> tuple[FrameArrays, int]:
        """The arrays of ``context()`` (made from the entries ``recent`` and ``key``) followed
        by ``held``, and the number of context frames."""
        if not self._same_context(recent, key) or not self._grows(held):
            self._start(recent, key, context())
        collector = self._collector
        assert collector is not None
        for msg in held[len(self._held):]:
            collector.on_message_received(msg)
            self._held.append(msg)
        return collector.arrays(), self._context_len

    def _same_context(self, recent: Sequence[object], key: ContextKey) -> bool:
        """Whether the context would be made from the very entries and state as last time."""
        mine = self._recent
        return (self._collector is not None and key == self._key and len(recent) == len(mine)
                and all(a is b for a, b in zip(recent, mine, strict=True)))

    def _grows(self, held: Sequence[can.Message]) -> bool:
        """Whether the frames held in the collector are the first of ``held``, in order."""
        mine = self._held
        return len(held) >= len(mine) and all(a is b for a, b in zip(held, mine, strict=False))

    def _start(self, recent: Sequence[object], key: ContextKey,
               context: list[can.Message]) -> None:
        """Arrays anew: the context's frames, none held yet."""
        from odocan.host.io.collector import FrameCollector  # a hold's only (its import's cost)

        self._recent, self._key = list(recent), key
        self._collector = FrameCollector()
        for msg in context:
            self._collector.on_message_received(msg)
        self._context_len, self._held = len(context), []
