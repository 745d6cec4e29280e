"""``odocan``: a lean in-process CAN transport, as a python-can interface plugin.

``can.Bus(interface="odocan", channel="x")`` opens a handle on channel ``x``; every handle on the
same channel in the same process is a node on one wire. The semantics are python-can ``virtual``'s:

* every OTHER handle on the channel receives every frame; the sender gets its own frame back only
  when opened with ``receive_own_messages=True`` (then with ``is_rx=False``, as virtual does);
* each receiver gets a ``can.Message`` of its own (fresh object, fresh ``bytearray``): no receiver
  ever shares a mutable message with another, nor with the sender;
* ``timestamp`` is the sent message's own with ``preserve_timestamps=True``, else ``time.time()``
  at the send; ``channel`` is the channel's name;
* reliable, in-order delivery; ``rx_queue_size`` > 0 bounds a handle's queue (the oldest frame is
  dropped to make room, counted in ``rx_overruns``); python-can's filters act as the receiver's
  acceptance filter: a frame they refuse never enters its queue (and ``recv`` checks again, for
  frames queued before ``set_filters``).

**The lockstep rig's path** (issue #13): ``send_data(id, payload, t)`` queues one immutable
``DataFrame`` tuple ``(t, id, payload)`` that every accepting receiver shares (no ``Message`` per
receiver); ``recv`` still hands out a fresh ``Message`` of it, while ``drain`` returns a tick's
frames as queued, and ``FrameBatchListener``s (``host.io.frames.FrameCollector``) take them so.

It is faster than virtual because it does less: one fresh message per accepting receiver built slot
by slot (virtual deep-copies the message, its ``bytearray`` and its channel with ``deepcopy``), a
``collections.deque`` per handle instead of a ``queue.Queue`` (no lock on the lockstep path: a
receiver that blocks in ``recv(timeout)`` parks on a condition the sender notifies only then), and
``recv`` overridden so a poll costs one ``popleft``. Thread-safe for python-can's ``Notifier``:
``deque.append``/``popleft`` are atomic and the handle list is replaced, never mutated.

**Bit-timed mode** (``bitrate=...``, issue #16): the wire then has time. A sent frame becomes
ready at its timestamp (or at the latest time the wire was already run to: it never goes back);
whenever the bus falls idle, every ready frame of every handle contends and the lowest identifier
wins, as bitwise arbitration does (``sim.canbits.arbitration_key``; equal keys leave in the order
they became ready, then were sent: each handle is a controller whose transmit buffers all take
part in arbitration, in priority-by-identifier mode). The winner occupies the bus for its exact
length (``sim.canbits.frame_bits``: its own stuff bits, CRC-15 included), then the 3-bit
interframe space keeps it idle. Each receiver gets the frame stamped with its end-of-frame time,
and only once its handle's ``clock()`` has reached that time (default ``time.time``; the lockstep
rig passes its simulated clock). The bitrate belongs to the wire: the first handle on a channel
sets it (or leaves the wire instant), later ones must agree or give none. The wire counts what it
carried (``frames``, ``busy_bits``) and, per identifier, each frame's latency from ready to end of
frame (``latency``: ``sim.canbits.LatencyStats``, streaming max and p99 in bounded memory).

The plugin is registered under python-can's ``can.interface`` entry point group (pyproject.toml);
``register()`` adds it by hand to a python-can whose entry points predate the install.
"""

from __future__ import annotations

import copy
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Final

import can
from can import BusABC, CanInitializationError, CanOperationError, Message
from can.typechecking import AutoDetectedConfig, CanFilters, Channel

from odocan.sim.canbits import INTERFRAME_BITS, LatencyStats, arbitration_key, frame_bits
from odocan.sim.framebatch import DataFrame, Received

INTERFACE: Final = "odocan"
_POLL_S: Final = 0.001  # a bit-timed receiver blocked in recv looks at the wire this often
_new_message = Message.__new__
# A data frame's receivers (``_Wire._route``): each handle with its queue's ``append`` (None:
# bounded, through ``OdocanBus._put``).
_Route = tuple[tuple["OdocanBus", Callable[[Received], None] | None], ...]


