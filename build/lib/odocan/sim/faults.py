"""Fault injection on the CAN bus: a python-can ``BusABC`` that wraps any other bus.

``FaultInjectingBus(bus, FaultSpec.parse("drop=0.01,dup=0.005,flip=0.001,seed=7"))`` behaves as
``bus`` except on the **send path**: what a sender puts on the bus is what every receiver gets,
alike (a dropped frame is lost to all, a corrupted one reaches all corrupted). Receiving passes
through unchanged. Time is the wrapped clock: each message's own ``timestamp`` (lockstep
simulated time), or ``clock()`` when one is given (real time).

The fault model (``--faults`` text; every key optional, comma-separated)::

    drop=P          each frame is lost with probability P
    burst=P:LEN     with probability P a burst starts: this frame and the next LEN - 1 are lost
    dup=P           the frame goes on the bus twice (a retransmission of the same bits)
    delay=P:MS      the frame is held back and released MS ms later (by the wrapped clock), so
                    frames sent meanwhile overtake it: reordering
    flip=P[:BITS]   BITS distinct random bits of the payload are inverted (never the ID); BITS
                    defaults to 1 (a single-bit error, which every CRC detects)
    babble=RATE     a babbling node: random frames (11/29-bit IDs, DLC 0-8, random payloads, 10%
                    error frames, 10% remote frames) at RATE frames per second of the sender's
                    time, as a Poisson process
    busoff=T:DUR    at T s the transmitter's error counter climbs past 255 (32 failed attempts,
                    +8 each, through the warning and error-passive limits): bus-off for DUR s,
                    then recovery after 128 occurrences of 11 recessive bits (at ``bitrate``)
    seed=N          the seed of every random draw (the same seed gives the same faults)

P in [0, 1]; LEN >= 1; MS >= 0; 1 <= BITS <= 64; RATE >= 0 frames/s; T, DUR >= 0 s. A frame
suffers at most one of drop, burst, dup, delay, flip: one uniform draw per frame is split into
intervals of those widths (so each has exactly its probability; their sum must be <= 1), and a
burst once started takes the next frames whatever their draw. Babble and bus-off are independent
of the frame faults. While the bus is off, ``send`` raises ``can.CanOperationError`` (the frame
is refused, counted ``refused``) and held-back frames wait for the recovery; the babbling node is
another node and goes on babbling. ``state`` is python-can's ``BusState``: ``ACTIVE`` (error
active, TEC and REC < 128; ``error_warning`` from 96), ``PASSIVE`` (error passive), ``ERROR``
(bus-off).

Every injected fault is logged at INFO on logger ``odocan.faults`` (one line each) and counted in
``injected`` (per kind) and ``injected_by_id`` (per kind and CAN ID).
"""

from __future__ import annotations

import contextlib
import heapq
import logging
import math
import random
import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can
from can import BusABC, BusState

from odocan.sim.exceptions import ConfigurationError

LOG = logging.getLogger("odocan.faults")

FAULT_KINDS = ("drop", "burst", "dup", "delay", "flip", "babble", "busoff", "refused")
_EXCLUSIVE = ("drop", "burst", "dup", "delay", "flip")  # at most one of these per frame
_KEYS = ("drop", "burst", "dup", "delay", "flip", "babble", "busoff", "seed")
_BABBLE_ERROR_FRAMES = 0.1  # share of the babble that is error frames
_BABBLE_REMOTE_FRAMES = 0.1  # ... and remote frames (the rest: data frames)
DEFAULT_BITRATE = 500_000  # bit/s: the recovery time of bus-off (128 x 11 recessive bits)


def _fail(key: str, value: str, why: str) -> ConfigurationError:
    return ConfigurationError(f"faults: {key}={value}: {why}")


@dataclass(frozen=True)
class BusOff:
    """One bus-off episode: it starts at ``at_s`` (the sender's time) and lasts ``duration_s``."""

    at_s: float
    duration_s: float


