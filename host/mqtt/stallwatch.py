"""The bridge's event loop stalled: commands a broker held for it meanwhile may be lost unanswered.

Measured with a 1 500 ``set_pose`` flood on mosquitto 2.0 (operator in another process, issue
#13.4): with the bridge's loop busy but turning (30 or 100 ms of CPU every 10 ms timer turn)
every command was answered; with the loop blocked 6 s, 1 020 of 1 500 were, and mosquitto logged
"Outgoing messages are being dropped for client <the bridge>": a client that does not read gets
``max_inflight_messages`` (20) in flight and ``max_queued_messages`` (1 000) queued, the rest is
dropped, silently for the sender, which already has its PUBACK. The bridge answered every command
it received (1 020 finals for 1 020 received): the others never reached it, and nothing on the
wire says so. Since then the commands are read on a thread of their own
(``host.mqtt.cmdreader``), which goes on reading while the loop is blocked: none is left to the
broker's queue. A stall still delays every answer and every pose: ``StallWatch`` counts the
loop's turns that came ``STALL_S`` or more late while a link was connected (``loop_stalls``, and
``loop_stalled_ms`` in all, in the bridge's counters and the fleet report) and says once what it
does to commands. A stall the process did not run through at all (SIGSTOP, a suspended machine:
SIGCONT arrives as it goes on) stopped the command reader too: then the broker held the commands
and drops those beyond its queue unanswered, and the line says that instead.
"""

from __future__ import annotations

import asyncio
import logging
import signal
import time
from collections.abc import Callable

from odocan.sim.interrupts import handlers_installed

log = logging.getLogger("odocan.mqtt")

STALL_S = 1.0  # no loop turn this long: at 1 000 commands/s a broker's 1 000-slot queue is full
WATCH_PERIOD_S = 0.1


_BLOCKED = ("the bridge's event loop did not run for %.1f s: commands read meanwhile wait in the "
            "command reader's queue (command_queue per robot; beyond, answered busy) and expire "
            "there after --command-expiry (counted in loop_stalls)")
_STOPPED = ("the bridge's process was stopped for %.1f s (SIGSTOP or a suspended machine; "
            "SIGCONT went on): the command reader stopped too, so the broker held the commands "
            "sent meanwhile and drops those beyond its queue unanswered (mosquitto: "
            "max_queued_messages); those read late expire after --command-expiry (counted in "
            "loop_stalls)")


class StallWatch:
    """Counts the event loop's stalls of ``STALL_S`` or more while ``connected()``."""

    def __init__(self, connected: Callable[[], bool]) -> None:
        self.connected = connected
        self.stalls = 0
        self.stalled_s = 0.0  # in all
        self.said: set[bool] = set()  # the kinds of stall said (stopped or not), each once
        self.continued_at_s = float("-inf")  # monotonic time of the last SIGCONT

    async def run(self) -> None:
        """Wake every ``WATCH_PERIOD_S``; a wake that came ``STALL_S`` late is a stall. SIGCONT
        by a Python-level handler, not the loop's: it runs at the first bytecode after the
        process goes on, before the loop turns its late timer (``add_signal_handler``'s callback
        came a turn or two after it)."""
        with handlers_installed({signal.SIGCONT: self.continued}):  # main thread only
            last = time.monotonic()
            while True:
                await asyncio.sleep(WATCH_PERIOD_S)
                now = time.monotonic()
                late_s, since = now - last - WATCH_PERIOD_S, last
                last = now
                if late_s >= STALL_S and self.connected():
                    self.stalled(late_s, stopped=self.continued_at_s >= since)

    def continued(self, *_: object) -> None:
        """SIGCONT: the process had been stopped."""
        self.continued_at_s = time.monotonic()

    def stalled(self, late_s: float, stopped: bool = False) -> None:
        """One stall of ``late_s`` seconds: counted, the first one of each kind said."""
        if stopped not in self.said:
            self.said.add(stopped)
            log.warning(_STOPPED if stopped else _BLOCKED, late_s)
        self.stalls += 1
        self.stalled_s += late_s

    def counters(self) -> dict[str, int]:
        """``loop_stalls`` and ``loop_stalled_ms`` (sums: a sharded fleet adds its shards')."""
        return {"loop_stalls": self.stalls, "loop_stalled_ms": round(self.stalled_s * 1e3)}