class _Wire:
    """One channel: the handles on it (an immutable tuple, replaced on open and close) and, in
    bit-timed mode, the bus's own state."""

    __slots__ = ("handles", "name", "timing")

    def __init__(self, name: Channel, bitrate: int | None) -> None:
        self.name = name
        self.handles: tuple[OdocanBus, ...] = ()
        self.timing = None if bitrate is None else BitTiming(self, bitrate)

    def deliver_data(
        self, sender: OdocanBus, timestamp: float, can_id: int, data: bytes | bytearray
    ) -> None:
        """``deliver`` of a classic 11-bit data frame given by its fields (``data_frame``'s),
        without the sender's ``Message``: every receiver whose filter passes ``can_id`` queues
        one shared, immutable ``DataFrame`` (its ``Message`` is built only if ``recv`` asks);
        the sender's own echo, when asked for, is a ``Message`` (``is_rx=False``)."""
        frame: DataFrame = (timestamp, can_id, bytes(data))
        route = sender._routes.get(can_id)
        if route is None:
            route = self._route(sender, can_id)
        for handle, append in route:
            if append is None:  # a bounded queue: the oldest frame may have to go
                handle._put(frame)
                continue
            append(frame)  # handle._put(frame), inlined: two receivers a frame in the rig
            if handle._waiting:
                with handle._ready:
                    handle._ready.notify()
        if sender.receive_own_messages:
            echo = sender.as_message(frame)
            echo.is_rx = False
            if sender._filters is None or sender._matches_filters(echo):
                sender._put(echo)

    def _route(self, sender: OdocanBus, can_id: int) -> _Route:
        """The handles other than ``sender`` whose acceptance filter passes a data frame of
        ``can_id``, in the wire's order, each with its queue's ``append`` (None when the queue
        is bounded: ``_put`` counts the overrun); kept in ``sender._routes`` until a handle
        opens or closes or a filter changes (``forget_routes``)."""
        route = tuple(
            (h, None if h._queue.maxlen is not None else h._queue.append)
            for h in self.handles
            if h is not sender and (h._filters is None or h._accepts_data(can_id))
        )
        sender._routes[can_id] = route
        return route

    def set_handles(self, handles: tuple[OdocanBus, ...]) -> None:
        """The handles on the wire from now on (under ``_wires_lock``); every route forgotten."""
        before = self.handles
        self.handles = handles
        for handle in (*before, *handles):
            handle._routes = {}

    def forget_routes(self) -> None:
        """Every handle's routes, computed again at its next send (a filter changed)."""
        for handle in self.handles:
            handle._routes = {}

    def deliver(self, sender: OdocanBus, msg: Message, timestamp: float) -> None:
        """A fresh copy of ``msg``, stamped ``timestamp``, into every handle that hears it."""
        name = self.name
        data = msg.data
        for handle in self.handles:
            if handle is sender and not sender.receive_own_messages:
                continue
            if handle._filters is not None and not handle._matches_filters(msg):
                continue  # the receiver's acceptance filter: the frame never enters its queue
            # A fresh Message, slot by slot (Message.__init__ with keywords costs twice as much).
            out: Message = _new_message(Message)
            out.timestamp = timestamp
            out.arbitration_id = msg.arbitration_id
            out.is_extended_id = msg.is_extended_id
            out.is_remote_frame = msg.is_remote_frame
            out.is_error_frame = msg.is_error_frame
            out.channel = name
            out.dlc = msg.dlc
            out.data = bytearray(data)
            out.is_fd = msg.is_fd
            out.is_rx = handle is not sender
            out.bitrate_switch = msg.bitrate_switch
            out.error_state_indicator = msg.error_state_indicator
            handle._put(out)


# A frame in a transmit buffer: (arbitration key, ready s, send number, bits, sender, message).
# Tuples order as arbitration picks among ready frames; the send number is unique, so the
# comparison never reaches the sender.
_Pending = tuple[tuple[int, int, int, int, int], float, int, int, "OdocanBus", Message]


