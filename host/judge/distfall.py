"""A firmware reboot told by its ODOM_TWIST DISTANCE going back (issue #11).

``bootticks`` tells a power-up tick from the E2E COUNTERs. A reset whose first pose pair the bus
lost, 32 k ticks into the firmware's first second, leaves only one COUNTER broken: the old
firmware's last pose had COUNTER 15, the new one's COUNTER 1 comes 40 ms later, what one life
sends (``restarts_small`` cannot tell it), and only the boot summary breaks the ODOM_STATUS
sequence. The correct firmware then FAILed by 93 mm (tick 32), 0.25 m (64), 0.41 m (96) in
every judge against the old life's reference.

What else the reset leaves is the twist's DISTANCE (the DBC: "the low 16 bits of the path length
of the wheel-axis midpoint (sum of |ds|)", firmware/odometry.py ``distance_q40_m``): one life
only adds to it (a set-pose or a new configuration keeps it), a power-up starts it at 0. So a
twist whose DISTANCE is below the one heard before it is a new life's, unless the old one
drove a whole wrap less the fall (more than half of 65.536 m) between the two: the two are
taken less than ``FALL_GAP_S`` apart (32 m/s and more: no robot). Rounding to the mm is
monotone too, and frames of one ID are never reordered on a CAN bus. Tied to the power-up the
way ``restarts_small`` is: the twist that fell has a small COUNTER (below ``BOOT_POSE_FRAMES``,
the new firmware's first 80 ms), its CRC holding, whatever its sequence, less than 80 ms from
the boot summary either side (``bootticks.fell_around``: the twist of its tick comes before it;
that one lost, the next ones, COUNTER 1..3, after; or, the first 4 or 5 lost too, heard by the
next summary with no more twists counted than the time since the boot summary allows:
``bootticks.tied_to_boot``). ``bootticks.boot_ahead`` takes it as the second evidence beside
the summary's broken sequence; the next summary still has to continue the boot summary's
(``continues_summary``), and live the fall is read then (all those twists heard by a cycle on).

Where no fall shows (a robot that had not moved: the new pose is then no farther from the old
reference than the old life drove since its last twist heard, a tick or two; standing since
power-up, none, tests/test_first_second_lost_powerup.py) NAV_STATUS's COUNTER restarting
may still tell it (``navrestart``). The new firmware's first 6 to 10 twists lost too (its
first twist heard after the next summary) are read by the summary after (``latefall``); later,
or once the new life drove farther than the old one had, no fall shows: NAV_STATUS's COUNTER
restarting is then the second evidence (``navrestart``, joined with the falls).

A twist the bus held back behind later twists of its sender (``--faults delay``: it fills a
hole of the COUNTER sequence, ``host.judge.livelatestatus``'s rule) was sent before them: its
DISTANCE below theirs is no fall, and it is left out of the comparisons (every judge: the whole
log, the stream's chunks, the live ``RecentTwists``). Issue #11: pmir and kobuki random seed
10, ``delay=0.5:150``: the log's own power-up twist (DISTANCE 0), held back to 0.151 s behind
the twist of COUNTER 4 (DISTANCE 2), was taken for a fall; with the power-up pose and summary
held back with it (each rightly no evidence) a reboot was told at 0.151 s, the reference
restarted from (0, 0, 0) there and the correct firmware FAILed by 10.8 mm and 28.3 mrad (pmir),
65.6 mm (kobuki) in every judge.

Kept cheap live: a judge keeps the latest twists heard in order (bus time, bytes:
``RECENT_TWISTS``) and reads them only when a summary's first pose needs the fall
(``fell_within``).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.livelatestatus import StatusOrder
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, crc8h2f_p02_one, e2e_messages

TWIST_MESSAGE = "ODOM_TWIST"  # the firmware's twist: its DISTANCE, the path since power-up
DISTANCE_SIGNAL = "DISTANCE"
FALL_GAP_S = 1.0  # two twists this close: a fall is no wrap (half of 65.536 m in 1 s)
RECENT_TWISTS = 16  # kept live: the twists of the last 320 ms (one every 20 ms), read at the
# summary after the boot summary (100 ms on) for those tied to it (``bootticks.tied_to_boot``)


class Falls(NamedTuple):
    """The twists whose DISTANCE fell (``falls``): their bus times (in order), E2E COUNTERs and
    the bus times of the twists heard before them (``tied_late`` asks that one before the boot
    summary)."""

    times_s: npt.NDArray[np.float64]
    counters: npt.NDArray[np.int64]
    befores_s: npt.NDArray[np.float64]


def no_falls() -> Falls:
    """No twist fell (nothing read yet)."""
    return Falls(np.zeros(0, np.float64), np.zeros(0, np.int64), np.zeros(0, np.float64))


def any_tied(falls: Falls, from_s: float, to_s: float,
             tied: Callable[[float, int, float], bool]) -> bool:
    """Whether a fall heard from ``from_s`` to ``to_s`` (both included) ties to a boot summary:
    ``tied`` of its bus time, COUNTER and the bus time of the twist before it (the windows and
    ties of ``bootticks.fell_around``, ``fell_in_run``, ``latefall.fell_late``)."""
    times_s = falls.times_s
    first = int(np.searchsorted(times_s, from_s))
    last = int(np.searchsorted(times_s, to_s, side="right"))
    return any(tied(float(times_s[k]), int(falls.counters[k]), float(falls.befores_s[k]))
               for k in range(first, last))


def joined(first: Falls, then: Falls) -> Falls:
    """The falls of two stretches of a log in order (a stream's chunks)."""
    return Falls(*(np.concatenate((a, b)) for a, b in zip(first, then, strict=True)))


@dataclass(frozen=True)
class DistanceField:
    """Where ODOM_TWIST carries DISTANCE: its first byte and byte count (little-endian,
    unsigned, byte-aligned), the message's E2E DataIDs (None: unprotected)."""

    byte: int
    width: int
    data_ids: tuple[int, ...] | None

    @property
    def lap(self) -> int:
        """The raw value's wrap (65 536 for 16 bits)."""
        return 1 << (8 * self.width)

    def raw(self, data: bytes) -> int:
        """The raw DISTANCE of a frame's bytes."""
        return int.from_bytes(data[self.byte:self.byte + self.width], "little")

    def counter(self, data: bytes) -> int | None:
        """The frame's E2E COUNTER when its CRC holds (any sequence); None otherwise."""
        if len(data) < max(2, self.byte + self.width):
            return None
        ids = self.data_ids
        if ids and data[0] != crc8h2f_p02_one(data, ids[data[1] & ENC_COUNTER_MASK]):
            return None
        return data[1] & ENC_COUNTER_MASK


def distance_field(message: Any, e2e: Any = None) -> DistanceField | None:
    """``message``'s (a cantools ODOM_TWIST) DISTANCE field; ``e2e``: its ``E2EMessage``
    (None: unprotected). None when the DBC lays it out otherwise (no evidence read)."""
    try:
        signal = message.get_signal_by_name(DISTANCE_SIGNAL)
    except KeyError:
        return None
    if (signal.byte_order != "little_endian" or signal.is_signed or signal.start % 8
            or signal.length % 8 or signal.start + signal.length > 8 * message.length):
        return None
    ids = None if e2e is None else e2e.data_ids
    return DistanceField(signal.start // 8, signal.length // 8, ids)


def falls(before_raw: int, before_s: float, raw: int, t_s: float, counter: int,
          lap: int, small: int) -> bool:
    """Whether a twist (DISTANCE ``raw``, bus time ``t_s``, E2E ``counter``) heard after one of
    DISTANCE ``before_raw`` at ``before_s`` is a new firmware's (module docstring): below it by
    less than half a wrap, less than ``FALL_GAP_S`` after it, its COUNTER below ``small``."""
    fall = (before_raw - raw) % lap
    return bool(0 < fall < lap // 2 and 0.0 <= t_s - before_s < FALL_GAP_S and counter < small)


def fell_within(field: DistanceField | None, heard: Iterable[tuple[float, bytes]],
                tied: Callable[[float, int, float], bool], small: int) -> bool:
    """Whether a twist of ``heard`` (bus time, bytes; in order) that ``tied`` takes (its bus
    time, E2E COUNTER and the bus time of the twist before it: ``bootticks.tied_to_boot``, to a
    summary) fell below the twist heard before it (``falls``; their CRC holding)."""
    if field is None:
        return False
    before: tuple[float, int] | None = None
    for t_s, data in heard:
        counter = field.counter(data)
        if counter is None:
            continue
        raw = field.raw(data)
        if (before is not None and tied(t_s, counter, before[0])
                and falls(before[1], before[0], raw, t_s, counter, field.lap, small)):
            return True
        before = (t_s, raw)
    return False


class RecentTwists(deque[tuple[float, bytes]]):
    """The latest ``RECENT_TWISTS`` twists heard in order (bus time, bytes), live: one the bus
    held back (``order``: its COUNTER fills a hole, module docstring) is left out."""

    def __init__(self) -> None:
        super().__init__(maxlen=RECENT_TWISTS)
        self.order = StatusOrder()

    def hear(self, field: DistanceField | None, t_s: float, data: bytes) -> None:
        """A twist heard at bus time ``t_s``: kept unless its CRC holds and it was held back."""
        counter = None if field is None else field.counter(data)
        if counter is None or not self.order.hear(counter):
            self.append((t_s, data))


TwistCarried = tuple[float, int, StatusOrder]  # the latest twist kept: bus time, raw, the order


def in_order(counters: npt.NDArray[np.int64], order: StatusOrder) -> npt.NDArray[np.bool_]:
    """Which twists of E2E ``counters`` (bus order, CRC holding) ``order`` hears in order (not
    held back: module docstring)."""
    return ~np.array([order.hear(c) for c in counters.tolist()], dtype=bool)


def fall_times(frames: FrameArrays, decoder: BulkDecoder, small: int,
               carried: TwistCarried | None = None
               ) -> tuple[Falls, TwistCarried | None]:
    """The twists in ``frames`` whose DISTANCE fell (``falls``; their CRC holding, any
    sequence, the ones held back left out), and the latest twist's (bus time, raw DISTANCE)
    with the sequence's order for the next chunk (``carried``: the one before ``frames``)."""
    none = no_falls()
    try:
        message = decoder.message(TWIST_MESSAGE)
        rows = np.asarray(decoder.select(frames, TWIST_MESSAGE), dtype=np.int64)
    except (DecodeError, KeyError):
        return none, carried
    field = distance_field(message, e2e_messages(decoder.db).get(message.frame_id))
    if field is None or len(rows) == 0:
        return none, carried
    data = frames.data[rows]
    counter = (data[:, 1] & ENC_COUNTER_MASK).astype(np.int64)
    good = np.ones(len(rows), dtype=bool)
    if field.data_ids:
        ids = np.array(field.data_ids, dtype=np.uint8)[counter]
        good = crc8h2f_p02(data, ids) == data[:, 0]
    raw = np.zeros(len(rows), np.int64)
    for k in range(field.width):
        raw |= data[:, field.byte + k].astype(np.int64) << (8 * k)
    t_s = frames.timestamp_s[rows].astype(np.float64)[good]
    raw, counter = raw[good], counter[good]
    order = StatusOrder() if carried is None else carried[2].copy()
    kept = in_order(counter, order)
    t_s, raw, counter = t_s[kept], raw[kept], counter[kept]
    if carried is not None:
        t_s, raw = np.concatenate(([carried[0]], t_s)), np.concatenate(([carried[1]], raw))
        counter = np.concatenate(([0], counter))
    if len(t_s) == 0:
        return none, carried
    fall = (raw[:-1] - raw[1:]) % field.lap
    gap = t_s[1:] - t_s[:-1]
    fell = ((fall > 0) & (fall < field.lap // 2) & (gap >= 0.0) & (gap < FALL_GAP_S)
            & (counter[1:] < small))
    return (Falls(t_s[1:][fell], counter[1:][fell], t_s[:-1][fell]),
            (float(t_s[-1]), int(raw[-1]), order))


def any_within(times_s: npt.NDArray[np.float64], from_s: float, to_s: float) -> bool:
    """Whether a bus time of ``times_s`` (in order) lies in [``from_s``, ``to_s``]."""
    k = int(np.searchsorted(times_s, from_s))
    return bool(k < len(times_s) and times_s[k] <= to_s)
