"""Bulk decoding of CAN frames with numpy, from cantools' own signal layouts.

cantools decodes one frame at a time (``Database.decode_message``, tens of microseconds each). For
logs of millions of frames ``BulkDecoder`` reads each signal's layout from the cantools database
once (start bit, length, signedness, byte order, multiplexer) and extracts the signal from all
frames of a message at once: the 8 payload bytes as one 64-bit word (little-endian for Intel
signals, big-endian for Motorola ones), a shift, a mask and a sign extension.

The values are cantools' *raw* values (``decode_message(..., scaling=False)``): int64 arrays
(float64 for IEEE float signals; uint64 for an unsigned 64-bit signal, which int64 cannot
hold). Scale them with the signal's ``scale``/``offset`` yourself.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FLAG_ERROR, FLAG_EXTENDED, FLAG_REMOTE, FrameArrays
from odocan.sim.exceptions import OdocanError

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec, MessageSpec, SignalSpec

Int64Array = npt.NDArray[np.int64]


class DecodeError(OdocanError):
    """A message the bulk decoder cannot handle (unknown name, more than 8 bytes)."""


@dataclass(frozen=True)
class SignalLayout:
    """Where one signal sits in an 8-byte frame, as cantools defines it.

    Attributes:
        name: signal name.
        shift: bit position of the least significant bit in the 64-bit word (little-endian word
            for Intel signals, big-endian word for Motorola signals).
        length: bits, 1..64.
        signed: two's complement.
        big_endian: Motorola byte order.
        is_float: IEEE 754 binary32/binary64.
        mux_signal: the multiplexer signal selecting this one (None: always present).
        mux_ids: the multiplexer values that select it.
        is_multiplexer: this signal is a multiplexer.
    """

    name: str
    shift: int
    length: int
    signed: bool
    big_endian: bool
    is_float: bool
    mux_signal: str | None
    mux_ids: tuple[int, ...]
    is_multiplexer: bool = False


def signal_layout(signal: SignalSpec) -> SignalLayout:
    """The layout of a cantools signal (``cantools.database.utils.start_bit`` conventions)."""
    if signal.byte_order == "big_endian":
        msb = 8 * (signal.start // 8) + (7 - signal.start % 8)  # bit 0 = MSB of byte 0
        shift = 64 - msb - signal.length
    else:
        shift = signal.start
    return SignalLayout(
        name=signal.name,
        shift=shift,
        length=signal.length,
        signed=signal.is_signed,
        big_endian=signal.byte_order == "big_endian",
        is_float=signal.is_float,
        mux_signal=signal.multiplexer_signal,
        mux_ids=tuple(signal.multiplexer_ids or ()),
        is_multiplexer=signal.is_multiplexer,
    )


def frame_key(can_id: int, extended: bool) -> int:
    """One integer per (identifier, frame format): bit 31 set for extended frames."""
    return int(can_id) | (1 << 31 if extended else 0)


def frame_keys(frames: FrameArrays) -> npt.NDArray[np.int64]:
    """``frame_key`` of every frame (error and remote frames get -1: they carry no signals)."""
    keys = frames.can_id.astype(np.int64) | ((frames.flags & FLAG_EXTENDED).astype(np.int64) << 31)
    keys[(frames.flags & (FLAG_ERROR | FLAG_REMOTE)) != 0] = -1
    return keys


_STANDARD_IDS = 0x800  # 11-bit identifiers: their keys are the identifiers


def message_numbers(
    frames: FrameArrays, sorted_keys: npt.NDArray[np.int64]
) -> npt.NDArray[np.integer[Any]]:
    """For each frame, the position of its message's key (``frame_key``) in ``sorted_keys`` (a
    database's keys, ascending), or ``len(sorted_keys)`` for a frame of none. When every message
    has a standard identifier: a uint16 table lookup by the low 11 bits of the identifier,
    checked against it (and against the extended, error and remote flags, which no standard key
    has), without the int64 keys; else a search of the keys."""
    count = len(sorted_keys)
    if count and sorted_keys[-1] < _STANDARD_IDS:
        table = np.full(_STANDARD_IDS, count, dtype=np.uint16)
        table[sorted_keys] = np.arange(count)
        number = np.take(table, frames.can_id & (_STANDARD_IDS - 1))
        ids = np.append(sorted_keys, 0).astype(np.uint32)  # [count]: any, that frame has none
        plain = (frames.flags & (FLAG_EXTENDED | FLAG_ERROR | FLAG_REMOTE)) == 0
        number[~(plain & (np.take(ids, number) == frames.can_id))] = count
        return number
    keys = frame_keys(frames)
    padded = np.append(sorted_keys, -2)  # no frame's key: what "no message" compares to
    found = np.searchsorted(sorted_keys, keys)
    found[padded[found] != keys] = count
    result: npt.NDArray[np.intp] = found
    return result


@dataclass(frozen=True)
class FrameGroups:
    """The frames of a log grouped by message: ``of(k)``, the positions (ascending) of the
    frames whose key is ``sorted_keys[k]``; ``of(len(sorted_keys))``, those of no message."""

    sorted_keys: tuple[int, ...]
    numbers: npt.NDArray[np.integer[Any]]  # each frame's message number (``message_numbers``)
    positions: npt.NDArray[np.intp]
    bounds: tuple[int, ...]

    def of(self, number: int) -> npt.NDArray[np.intp]:
        """The positions of message ``number``'s frames (read-only view)."""
        return self.positions[self.bounds[number] : self.bounds[number + 1]]


