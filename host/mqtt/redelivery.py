"""The commands a broker delivers twice: run once.

QoS 1 is "at least once": a broker that sent a command and did not get our PUBACK (it restarted,
or the connection broke before the PUBACK went out) sends it again after the reconnect, with the
DUP flag set. The bridge had run it already: measured from outside on mosquitto restarted
(SIGTERM) while the bridge was stopped, every one of four commands was run twice, a
``nav_goal`` with ``append`` appending its goal twice.

``Redeliveries`` remembers the last ``capacity`` commands a link handled, by topic leaf and
payload bytes; a DUP copy of one of them is not handled again (its first delivery was answered
on ``cmd/result``). A command published twice by its sender is two messages without DUP: both
run. A DUP copy this process never saw (the bridge restarted meanwhile) runs.
"""

from __future__ import annotations

from collections import OrderedDict

DEFAULT_CAPACITY = 1024  # commands remembered per robot (a few KiB each at most)


class Redeliveries:
    """The commands one link handled, newest last, at most ``capacity``."""

    def __init__(self, capacity: int = DEFAULT_CAPACITY) -> None:
        self.capacity = capacity
        self._seen: OrderedDict[tuple[str, bytes], None] = OrderedDict()
        self.skipped = 0  # DUP copies not handled again

    def is_repeat(self, name: str, payload: bytes, *, dup: bool) -> bool:
        """True for a DUP copy of a command handled before (counted in ``skipped``); else
        remember this one and return False."""
        key = (name, payload)
        if dup and key in self._seen:
            self.skipped += 1
            return True
        self._seen[key] = None
        self._seen.move_to_end(key)
        if len(self._seen) > self.capacity:
            self._seen.popitem(last=False)
        return False