@dataclass(frozen=True)
class FaultSpec:
    """What to inject (see the module docstring); validated at construction."""

    drop: float = 0.0
    burst: float = 0.0
    burst_len: int = 1
    dup: float = 0.0
    delay: float = 0.0
    delay_ms: float = 0.0
    flip: float = 0.0
    flip_bits: int = 1
    babble: float = 0.0  # frames/s
    busoff: BusOff | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        for name in _EXCLUSIVE:
            _check_probability(name, getattr(self, name))
        total = sum(getattr(self, name) for name in _EXCLUSIVE)
        if total > 1.0:
            raise ConfigurationError(
                f"faults: drop + burst + dup + delay + flip = {total:g} > 1 "
                "(a frame suffers at most one of them)"
            )
        _check_int("burst", self.burst_len, 1, None, "LEN")
        _check_float("delay", self.delay_ms, "MS")
        _check_int("flip", self.flip_bits, 1, 64, "BITS")
        _check_float("babble", self.babble, "RATE")
        if self.busoff is not None:
            _check_float("busoff", self.busoff.at_s, "T")
            _check_float("busoff", self.busoff.duration_s, "DUR")
        _check_int("seed", self.seed, None, None, "N")

    @classmethod
    def parse(cls, text: str) -> FaultSpec:
        """A spec from ``--faults`` text such as ``drop=0.01,burst=0.001:5,seed=3`` ("" = none)."""
        values: dict[str, Any] = {}
        seen: set[str] = set()
        for item in (part.strip() for part in text.split(",")):
            if not item:
                continue
            key, sep, value = (s.strip() for s in item.partition("="))
            if not sep:
                raise ConfigurationError(f"faults: {item!r}: expected KEY=VALUE")
            if key not in _KEYS:
                raise ConfigurationError(f"faults: unknown key {key!r} (known: {', '.join(_KEYS)})")
            if key in seen:
                raise ConfigurationError(f"faults: {key} given twice")
            seen.add(key)
            values.update(_parse_value(key, value))
        return cls(**values)

    @property
    def active(self) -> bool:
        """True when anything at all is injected."""
        return self != FaultSpec(seed=self.seed)

    def __str__(self) -> str:
        """The canonical ``--faults`` text (``parse(str(spec)) == spec``)."""
        items = [
            f"{name}={_num(getattr(self, name))}" for name in ("drop", "dup") if getattr(self, name)
        ]
        if self.burst:
            items.append(f"burst={_num(self.burst)}:{self.burst_len}")
        if self.delay:
            items.append(f"delay={_num(self.delay)}:{_num(self.delay_ms)}")
        if self.flip:
            items.append(f"flip={_num(self.flip)}:{self.flip_bits}")
        if self.babble:
            items.append(f"babble={_num(self.babble)}")
        if self.busoff is not None:
            items.append(f"busoff={_num(self.busoff.at_s)}:{_num(self.busoff.duration_s)}")
        items.append(f"seed={self.seed}")
        return ",".join(items)