_last_groups: tuple[weakref.ref[FrameArrays], FrameGroups] | None = None


def frame_groups(frames: FrameArrays, sorted_keys: tuple[int, ...]) -> FrameGroups:
    """``FrameGroups`` of ``frames`` by ``sorted_keys`` (ascending): one table lookup and one
    stable radix sort of message numbers for all messages at once. The last answer is kept for
    the same ``FrameArrays`` (immutable) and keys: the E2E check and each ``BulkDecoder`` of an
    analysis share it."""
    global _last_groups
    last = _last_groups
    if last is not None and last[0]() is frames and last[1].sorted_keys == sorted_keys:
        return last[1]
    number = message_numbers(frames, np.array(sorted_keys, dtype=np.int64))
    small = number.astype(np.uint16, copy=False) if len(sorted_keys) < 0xFFFF else number
    positions = np.argsort(small, kind="stable")  # radix sort: each message in bus order
    positions.flags.writeable = False
    per_message = np.bincount(number, minlength=len(sorted_keys) + 1)
    bounds = (0, *np.cumsum(per_message).tolist())
    number.flags.writeable = False
    groups = FrameGroups(sorted_keys, number, positions, bounds)
    _last_groups = (weakref.ref(frames), groups)
    return groups


class BulkDecoder:
    """Decode every frame of a message at once, from the layouts of a cantools database.

    ``decode(frames, name)`` returns one array per signal over the frames of that message (its
    identifier and frame format, DLC equal to the message's length, neither error nor remote
    frame), plus ``"timestamp_s"`` (float64) and ``"index"`` (int64, the frame's position in
    ``frames``).

    Multiplexed messages: every signal's array has the full length; a signal of one multiplexer
    page is meaningful only where the multiplexer selects it (elsewhere it is what its bits
    hold). ``decode_page`` returns just the frames of one page with just that page's signals,
    exactly what cantools returns for each of them.

    The analysis asks for the same message's frames several times (its frame counts, a page at
    a time, the E2E-accepted frames): ``select`` keeps its answer for the last ``FrameArrays``
    seen (immutable), at most 8 bytes a frame over all messages, and hands it out read-only (a
    caller that changed it in place would change every later answer); ``decode_page`` keeps
    the page (top multiplexer value) of each frame of a multiplexed message (8 bytes a frame
    more). Decoded values are not kept: each call returns arrays of its own, and a page decodes
    only its own frames' signals.
    """

    def __init__(self, db: DatabaseSpec) -> None:
        self.db = db
        self._layouts: dict[str, tuple[SignalLayout, ...]] = {}
        self._messages: dict[str, MessageSpec] = {}
        self._frames: FrameArrays | None = None  # the frames the caches below belong to
        self._groups: FrameGroups | None = None
        self._numbers: dict[int, int] = {}  # frame key -> its message's number in the groups
        self._selected: dict[str, npt.NDArray[np.intp]] = {}
        self._pages: dict[str, np.ndarray] = {}  # top multiplexer value of each selected frame
        for message in db.messages:
            self._messages[message.name] = message
            self._layouts[message.name] = tuple(signal_layout(s) for s in message.signals)
        keys = sorted({frame_key(m.frame_id, m.is_extended_frame) for m in db.messages})
        self._sorted_keys = tuple(keys)
        self._numbers = {key: number for number, key in enumerate(keys)}

    def message(self, name: str) -> MessageSpec:
        """The cantools message ``name`` (``DecodeError`` when the database has none)."""
        try:
            return self._messages[name]
        except KeyError:
            raise DecodeError(f"the DBC has no message {name}") from None

    def select(self, frames: FrameArrays, name: str) -> npt.NDArray[np.intp]:
        """Positions in ``frames`` of the decodable frames of message ``name`` (read-only)."""
        if self._frames is not frames:  # start the caches afresh
            self._frames, self._selected, self._pages = frames, {}, {}
            self._groups = frame_groups(frames, self._sorted_keys)
        index = self._selected.get(name)
        if index is None:
            message = self.message(name)
            if message.length > 8:
                raise DecodeError(f"{name}: {message.length}-byte message (classic CAN only)")
            assert self._groups is not None
            of_id = self._groups.of(
                self._numbers[frame_key(message.frame_id, message.is_extended_frame)])
            index = of_id[frames.dlc[of_id] == message.length]
            index.flags.writeable = False
            self._selected[name] = index
        return index

    def decode(self, frames: FrameArrays, message_name: str) -> dict[str, np.ndarray]:
        """Raw values of every signal of ``message_name`` over its frames (see the class doc)."""
        index = self.select(frames, message_name)
        return self._decode(frames, index, self._layouts[message_name])

    def decode_page(
        self, frames: FrameArrays, message_name: str, mux_value: int
    ) -> dict[str, np.ndarray]:
        """The frames of one multiplexer page (value of the top-level multiplexer) with the
        signals cantools decodes for it."""
        layouts = self._layouts[message_name]
        muxes = [lay for lay in layouts if lay.is_multiplexer and lay.mux_signal is None]
        if not muxes:
            raise DecodeError(f"{message_name} is not multiplexed")
        index = self.select(frames, message_name)
        top = muxes[0]
        pages = self._pages.get(message_name)
        if pages is None:  # kept for the message's other pages
            pages = extract(_words(frames.data[index], top.big_endian), top)
            self._pages[message_name] = pages
        kept = np.flatnonzero(pages == mux_value)
        wanted = layouts if len(kept) == 0 else tuple(  # an empty page: every signal, as ever
            lay for lay in layouts if lay.mux_signal != top.name or mux_value in lay.mux_ids
        )
        decoded = self._decode(frames, index[kept], wanted)
        page = {
            lay.name: decoded[lay.name]
            for lay in wanted if _selected(lay, top.name, mux_value, decoded)
        }
        page["timestamp_s"] = decoded["timestamp_s"]
        page["index"] = decoded["index"]
        return page

    @staticmethod
    def _decode(
        frames: FrameArrays, index: npt.NDArray[np.intp], layouts: tuple[SignalLayout, ...],
        data: npt.NDArray[np.uint8] | None = None,
    ) -> dict[str, np.ndarray]:
        """The signals of ``layouts`` over the frames ``index`` (``data``: their payloads, when
        already gathered); each byte order's 64-bit words built only if a signal uses it."""
        payloads = frames.data[index] if data is None else data
        words = {big: _words(payloads, big) for big in {lay.big_endian for lay in layouts}}
        result: dict[str, np.ndarray] = {
            "timestamp_s": frames.timestamp_s[index],
            "index": index.astype(np.int64),
        }
        for layout in layouts:
            result[layout.name] = extract(words[layout.big_endian], layout)
        return result


