"""When the bridge publishes each robot's ``status`` and ``rates``: turns spread over a period
(``Bridge._periodic``)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Sequence

SLOTS = 100  # turns per period at most: more robots share the turns


class PeriodicTurns:
    """The due times of ``slots`` turns spread over ``period_s``: slot k's at
    ``start_s + period_s * (k + 1) / slots`` and every ``period_s`` after, for good.

    ``due(now_s)`` names the slots due at a loop turn (1 ms early counts: a sleep that wakes a
    hair early does not cost a whole turn) and moves each to its next due time after ``now_s``
    on its own phase. A loop that stalled for periods publishes each overdue slot once, not once
    per period missed, and the slots keep their spread (before: ``max(due + period, now)`` set
    every slot overdue by more than a period to the same ``now``, and the whole fleet published
    in one loop turn every period from then on).
    """

    EARLY_S = 1e-3

    def __init__(self, slots: int, period_s: float, start_s: float) -> None:
        self.period_s = period_s
        self.due_s = [start_s + period_s * (slot + 1) / slots for slot in range(slots)]

    def due(self, now_s: float) -> list[int]:
        """The slots due at ``now_s``, each moved to its first due time after ``now_s``."""
        fired = [slot for slot, due_s in enumerate(self.due_s) if now_s >= due_s - self.EARLY_S]
        for slot in fired:
            late_s = now_s + self.EARLY_S - self.due_s[slot]
            self.due_s[slot] += self.period_s * (late_s // self.period_s + 1)
            if self.due_s[slot] - self.EARLY_S <= now_s:  # a float a hair short of the period
                self.due_s[slot] += self.period_s
        return fired


async def publish_in_turns(robots: int, periods_s: Sequence[float],
                           publishers: Sequence[Callable[[int, float], None]],
                           clock: Callable[[], float],
                           sleep: Callable[[float], Awaitable[None]]) -> None:
    """Forever: each publisher called as (robot index, now) for every one of ``robots`` once
    in each of its period of ``periods_s``, each robot in a turn of its own (up to ``SLOTS``
    robots; more share the turns), the turns spread over the period: a large fleet's periodic
    publications (~90 us of CPU a robot, plus the QoS-1 status's round trip) never come as a
    burst in one loop turn, which would hold back the fleet's next tick (before, 10 groups: a
    50-robot worker's 5 robots a turn, ~0.5 ms more loop work before one tick in ten). A loop
    that stalled catches up once and keeps the spread (``PeriodicTurns``)."""
    slots = max(1, min(SLOTS, robots))
    groups = [range(slot, robots, slots) for slot in range(slots)]
    start_s = clock()
    schedules = [PeriodicTurns(slots, period_s, start_s) for period_s in periods_s]
    turn_s = min(periods_s) / slots
    while True:
        await sleep(turn_s)
        now_s = clock()
        for schedule, publish in zip(schedules, publishers, strict=True):
            for slot in schedule.due(now_s):
                for robot in groups[slot]:
                    publish(robot, now_s)
