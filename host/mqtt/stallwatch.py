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
does to commands.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable

log = logging.getLogger("odocan.mqtt")

STALL_S = 1.0  # no loop turn this long: at 1 000 commands/s a broker's 1 000-slot queue is full
WATCH_PERIOD_S = 0.1


class StallWatch:
    """Counts the event loop's stalls of ``STALL_S`` or more while ``connected()``."""

    def __init__(self, connected: Callable[[], bool]) -> None:
        self.connected = connected
        self.stalls = 0
        self.stalled_s = 0.0  # in all

    async def run(self) -> None:
        """Wake every ``WATCH_PERIOD_S``; a wake that came ``STALL_S`` late is a stall."""
        last = time.monotonic()
        while True:
            await asyncio.sleep(WATCH_PERIOD_S)
            now = time.monotonic()
            late_s, last = now - last - WATCH_PERIOD_S, now
            if late_s >= STALL_S and self.connected():
                self.stalled(late_s)

    def stalled(self, late_s: float) -> None:
        """One stall of ``late_s`` seconds: counted, the first one said."""
        if not self.stalls:
            log.warning("the bridge's event loop did not run for %.1f s: commands read "
                        "meanwhile wait in the command reader's queue (command_queue per robot; "
                        "beyond, answered busy) and expire there after --command-expiry "
                        "(counted in loop_stalls)", late_s)
        self.stalls += 1
        self.stalled_s += late_s

    def counters(self) -> dict[str, int]:
        """``loop_stalls`` and ``loop_stalled_ms`` (sums: a sharded fleet adds its shards')."""
        return {"loop_stalls": self.stalls, "loop_stalled_ms": round(self.stalled_s * 1e3)}
