"""When the bridge publishes each robot's ``status`` and ``rates``: turns spread over a period
(``Bridge._periodic``)."""

from __future__ import annotations


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
