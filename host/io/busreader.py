"""A live bus read on its own thread: every frame recorded the moment it is read, then handed to
the judge through a bounded queue (``odocan monitor``'s receive side).

The monitor's one loop used to read a frame, write it to ``--log``, judge it and redraw the
screen; while it judged, drew or was not scheduled, the frames waited in the socket's buffer and
the kernel dropped what did not fit: a 20 s drive replayed onto udp_multicast on a loaded machine
with three busy loops left recordings without up to 3 337 of its 7 200 frames (the kernel's
count of drops on the monitor's socket agreed: ``host.io.rxsocket``). Here the reading and the
recording do not wait for the judge: the reader thread does nothing else (python-can's
``Notifier`` does the same, but stops its listeners with it and wants a whole ``BusABC``; this
one reads any object with ``recv``). The judge takes the frames from a queue of at most
``capacity``; when it falls that far behind, the frames it cannot take are still recorded,
counted in ``judge_skipped`` and said (the judge may fall behind or skip, the log must not).

Threads: the reader thread calls ``bus.recv`` and ``record``; the caller's thread calls ``get``,
``stop`` and ``drain``. An error of ``bus.recv`` ends the reading and is raised by ``get`` in the
caller's thread once the frames read before it were taken.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterator
from typing import Protocol

import can

from odocan.host.io.rxsocket import SocketDrops, widen_receive_buffer

JUDGE_QUEUE_FRAMES = 200_000  # ~10 min of the rig's 360 frames/s; ~25 s of 8 000 frames/s
POLL_S = 0.1  # the reader sees a stop request within this
JOIN_S = 5.0  # at most this long for a bus whose recv ignores its timeout


class Receiver(Protocol):
    """What the reader needs of a bus."""

    def recv(self, timeout: float | None = None) -> can.Message | None: ...


class BusReader:
    """Read ``bus`` on a thread of its own: ``record(msg)`` at once (``--log``), then queue it
    for the judge (``get``)."""

    def __init__(self, bus: Receiver, record: Callable[[can.Message], None] | None = None,
                 capacity: int = JUDGE_QUEUE_FRAMES,
                 notify: Callable[[], None] | None = None) -> None:
        """Widens the receive buffer of a bus over a socket at once (``host.io.rxsocket``).
        ``notify()`` is called on the reader thread after each frame queued for the judge (a
        consumer that waits elsewhere than in ``get``, e.g. an event loop, is woken by it)."""
        self.bus, self.record, self.notify = bus, record, notify
        self.socket_buffer_bytes = widen_receive_buffer(bus)
        self.socket_drops = SocketDrops(bus)
        self.read = 0  # frames read from the bus
        self.judge_skipped = 0  # frames read (and recorded) that the judge's full queue refused
        self.error: BaseException | None = None  # what ended the reading (raised by ``get``)
        self._queue: queue.Queue[can.Message] = queue.Queue(maxsize=capacity)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="odocan-bus-reader", daemon=True)

    def start(self) -> BusReader:
        """Start reading; returns self."""
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                msg = self.bus.recv(timeout=POLL_S)
                if msg is not None:
                    self._take(msg)
        except BaseException as exc:  # the bus failed (or a test's bus "got Ctrl-C" in recv):
            self.error = exc  # raised in the caller's thread (``get``)

    def _take(self, msg: can.Message) -> None:
        self.read += 1
        if self.record is not None:
            self.record(msg)
        try:
            self._queue.put_nowait(msg)
        except queue.Full:
            self.judge_skipped += 1
            return
        if self.notify is not None:
            self.notify()

    def get(self, timeout_s: float) -> can.Message | None:
        """The next frame for the judge, waiting up to ``timeout_s``; None when none came. Raises
        the bus's error once every frame read before it was taken (the error is set after the
        reader's last ``put``: seen set with the queue empty, nothing is left behind)."""
        self._raise_when_done()
        try:
            return self._queue.get(timeout=timeout_s) if timeout_s > 0 else \
                self._queue.get_nowait()
        except queue.Empty:
            pass
        self._raise_when_done()
        return None

    def _raise_when_done(self) -> None:
        if self.error is not None and self._queue.empty():
            raise self.error

    @property
    def pending(self) -> int:
        """Frames read and not yet taken by the judge."""
        return self._queue.qsize()

    def socket_dropped(self) -> int | None:
        """Frames the kernel dropped on the bus's socket since it was opened (its receive buffer
        full: the reader was not scheduled in time), or None when it does not count them; the
        last count read once the socket is closed."""
        now = self.socket_drops.count()
        return self.socket_drops.last if now is None else now

    def stats(self) -> dict[str, int | None]:
        """What was read and what was lost here, for the monitor's JSON: ``read`` (frames read
        from the bus), ``judge_skipped`` (read and recorded, refused by the judge's full queue),
        ``judge_pending`` (read and recorded, not judged: a signal ended the watch),
        ``socket_dropped`` (never read: the kernel dropped them, None when it does not count),
        ``socket_buffer_bytes`` (the receive buffer the kernel granted, None without a socket)."""
        return {"read": self.read, "judge_skipped": self.judge_skipped,
                "judge_pending": self.pending, "socket_dropped": self.socket_dropped(),
                "socket_buffer_bytes": self.socket_buffer_bytes}

    def stop(self) -> None:
        """Stop reading (within ``POLL_S``, or once a blocking ``recv`` returns); idempotent.
        The socket's drop count is read here for the last time (call it before closing the bus)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(JOIN_S)
        self.socket_drops.count()

    def drain(self) -> Iterator[can.Message]:
        """After ``stop``: the frames read that the judge has not taken yet, in order."""
        while True:
            try:
                yield self._queue.get_nowait()
            except queue.Empty:
                return


def lost_here_text(stats: dict[str, int | None], *, short: bool = False) -> str:
    """What this process lost of the bus (``BusReader.stats``), in words; "" when nothing: the
    frames the kernel dropped before they were read (in neither the log nor the judge) apart
    from those read and recorded that the judge skipped. The E2E ``lost`` counts of the
    monitor's messages include both: the bus and the sender did not lose these. ``short``:
    for the screen's last line (``120 dropped by the socket, 5 not judged``)."""
    parts = []
    if dropped := stats.get("socket_dropped"):
        parts.append(f"{dropped} dropped by the socket" if short else
                     f"{dropped} frames dropped by the kernel before they were read (socket "
                     f"receive buffer of {(stats.get('socket_buffer_bytes') or 0) >> 10} KiB "
                     "full): in neither the log nor the judge")
    if skipped := stats.get("judge_skipped"):
        parts.append(f"{skipped} not judged" if short else
                     f"{skipped} frames recorded but not judged (the judge fell behind)")
    return ", ".join(parts) if short else "; ".join(parts)