def _selected(
    layout: SignalLayout, mux: str, mux_value: int, page: dict[str, np.ndarray]
) -> bool:
    """Whether a signal is present in the frames of page ``mux_value`` of the top-level
    multiplexer ``mux`` (its multiplexer selects it in all of them; on an empty page: all are)."""
    if layout.mux_signal is None or len(page["index"]) == 0:
        return True
    if layout.mux_signal == mux:  # every frame of the page has mux == mux_value
        return mux_value in layout.mux_ids
    if layout.mux_signal not in page:  # a nested multiplexer of another page
        return False
    return bool(np.isin(page[layout.mux_signal], layout.mux_ids).all())


def _words(data: npt.NDArray[np.uint8], big_endian: bool) -> npt.NDArray[np.uint64]:
    """Each 8-byte payload as one unsigned 64-bit word: little-endian (Intel signals) or
    big-endian (Motorola), in the machine's own byte order."""
    contiguous = np.ascontiguousarray(data, dtype=np.uint8)
    word = contiguous.view(">u8" if big_endian else "<u8").reshape(-1)
    return word.astype(np.uint64, copy=not word.dtype.isnative)


def extract(words: npt.NDArray[np.uint64], layout: SignalLayout) -> np.ndarray:
    """One signal's raw values from 64-bit words: shift and mask, or for a signed signal shift
    its top bit to bit 63 and shift back arithmetically (the sign extension); or IEEE view."""
    if layout.is_float:
        raw = (words >> np.uint64(layout.shift)) & np.uint64((1 << layout.length) - 1)
        float_type = np.float32 if layout.length == 32 else np.float64
        int_type = np.uint32 if layout.length == 32 else np.uint64
        return raw.astype(int_type).view(float_type).astype(np.float64)
    if layout.signed:
        top = words << np.uint64(64 - layout.shift - layout.length)
        return top.view(np.int64) >> np.int64(64 - layout.length)
    value = words >> np.uint64(layout.shift)
    if layout.shift + layout.length < 64:
        value &= np.uint64((1 << layout.length) - 1)
    return value.view(np.int64) if layout.length < 64 else value  # uint64: int64 cannot hold it
