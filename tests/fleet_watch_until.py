"""``odocan monitor --mqtt`` ended once it saw what a test checks, its ``--duration`` a bound.

The monitor's fleet watch runs for its whole ``--duration`` of wall time, connecting included:
a test that gave it 1-2 s and then read its table depended on the machine's load (a loaded CI
machine's loop stalled 1.1 s: the monitor ended before it had connected, or before the broker
handed it the retained status the test had published). Here the watch ends (as at its
duration) as soon as ``seen(watch)`` holds; the test's ``--duration`` only bounds a hang.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from typing import Any

import pytest

from odocan.host.cli.subparsers import monitor as monitor_cmd

BOUND_S = "60"  # the monitor's --duration where it ends once it saw what is checked
POLL_S = 0.01


def end_watch_once(monkeypatch: pytest.MonkeyPatch, seen: Callable[[Any], bool]) -> None:
    """The monitor's fleet watch (``monitor._FleetWatch``) ends once ``seen(watch)`` holds
    (``watch.connected_once``, ``watch.table``); a connection error still ends it as before."""

    class UntilSeen(monitor_cmd._FleetWatch):
        async def _follow(self, redraw: Callable[[], None] | None) -> None:
            follow = asyncio.ensure_future(super()._follow(redraw))
            try:
                while not seen(self):
                    if follow.done():
                        await follow  # its error, as the watch raises it
                        return
                    await asyncio.sleep(POLL_S)
            finally:
                follow.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await follow

    monkeypatch.setattr(monitor_cmd, "_FleetWatch", UntilSeen)
