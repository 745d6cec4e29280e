"""Listener isolation: a failing listener neither stops python-can's Notifier nor starves others.

python-can's ``Notifier`` calls its listeners in turn: when one raises, the listeners after it miss
that frame, and the receive thread dies unless some listener's ``on_error`` claims the error.
``Isolated`` wraps a listener so its exceptions stay its own: counted, logged (the first with a
traceback, then one line per thousand) and handed to its ``on_error``; the frame goes on to the
next listener.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

import can

log = logging.getLogger("odocan.listeners")


class Isolated(can.Listener):
    """A listener whose exceptions are caught and counted instead of reaching the Notifier."""

    def __init__(self, listener: can.Listener, name: str | None = None) -> None:
        self.listener = listener
        self.name = name or type(listener).__name__
        self.errors = 0
        self.last_error: Exception | None = None

    def on_message_received(self, msg: can.Message) -> None:
        """Deliver ``msg``; an exception is counted and logged, never raised."""
        try:
            self.listener.on_message_received(msg)
        except Exception as exc:
            self._record(exc)

    def _record(self, exc: Exception) -> None:
        self.errors += 1
        self.last_error = exc
        if self.errors == 1:
            log.warning("listener %s failed (isolated, counting)", self.name, exc_info=exc)
        elif self.errors % 1000 == 0:
            log.warning("listener %s: %d failures, last: %s", self.name, self.errors, exc)
        try:
            self.listener.on_error(exc)
        except Exception:
            log.debug("on_error of %s failed too", self.name)

    def on_error(self, exc: Exception) -> None:
        """Errors of the bus itself go to the wrapped listener."""
        self.listener.on_error(exc)

    def stop(self) -> None:
        """Stop the wrapped listener."""
        self.listener.stop()


def isolate(listeners: Iterable[can.Listener]) -> list[can.Listener]:
    """Each listener wrapped in ``Isolated`` (already isolated ones kept as they are)."""
    return [lst if isinstance(lst, Isolated) else Isolated(lst) for lst in listeners]