class BitTiming:
    """The bus of a bit-timed wire: transmit buffers, arbitration, the frame on the wire."""

    def __init__(self, wire: _Wire, bitrate: int) -> None:
        self.wire = wire
        self.bitrate = bitrate
        self.lock = threading.RLock()
        self.pending: list[_Pending] = []
        self.on_wire: tuple[_Pending, float, float] | None = None  # frame, start s, end s
        self.idle_from_s = -math.inf  # the bus is idle (after the interframe space) from here
        self.horizon_s = -math.inf  # the latest time the wire has been run to
        self.next_event_s = math.inf  # nothing happens on the wire before this
        self.frames = 0  # frames transmitted
        self.busy_bits = 0  # bit times those frames and their interframe spaces took
        self.latency = LatencyStats(bitrate)  # per ID: ready to end of frame, streaming max/p99
        self._seq = 0

    def enqueue(self, sender: OdocanBus, msg: Message, ready_s: float) -> None:
        """``msg`` enters ``sender``'s transmit buffer, ready from ``ready_s`` (a snapshot: the
        sender may reuse its message)."""
        try:
            bits = frame_bits(msg)
        except ValueError as exc:
            raise CanOperationError(f"bit-timed wire: {exc}") from None
        snapshot = copy.copy(msg)
        snapshot.data = bytearray(msg.data)  # Message.__copy__ shares the bytearray
        key = arbitration_key(msg)
        with self.lock:
            self._seq += 1
            ready = max(ready_s, self.horizon_s)
            self.pending.append((key, ready, self._seq, bits, sender, snapshot))
            if self.on_wire is None:
                self.next_event_s = min(self.next_event_s, max(ready, self.idle_from_s))

    def drop_pending_of(self, sender: OdocanBus) -> None:
        """Forget ``sender``'s frames still waiting for the bus."""
        with self.lock:
            self.pending = [p for p in self.pending if p[4] is not sender]

    def run_until(self, now_s: float) -> None:
        """Transmit, arbitrate and deliver everything the bus does up to ``now_s``."""
        with self.lock:
            if now_s > self.horizon_s:
                self.horizon_s = now_s
            if now_s < self.next_event_s:  # a receiver polling again: nothing new
                return
            while True:
                if self.on_wire is not None:
                    frame, start_s, end_s = self.on_wire
                    if end_s > now_s:
                        self.next_event_s = end_s
                        return
                    self.on_wire = None
                    self.latency.record(frame[5], frame[1], start_s, end_s)
                    self.wire.deliver(frame[4], frame[5], end_s)
                if not self._start_next(now_s):
                    return

    def _start_next(self, now_s: float) -> bool:
        """Arbitrate at the next bus idle, if it comes by ``now_s``; True when a frame won."""
        pending = self.pending
        if not pending:
            self.next_event_s = math.inf
            return False
        idle_s = max(self.idle_from_s, min(p[1] for p in pending))
        if idle_s > now_s:
            self.next_event_s = idle_s
            return False
        winner = min(p for p in pending if p[1] <= idle_s)
        pending.remove(winner)
        bits = winner[3]
        end_s = idle_s + bits / self.bitrate
        self.on_wire = (winner, idle_s, end_s)
        self.idle_from_s = idle_s + (bits + INTERFRAME_BITS) / self.bitrate
        self.frames += 1
        self.busy_bits += bits + INTERFRAME_BITS
        return True


_wires: dict[Channel, _Wire] = {}
_wires_lock: Final = threading.Lock()

def data_frame(timestamp_s: float, can_id: int, data: bytes | bytearray) -> Message:
    """A classic 11-bit data frame, as ``can.Message(timestamp=..., arbitration_id=...,
    is_extended_id=False, data=...)`` builds it, built slot by slot (half the cost)."""
    out: Message = _new_message(Message)
    out.timestamp = timestamp_s
    out.arbitration_id = can_id
    out.is_extended_id = False
    out.is_remote_frame = False
    out.is_error_frame = False
    out.channel = None
    out.data = bytearray(data)
    out.dlc = len(out.data)
    out.is_fd = False
    out.is_rx = True
    out.bitrate_switch = False
    out.error_state_indicator = False
    return out


