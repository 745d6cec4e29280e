"""A live bus into the bridge's event loop: ``odocan monitor``'s reader (``host.io.busreader``),
and what this process lost of the bus said apart in ``status`` (``receive``) and its events.

The bridge's reader thread used to hand every burst of frames it read to the event loop as one
batch of the bridge's bounded queue (1 024 batches): while the loop was busy (judging,
publishing, a slow broker's callbacks) the thread, holding the GIL for a few frames at a time,
made batches of one or two frames and the queue overflowed: 929 of a 3 000-frame burst at
2 000 frames/s were dropped while the loop was held 1 s, said only in the exit line, and the
judge took them for the bus's losses. Stopped by the machine (SIGSTOP 2 s, a loaded laptop),
the kernel dropped 469 of a 20 s drive at the rig's 360 frames/s (Linux's default socket buffer,
256 udp_multicast frames), said nowhere. Here the bus is read by ``host.io.busreader.BusReader``
(the socket's receive buffer widened, the kernel's drops counted, a queue of
``JUDGE_QUEUE_FRAMES`` that counts what it must skip); the task ``can-feed`` moves its frames to
the bridge's queue in batches of up to ``max_batch`` (each frame on the drive's clock: a
sped-up replay's, ``host.judge.livepace``), waiting for room rather than dropping, and
sleeps while the reader has nothing (woken by the reader's ``notify``, then ``COALESCE_S`` more,
so a burst of frames costs the loop one wake-up, not one each: woken per frame, the bridge took
~14 % more CPU than main's reader on a 20 s replay at 360 frames/s, ~2 % with it).

What this process lost is not the bus's nor the firmware's: ``status`` carries ``receive``
(``BusReader.stats`` plus ``bus_errors``) and a ``lost_here`` event each time the frames
dropped by the kernel or skipped by the queue grew (the E2E ``lost`` counts of ``rates``
include them: the sender did not lose these). A bus error is counted, logged once, and the
reading goes on (after 0.1 s: a bus that is down must not spin a core).

Threads: the reader thread calls the bus's ``recv`` and ``_wake``; everything else runs on the
event loop's thread.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from typing import TYPE_CHECKING, Any

import can

from odocan.host.io.busreader import JUDGE_QUEUE_FRAMES, BusReader
from odocan.host.judge.livepace import LivePace

if TYPE_CHECKING:
    from odocan.host.mqtt.bridge import Batch, Bridge

log = logging.getLogger(__name__)
COALESCE_S = 0.002  # woken by a frame, the feed takes what came within this, in one go
ERROR_PAUSE_S = 0.1  # after a bus error, the next recv this much later at least


class _ReadsOn:
    """A bus whose ``recv`` errors are counted and logged once, then read on (``fileno`` passed
    through, so the reader widens and watches the bus's own socket)."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.errors = 0
        self.stopped = threading.Event()

    def recv(self, timeout: float | None = None) -> can.Message | None:
        try:
            return self.bus.recv(timeout)
        except (can.CanError, OSError, ValueError) as exc:
            if self.errors == 0:
                log.warning("CAN bus %s: %s (reading on)", self.bus.channel_info, exc)
            self.errors += 1
            self.stopped.wait(max(timeout or 0.0, ERROR_PAUSE_S))
            return None

    def fileno(self) -> int:
        return self.bus.fileno()


class BusFeed:
    """One robot's live bus into ``bridge`` (see the module docstring); ``robot_index`` says whose
    frames they are (0 for a one-robot bus). ``start`` and ``stop`` on the loop's thread."""

    def __init__(
        self, bus: can.BusABC, bridge: Bridge, loop: asyncio.AbstractEventLoop, *,
        robot_index: int = 0, max_batch: int = 256, capacity: int = JUDGE_QUEUE_FRAMES,
    ) -> None:
        self.bridge, self.loop = bridge, loop
        self.robot_index, self.max_batch = robot_index, max_batch
        self._bus = _ReadsOn(bus)
        self._woken = asyncio.Event()
        self._asleep = False  # the feed waits for ``_woken`` (read by the reader thread)
        self.reader = BusReader(self._bus, capacity=capacity, notify=self._wake)
        self._task: asyncio.Task[None] | None = None
        self._lost_said = 0  # frames lost here as of the latest ``lost_here`` event
        self.last_t_s = 0.0  # bus timestamp of the latest frame fed (the events' ``t_s``)
        # a sped-up replay's frames on the drive's clock, as the monitor judges them (livepace)
        self.pace = LivePace(bridge.robots[robot_index].telemetry.db)

    @property
    def errors(self) -> int:
        """Bus errors while reading (counted, logged once)."""
        return self._bus.errors

    def start(self) -> None:
        """Start the reader thread and the task ``can-feed``; ``status`` carries ``receive``."""
        self.bridge.robots[self.robot_index].receive = self.receive
        self.reader.start()
        self._task = self.loop.create_task(self._feed(), name="can-feed")

    def stop(self) -> None:
        """Stop reading (within the reader's 0.1 s poll) and feeding; the kernel's drop count
        is read one last time (call it before closing the bus)."""
        self._bus.stopped.set()
        self.reader.stop()
        if self._task is not None:
            self._task.cancel()

    def _wake(self) -> None:
        """On the reader thread, after a frame was queued: wake the feed if it sleeps."""
        if self._asleep:
            self._asleep = False
            with contextlib.suppress(RuntimeError):  # the loop is closed: shutting down
                self.loop.call_soon_threadsafe(self._woken.set)

    async def _feed(self) -> None:
        while True:
            batch = self._take()
            if not batch:
                self._asleep = True  # then look again: a frame queued before it is not missed
                batch = self._take()
                if not batch:
                    await self._woken.wait()
                    self._woken.clear()
                    await asyncio.sleep(COALESCE_S)  # the rest of a burst comes with it
                    continue
                self._asleep = False
            await self.bridge.queue.put(batch)  # no room: the reader's queue holds the rest

    def _take(self) -> Batch:
        """Up to ``max_batch`` frames the reader has queued, without waiting."""
        index, reader = self.robot_index, self.reader
        batch: Batch = []
        while len(batch) < self.max_batch and (msg := reader.get(0)) is not None:
            msg = self.pace.stamped(msg)
            batch.append((index, msg))
            self.last_t_s = msg.timestamp
        return batch

    def receive(self) -> dict[str, Any]:
        """``status``'s ``receive`` (called once per ``status``): ``BusReader.stats``
        (``read``, ``judge_skipped``, ``judge_pending``, ``socket_dropped``: None where the
        kernel does not count, ``socket_buffer_bytes``) and ``bus_errors``; when the frames
        lost here grew since the last call, a ``lost_here`` event joins the robot's events."""
        stats: dict[str, Any] = {**self.reader.stats(), "bus_errors": self.errors}
        event = self._lost_here_event(stats)
        if event is not None:
            self.bridge.robots[self.robot_index].telemetry.events.append(event)
        return stats

    def _lost_here_event(self, stats: dict[str, Any]) -> dict[str, Any] | None:
        """A ``lost_here`` event when the frames lost here (dropped by the kernel, skipped by
        the queue) grew since the last one (``frames``: how many more), else None."""
        lost = (stats["socket_dropped"] or 0) + stats["judge_skipped"]
        if lost <= self._lost_said:
            return None
        new, self._lost_said = lost - self._lost_said, lost
        return {"t_s": self.last_t_s, "kind": "lost_here", "frames": new,
                "socket_dropped": stats["socket_dropped"],
                "judge_skipped": stats["judge_skipped"]}