def _num(value: float) -> str:
    """A number as short as it reads back exactly: 0.01, 100, 2.5."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def _check_probability(key: str, p: object) -> None:
    if isinstance(p, bool) or not isinstance(p, int | float) or not 0.0 <= p <= 1.0:
        raise _fail(key, repr(p), "P must be a probability in [0, 1]")


def _check_float(key: str, value: object, what: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise _fail(key, repr(value), f"{what} must be a finite number >= 0")
    if value < 0:
        raise _fail(key, repr(value), f"{what} must be a finite number >= 0")


def _check_int(key: str, value: object, lo: int | None, hi: int | None, what: str) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or (lo is not None and value < lo)
        or (hi is not None and value > hi)
    ):
        bounds = f" in [{lo}, {hi}]" if hi is not None else (f" >= {lo}" if lo is not None else "")
        raise _fail(key, repr(value), f"{what} must be an integer{bounds}")


def _number(key: str, text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _fail(key, text, f"{what} is not a number") from None
    if not math.isfinite(value):
        raise _fail(key, text, f"{what} must be finite")
    return value


def _integer(key: str, text: str, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise _fail(key, text, f"{what} is not an integer") from None


def _fields(key: str, value: str, shape: str, optional_second: bool = False) -> list[str]:
    parts = value.split(":")
    if len(parts) == 2 or (optional_second and len(parts) == 1):
        return parts
    raise _fail(key, value, f"expected {key}={shape}")


def _parse_value(key: str, value: str) -> dict[str, Any]:
    """The FaultSpec fields of one ``key=value`` item."""
    if key in ("drop", "dup"):
        return {key: _number(key, value, "P")}
    if key == "babble":
        return {key: _number(key, value, "RATE")}
    if key == "seed":
        return {key: _integer(key, value, "N")}
    if key == "burst":
        p, n = _fields(key, value, "P:LEN")
        return {"burst": _number(key, p, "P"), "burst_len": _integer(key, n, "LEN")}
    if key == "delay":
        p, ms = _fields(key, value, "P:MS")
        return {"delay": _number(key, p, "P"), "delay_ms": _number(key, ms, "MS")}
    if key == "flip":
        parts = _fields(key, value, "P[:BITS]", optional_second=True)
        bits = _integer(key, parts[1], "BITS") if len(parts) == 2 else 1
        return {"flip": _number(key, parts[0], "P"), "flip_bits": bits}
    at, duration = _fields(key, value, "T:DURATION")
    return {"busoff": BusOff(_number(key, at, "T"), _number(key, duration, "DURATION"))}


class ErrorCounters:
    """ISO 11898-1 fault confinement of one CAN controller: TEC, REC and the error states.

    A transmit error adds 8 to TEC, a successful transmission takes 1 off; a receive error adds 1
    to REC, a successful reception takes 1 off (from above 127 it drops to 127). Error warning from
    96, error passive from 128, bus-off when TEC exceeds 255; bus-off is left only by ``recover``
    (after 128 occurrences of 11 recessive bits), which clears both counters.
    """

    WARNING_LIMIT = 96
    PASSIVE_LIMIT = 128
    BUS_OFF_LIMIT = 255
    RECOVERY_BITS = 128 * 11

    def __init__(self) -> None:
        self.tec = 0
        self.rec = 0
        self.bus_off = False

    def transmit_error(self) -> None:
        """A transmitter saw an error: TEC += 8 (bus-off beyond 255)."""
        if not self.bus_off:
            self.tec += 8
            self.bus_off = self.tec > self.BUS_OFF_LIMIT

    def transmit_success(self) -> None:
        """A frame went out: TEC -= 1."""
        if not self.bus_off and self.tec:
            self.tec -= 1

    def receive_error(self) -> None:
        """A receiver saw an error: REC += 1 (held at 255)."""
        if not self.bus_off:
            self.rec = min(self.rec + 1, 255)

    def receive_success(self) -> None:
        """A frame came in: REC -= 1, or back to 127 from error-passive levels."""
        if self.rec > 127:
            self.rec = 127
        elif self.rec:
            self.rec -= 1

    def recover(self) -> None:
        """128 x 11 recessive bits seen while bus-off: error active, TEC = REC = 0."""
        self.tec = self.rec = 0
        self.bus_off = False

    @property
    def error_warning(self) -> bool:
        """TEC or REC at the warning limit (96) or above."""
        return self.tec >= self.WARNING_LIMIT or self.rec >= self.WARNING_LIMIT

    @property
    def bus_state(self) -> BusState:
        """ACTIVE (error active), PASSIVE (error passive) or ERROR (bus-off)."""
        if self.bus_off:
            return BusState.ERROR
        if self.tec >= self.PASSIVE_LIMIT or self.rec >= self.PASSIVE_LIMIT:
            return BusState.PASSIVE
        return BusState.ACTIVE


class FaultInjectingBus(BusABC):
    """Any python-can bus with the faults of a ``FaultSpec`` on its send path.

    Args:
        bus: the wrapped bus (shut down with this one).
        spec: the faults.
        clock: the time of a send (s); default: the message's own ``timestamp``.
        bitrate: bit/s, for the bus-off recovery time (128 x 11 bits).
        can_filters: software filters applied on top of the wrapped bus's own.
    """

    def __init__(
        self,
        bus: BusABC,
        spec: FaultSpec,
        *,
        clock: Callable[[], float] | None = None,
        bitrate: int = DEFAULT_BITRATE,
        can_filters: can.typechecking.CanFilters | None = None,
        **kwargs: object,
    ) -> None:
        if bitrate <= 0:
            raise ConfigurationError(f"faults: bitrate must be > 0 bit/s, got {bitrate!r}")
        self._bus = bus
        self.spec = spec
        self._clock = clock
        self._recovery_s = ErrorCounters.RECOVERY_BITS / bitrate
        self._can_protocol = bus.protocol
        self.channel_info = f"faults({spec}) on {bus.channel_info}"
        self.counters = ErrorCounters()
        self.injected: dict[str, int] = dict.fromkeys(FAULT_KINDS, 0)
        self.injected_by_id: Counter[tuple[str, int]] = Counter()
        self.offered = 0  # frames the sender asked to send
        self._rng_frames = random.Random(f"{spec.seed}/frames")
        self._rng_flip = random.Random(f"{spec.seed}/flip")
        self._rng_babble = random.Random(f"{spec.seed}/babble")
        self._edges = _edges(spec)
        self._burst_left = 0
        self._held: list[tuple[float, int, can.Message]] = []  # (release time, seq, frame)
        self._held_seq = 0
        self._babble_next_s: float | None = None
        self._busoff_started = False
        self._recover_at_s = math.inf
        self._lock = threading.RLock()
        super().__init__(channel=bus.channel_info, can_filters=can_filters, **kwargs)

    # --- python-can BusABC -------------------------------------------------------------------

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` through the faults (``can.CanOperationError`` while bus-off)."""
        with self._lock:
            now = self._clock() if self._clock is not None else msg.timestamp
            self.poll(now, timeout)
            self.offered += 1
            if self.counters.bus_off:
                self._count("refused", msg.arbitration_id, now, "bus-off: frame not sent")
                raise can.CanOperationError(f"bus-off (TEC {self.counters.tec}): frame not sent")
            self._send_faulted(msg, now, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self._bus.recv(timeout), False

    @property
    def state(self) -> BusState:
        """The modelled controller's state (bus-off, error passive), else the wrapped bus's."""
        modelled = self.counters.bus_state
        return self._bus.state if modelled is BusState.ACTIVE else modelled

    @state.setter
    def state(self, new_state: BusState) -> None:
        self._bus.state = new_state

    def flush_tx_buffer(self) -> None:
        """Discard the held-back (delayed) frames, and the wrapped bus's TX buffer if it has one."""
        with self._lock:
            self._held.clear()
        with contextlib.suppress(NotImplementedError):
            self._bus.flush_tx_buffer()

    def fileno(self) -> int:
        return self._bus.fileno()

    def shutdown(self) -> None:
        """Discard the held-back frames and shut the wrapped bus down (safe to call twice)."""
        already = self._is_shutdown
        super().shutdown()
        if already:
            return
        if self._held:
            LOG.debug("shutdown: %d held-back frame(s) discarded", len(self._held))
            self._held.clear()
        self._bus.shutdown()

    # --- the wrapped clock -------------------------------------------------------------------

    @property
    def tec(self) -> int:
        """The modelled transmit error counter."""
        return self.counters.tec

    @property
    def rec(self) -> int:
        """The modelled receive error counter (receiving is not faulted: it stays 0)."""
        return self.counters.rec

    @property
    def error_warning(self) -> bool:
        """TEC or REC at 96 or above."""
        return self.counters.error_warning

    @property
    def held(self) -> int:
        """Frames held back by ``delay`` and not yet released."""
        return len(self._held)

    def poll(self, now_s: float, timeout: float | None = None) -> None:
        """Bring the faults up to ``now_s``: bus-off transitions, babble, delayed releases.

        ``send`` calls it; call it yourself to release held frames when the sender is silent.
        """
        with self._lock:
            self._busoff_to(now_s)
            while True:
                babble_s = self._next_babble_s(now_s)
                held_s = self._held[0][0] if self._held and not self.counters.bus_off else math.inf
                if min(babble_s, held_s) > now_s:
                    return
                if babble_s <= held_s:
                    self._babble_once(babble_s, timeout)
                else:
                    self._release_one(timeout)

    # --- frame faults ------------------------------------------------------------------------

    def _send_faulted(self, msg: can.Message, now: float, timeout: float | None) -> None:
        can_id = msg.arbitration_id
        if self._burst_left:
            self._burst_left -= 1
            self._count("burst", can_id, now, f"lost in a burst ({self._burst_left} to go)")
            return
        kind = self._draw()
        if kind == "drop":
            self._count("drop", can_id, now, "lost")
        elif kind == "burst":
            self._burst_left = self.spec.burst_len - 1
            self._count("burst", can_id, now, f"burst of {self.spec.burst_len} starts: lost")
        elif kind == "delay":
            self._hold(msg, now)
        elif kind == "flip" and msg.dlc and not (msg.is_remote_frame or msg.is_error_frame):
            self._transmit(self._flipped(msg, now), timeout)
        else:
            self._transmit(msg, timeout)
            if kind == "dup":
                self._count("dup", can_id, now, "sent twice")
                self._transmit(msg, timeout)

    def _draw(self) -> str | None:
        """One uniform draw split into the exclusive faults' intervals."""
        u = self._rng_frames.random()
        for edge, kind in self._edges:
            if u < edge:
                return kind
        return None

    def _transmit(self, msg: can.Message, timeout: float | None) -> None:
        self._bus.send(msg, timeout)
        self.counters.transmit_success()

    def _flipped(self, msg: can.Message, now: float) -> can.Message:
        """A copy of ``msg`` with ``flip_bits`` distinct payload bits inverted."""
        data = bytearray(msg.data)
        nbits = len(data) * 8
        if nbits == 0:
            return msg
        bits = self._rng_flip.sample(range(nbits), min(self.spec.flip_bits, nbits))
        for bit in bits:
            data[bit >> 3] ^= 1 << (bit & 7)
        self._count("flip", msg.arbitration_id, now, f"bits {sorted(bits)} inverted")
        return _clone(msg, data)

    def _hold(self, msg: can.Message, now: float) -> None:
        release_s = now + self.spec.delay_ms / 1000.0
        self._held_seq += 1
        heapq.heappush(self._held, (release_s, self._held_seq, _clone(msg, bytearray(msg.data))))
        self._count("delay", msg.arbitration_id, now, f"held until t={release_s:.6f}")

    def _release_one(self, timeout: float | None) -> None:
        release_s, _, msg = heapq.heappop(self._held)
        msg.timestamp = release_s
        try:
            self._transmit(msg, timeout)
        except can.CanError as exc:
            LOG.debug("held frame 0x%X lost on release: %s", msg.arbitration_id, exc)

    def _count(self, kind: str, can_id: int, now: float, detail: str) -> None:
        self.injected[kind] += 1
        self.injected_by_id[kind, can_id] += 1
        LOG.info("%s id=0x%X t=%.6f: %s", kind, can_id, now, detail)

    # --- the babbling node -------------------------------------------------------------------

    def _next_babble_s(self, now_s: float) -> float:
        if self.spec.babble <= 0.0:
            return math.inf
        if self._babble_next_s is None:  # the babbler wakes up with the first frame seen
            self._babble_next_s = now_s + self._rng_babble.expovariate(self.spec.babble)
        return self._babble_next_s

    def _babble_once(self, t_s: float, timeout: float | None) -> None:
        msg = _random_frame(self._rng_babble, t_s)
        self._babble_next_s = t_s + self._rng_babble.expovariate(self.spec.babble)
        kind = "error" if msg.is_error_frame else "remote" if msg.is_remote_frame else "data"
        self._count("babble", msg.arbitration_id, t_s, f"{kind} frame, dlc {msg.dlc}")
        try:
            self._bus.send(msg, timeout)
        except can.CanError as exc:
            LOG.debug("babble frame lost: %s", exc)

    # --- bus-off -----------------------------------------------------------------------------

    def _busoff_to(self, now_s: float) -> None:
        episode = self.spec.busoff
        if episode is None:
            return
        if not self._busoff_started and now_s >= episode.at_s:
            self._busoff_started = True
            self._climb_to_busoff(episode.at_s)
            self._recover_at_s = episode.at_s + episode.duration_s + self._recovery_s
        if self.counters.bus_off and now_s >= self._recover_at_s:
            self.counters.recover()
            LOG.info("busoff recovered t=%.6f: 128 x 11 recessive bits, TEC = REC = 0", now_s)

    def _climb_to_busoff(self, at_s: float) -> None:
        """The controller's automatic retransmissions all fail: TEC +8 each, to beyond 255."""
        c = self.counters
        while not c.bus_off:
            was_warning, was_state = c.error_warning, c.bus_state
            c.transmit_error()
            if c.error_warning and not was_warning:
                LOG.info("busoff climb t=%.6f: TEC %d, error warning", at_s, c.tec)
            if c.bus_state is not was_state and not c.bus_off:
                LOG.info("busoff climb t=%.6f: TEC %d, error passive", at_s, c.tec)
        self._count("busoff", 0, at_s, f"TEC {c.tec} > 255: bus-off")


def _clone(msg: can.Message, data: bytearray) -> can.Message:
    """A copy of ``msg`` carrying ``data`` (never the sender's own buffer)."""
    copy = msg.__copy__()
    copy.data = data
    return copy


def _edges(spec: FaultSpec) -> list[tuple[float, str]]:
    """Cumulative interval ends of the exclusive faults (zero-width ones left out)."""
    edges = []
    total = 0.0
    for kind in _EXCLUSIVE:
        p = float(getattr(spec, kind))
        if p:
            total += p
            edges.append((total, kind))
    return edges


def _random_frame(rng: random.Random, t_s: float) -> can.Message:
    """A babbling node's frame: any ID, DLC 0-8, random bytes; some error and remote frames."""
    u = rng.random()
    extended = rng.random() < 0.5
    can_id = rng.getrandbits(29 if extended else 11)
    dlc = rng.randint(0, 8)
    if u < _BABBLE_ERROR_FRAMES:
        return can.Message(
            timestamp=t_s, arbitration_id=can_id, is_error_frame=True, data=rng.randbytes(dlc)
        )
    if u < _BABBLE_ERROR_FRAMES + _BABBLE_REMOTE_FRAMES:
        return can.Message(
            timestamp=t_s,
            arbitration_id=can_id,
            is_extended_id=extended,
            is_remote_frame=True,
            dlc=dlc,
        )
    return can.Message(
        timestamp=t_s, arbitration_id=can_id, is_extended_id=extended, data=rng.randbytes(dlc)
    )


__all__ = [
    "FAULT_KINDS",
    "BusOff",
    "ErrorCounters",
    "FaultInjectingBus",
    "FaultSpec",
]