class OdocanBus(BusABC):
    """A handle on an in-process CAN channel (see the module docstring).

    Args:
        channel: any hashable name; handles with equal names share a wire.
        receive_own_messages: also receive what this handle sends (``is_rx=False``).
        rx_queue_size: frames a handle holds before the oldest is dropped (0: unbounded).
        preserve_timestamps: keep each sent message's ``timestamp`` (lockstep simulated time);
            otherwise stamp it with ``time.time()`` at the send.
        can_filters: python-can filters, applied as the receiver's acceptance filter.
        bitrate: bit/s: the wire is bit-timed (see the module docstring); None: instant.
        clock: this handle's time in bit-timed mode, s, on the timestamps' scale (default
            ``time.time``): ``recv`` gets the frames whose end of frame it has reached.
    """

    def __init__(
        self,
        channel: Channel = "channel-0",
        receive_own_messages: bool = False,
        rx_queue_size: int = 0,
        preserve_timestamps: bool = False,
        can_filters: CanFilters | None = None,
        bitrate: int | None = None,
        clock: Callable[[], float] | None = None,
        **kwargs: Any,
    ) -> None:
        if rx_queue_size < 0:
            raise ValueError(f"rx_queue_size must be >= 0, got {rx_queue_size}")
        if bitrate is not None and (
            isinstance(bitrate, bool) or int(bitrate) != bitrate or bitrate <= 0
        ):
            raise CanInitializationError(f"bitrate must be a positive integer, got {bitrate!r}")
        self.channel_id = channel
        self.channel_info = f"odocan in-process channel {channel!r}"
        self.receive_own_messages = bool(receive_own_messages)
        self.preserve_timestamps = bool(preserve_timestamps)
        self.rx_overruns = 0
        self.clock = clock or time.time
        self._queue: deque[Received] = deque(maxlen=rx_queue_size or None)
        self._waiting = False
        self._ready = threading.Condition(threading.Lock())
        self._open = True
        self._data_accepts: dict[int, bool] = {}  # can_id -> the filters pass its data frame
        # can_id -> the other handles a data frame this handle sends reaches (_Wire._route)
        self._routes: dict[int, _Route] = {}
        with _wires_lock:
            wire = _wires.get(channel)
            if wire is None:
                wire = _wires[channel] = _Wire(channel, None if bitrate is None else int(bitrate))
            elif bitrate is not None and (wire.timing is None or wire.timing.bitrate != bitrate):
                have = "instant" if wire.timing is None else f"{wire.timing.bitrate} bit/s"
                raise CanInitializationError(
                    f"channel {channel!r} is already open {have}, not {bitrate} bit/s"
                )
            wire.set_handles((*wire.handles, self))
        self._wire = wire
        self.timing = wire.timing
        super().__init__(channel=channel, can_filters=can_filters, **kwargs)

    # --- sending ----------------------------------------------------------------------------

    def send(self, msg: Message, timeout: float | None = None) -> None:
        """Put ``msg`` on the wire: a fresh copy for every other handle (and this one with
        ``receive_own_messages``) whose filters accept it, at once or, bit-timed, at its end of
        frame. Never blocks; ``timeout`` is accepted and unused."""
        if not self._open:
            raise CanOperationError("Cannot operate on a closed bus")
        timestamp = msg.timestamp if self.preserve_timestamps else time.time()
        if self.timing is None:
            self._wire.deliver(self, msg, timestamp)
        else:
            self.timing.enqueue(self, msg, timestamp)

    def send_data(self, can_id: int, data: bytes | bytearray, timestamp: float) -> None:
        """``send(data_frame(timestamp, can_id, data))`` on an instant wire, without building
        the sender's ``Message`` (the receivers get theirs as from ``send``): the lockstep rig's
        nodes send this way (``sim.node.BusNode``). A bit-timed wire goes through ``send``."""
        if self.timing is None and self._open:
            self._wire.deliver_data(
                self, timestamp if self.preserve_timestamps else time.time(), can_id, data
            )
        else:  # closed (refused there) or bit-timed
            self.send(data_frame(timestamp, can_id, data))

    def _put(self, msg: Received) -> None:
        """Queue one received frame (runs in the sender's thread)."""
        queue = self._queue
        if queue.maxlen is not None and len(queue) == queue.maxlen:
            self.rx_overruns += 1
        queue.append(msg)
        if self._waiting:
            with self._ready:
                self._ready.notify()

    # --- receiving --------------------------------------------------------------------------

    def recv(self, timeout: float | None = None) -> Message | None:
        """The next frame that passes the filters, waiting up to ``timeout`` s (None: forever;
        0: poll)."""
        if not self._open:
            raise CanOperationError("Cannot operate on a closed bus")
        if self.timing is not None:
            self.timing.run_until(self.clock())
        queue = self._queue
        if self._filters is None:
            if queue:
                return self.as_message(queue.popleft())
            return None if timeout == 0 else self._wait(timeout)
        while queue:
            msg = self.as_message(queue.popleft())
            if self._matches_filters(msg):
                return msg
        return None if timeout == 0 else self._wait(timeout)

    def drain(self) -> list[Received]:
        """Every frame waiting on this instant handle that passes the filters, in bus order, as
        queued: a ``DataFrame`` tuple for what ``send_data`` sent (no ``Message`` built), a
        ``Message`` otherwise. ``recv(0)`` until None, without the per-frame objects; the
        lockstep rig's receivers read their tick's frames this way. A bit-timed handle's frames
        come through ``recv`` (as ``Message``s), which runs its wire first."""
        if not self._open:
            raise CanOperationError("Cannot operate on a closed bus")
        if self.timing is not None:
            return list(iter(lambda: self.recv(0), None))
        queue = self._queue
        if not queue:
            return []
        items: list[Received] = []
        take, popleft = items.append, queue.popleft
        while queue:  # popleft, not list(queue): a sender in another thread may append meanwhile
            take(popleft())
        if self._filters is None:
            return items
        accepts, matches = self._accepts_data, self._matches_filters  # set_filters may be newer
        return [f for f in items if (accepts(f[1]) if isinstance(f, tuple) else matches(f))]

    def _accepts_data(self, can_id: int) -> bool:
        """python-can's filters on a classic 11-bit data frame of ``can_id`` (cached per id:
        ``_matches_filters`` only reads the identifier and ``is_extended_id``)."""
        accepts = self._data_accepts.get(can_id)
        if accepts is None:
            accepts = self._data_accepts[can_id] = self._matches_filters(
                data_frame(0.0, can_id, b"")
            )
        return accepts

    def _apply_filters(self, filters: CanFilters | None) -> None:
        """New filters (``BusABC.set_filters``): forget the identifiers they were checked for."""
        self._data_accepts = {}
        self._wire.forget_routes()

    def as_message(self, item: Received) -> Message:
        """A queued frame as a ``Message``: a ``DataFrame``'s built fresh, as ``send`` of
        ``data_frame`` delivers it (``is_rx`` True, the channel's name)."""
        if not isinstance(item, tuple):
            return item
        out = data_frame(*item)
        out.channel = self._wire.name
        return out

    def _wait(self, timeout: float | None) -> Message | None:
        """Block until a frame that passes the filters arrives or ``timeout`` runs out (bit-timed:
        looking at the wire again every ``_POLL_S``). Never holds ``_ready`` while running the
        wire, which takes the wire's lock and then a receiver's ``_ready``."""
        deadline = None if timeout is None else time.monotonic() + timeout
        queue = self._queue
        while self._open:
            if self.timing is not None:
                self.timing.run_until(self.clock())
            while queue:
                msg = self.as_message(queue.popleft())
                if self._matches_filters(msg):
                    return msg
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                return None
            if self.timing is not None:
                remaining = _POLL_S if remaining is None else min(remaining, _POLL_S)
            with self._ready:
                self._waiting = True
                try:
                    if not queue:
                        self._ready.wait(remaining)
                finally:
                    self._waiting = False
        return None

    def _recv_internal(self, timeout: float | None) -> tuple[Message | None, bool]:
        """Unused by ``recv`` (overridden); kept for code that calls the BusABC hook."""
        return self.recv(timeout), True

    # --- lifecycle --------------------------------------------------------------------------

    def flush_tx_buffer(self) -> None:
        """Bit-timed: drop this handle's frames still waiting for the bus (not the one on it)."""
        if self.timing is not None:
            self.timing.drop_pending_of(self)

    def shutdown(self) -> None:
        """Leave the wire (idempotent; bit-timed, its waiting frames go with it); a receiver
        blocked in ``recv`` returns None."""
        super().shutdown()
        if not self._open:
            return
        self._open = False
        self.flush_tx_buffer()
        with _wires_lock:
            wire = self._wire
            wire.set_handles(tuple(h for h in wire.handles if h is not self))
            if not wire.handles and _wires.get(wire.name) is wire:
                del _wires[wire.name]
        with self._ready:
            self._ready.notify_all()

    @staticmethod
    def _detect_available_configs() -> list[AutoDetectedConfig]:
        """The channels in use in this process."""
        with _wires_lock:
            names = list(_wires)
        return [{"interface": INTERFACE, "channel": name} for name in names]


def register() -> None:
    """Make ``can.Bus(interface="odocan")`` work in this process without the entry point (a
    checkout not reinstalled since the plugin was added); a no-op when python-can knows it."""
    from can import interfaces, util

    if INTERFACE in interfaces.BACKENDS:
        return
    interfaces.BACKENDS[INTERFACE] = (__name__, OdocanBus.__name__)
    valid = frozenset((*interfaces.VALID_INTERFACES, INTERFACE))
    interfaces.VALID_INTERFACES = valid
    util.VALID_INTERFACES = valid  # type: ignore[attr-defined]
    can.VALID_INTERFACES = valid
