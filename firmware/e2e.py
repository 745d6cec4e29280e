"""AUTOSAR E2E Profile 2 on classic CAN frames: CRC8H2F, the Profile 2 CRC, the receiver's check.

The header of every odocan frame (dbc/odocan.dbc)::

    byte 0          CHECKSUM  CRC8H2F over bytes 1..7, then the data ID
    byte 1 bits 0-3 COUNTER   0..15, +1 per frame sent, wraps 15 -> 0
    byte 1 bits 4-7           payload (the message's own use)

The data ID is ``data_ids[COUNTER]``, one of a 16-entry list per message (Profile 2's
``DataIDList``); odocan builds them as ``(slot << 4) | counter`` with a slot unique per message,
so no data ID is shared between two messages (dbc/README.md).

CRC8H2F (AUTOSAR SWS CRC Library, ``Crc_CalculateCRC8H2F``): width 8, polynomial 0x2F, initial
value 0xFF, no reflection, final XOR 0xFF; check value ``CRC("123456789") = 0xDF``. The AUTOSAR
library computes the data bytes and then the data ID in two calls (the second continuing from the
first); that equals one CRC over the concatenation, which is what :func:`p02_crc` does.

Receiver semantics are those of ``E2E_P02Check`` (R4.0, no SyncCounter), except that the first
valid frame after (re-)initialisation is reported ``OK`` (AUTOSAR: ``INITIAL``, mapped to OK by the
E2E state machine's legacy behaviour). Everything is integer-only and allocation-free per frame.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Final

from odocan.firmware.fixmath import U8_MAX, U32_MAX, u8, u32, wrap_u32

CRC8H2F_POLY: Final = 0x2F
CRC8H2F_INIT: Final = 0xFF
CRC8H2F_XOR_OUT: Final = 0xFF
CRC8H2F_CHECK: Final = 0xDF  # CRC8H2F(b"123456789"), AUTOSAR SWS CRC Library, 7.2.1.2

FRAME_LEN: Final = 8  # Profile 2 DataLength, bytes: classic CAN
COUNTER_MASK: Final = 0x0F  # Profile 2 counter: 0..15
DATA_ID_COUNT: Final = 16  # entries of a Profile 2 DataIDList
MAX_DELTA_COUNTER_LIMIT: Final = 15  # MaxDeltaCounter saturates here


def _crc8h2f_table() -> tuple[u8, ...]:
    """The 256-entry MSB-first table of polynomial 0x2F (a ``const uint8_t[256]`` in C)."""
    table: list[u8] = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ CRC8H2F_POLY) if crc & 0x80 else (crc << 1)
            crc &= U8_MAX  # (uint8_t)
        table.append(crc)
    return tuple(table)


CRC8H2F_TABLE: Final[tuple[u8, ...]] = _crc8h2f_table()


def crc8h2f(data: bytes | bytearray) -> u8:
    """CRC8H2F of ``data`` (any length): table-driven, one lookup per byte."""
    table = CRC8H2F_TABLE
    crc = CRC8H2F_INIT
    for byte in data:
        crc = table[crc ^ byte]
    return crc ^ CRC8H2F_XOR_OUT


def p02_crc(frame: bytes | bytearray, data_id: u8) -> u8:
    """The Profile 2 CRC of an 8-byte ``frame``: CRC8H2F over bytes 1..7, then ``data_id``.

    Unrolled (as a C compiler would unroll the 8-iteration loop): it runs once per frame sent and
    once per frame received.
    """
    t = CRC8H2F_TABLE
    crc = t[CRC8H2F_INIT ^ frame[1]]
    crc = t[crc ^ frame[2]]
    crc = t[crc ^ frame[3]]
    crc = t[crc ^ frame[4]]
    crc = t[crc ^ frame[5]]
    crc = t[crc ^ frame[6]]
    crc = t[crc ^ frame[7]]
    crc = t[crc ^ data_id]
    return crc ^ CRC8H2F_XOR_OUT


def p02_seal(word: int, data_ids: tuple[u8, ...]) -> bytes:
    """The 8-byte frame of ``word`` (a little-endian ``uint64_t``, CHECKSUM bits 0-7 still 0)
    with its Profile 2 CRC in byte 0: ``p02_crc`` over its bytes with the data ID of its COUNTER
    (bits 8-11), unrolled here too (every frame sent: one call less, as C would inline it)."""
    t = CRC8H2F_TABLE
    frame = word.to_bytes(8, "little")
    crc = t[CRC8H2F_INIT ^ frame[1]]
    crc = t[crc ^ frame[2]]
    crc = t[crc ^ frame[3]]
    crc = t[crc ^ frame[4]]
    crc = t[crc ^ frame[5]]
    crc = t[crc ^ frame[6]]
    crc = t[crc ^ frame[7]]
    crc = t[crc ^ data_ids[frame[1] & COUNTER_MASK]]
    return (word | (crc ^ CRC8H2F_XOR_OUT)).to_bytes(8, "little")


class E2EStatus(IntEnum):
    """Result of one Profile 2 check (values of AUTOSAR ``E2E_P02CheckStatusType``)."""

    OK = 0x00  # valid, counter +1 (or the first valid frame after init)
    NONEWDATA = 0x01  # the check ran with no frame received
    ERROR = 0x02  # WRONGCRC: bad CRC (or not 8 bytes): the frame carries nothing usable
    REPEATED = 0x08  # valid CRC, same counter as the last valid frame: drop it
    OKSOMELOST = 0x20  # valid, counter +2..+MaxDeltaCounter: frames were lost, use this one
    WRONGSEQUENCE = 0x40  # valid CRC, counter jump beyond MaxDeltaCounter: drop it


_OK: Final = E2EStatus.OK
_NONEWDATA: Final = E2EStatus.NONEWDATA
_ERROR: Final = E2EStatus.ERROR
_REPEATED: Final = E2EStatus.REPEATED
_OKSOMELOST: Final = E2EStatus.OKSOMELOST
_WRONGSEQUENCE: Final = E2EStatus.WRONGSEQUENCE


class E2EReceiver:
    """Profile 2 receiver check state of one message (``E2E_P02CheckStateType`` plus counts).

    ``max_delta_counter_init`` (AUTOSAR ``MaxDeltaCounterInit``, 0..14): the window
    ``max_delta_counter`` restarts from it at each accepted frame and grows by one at every check
    call (up to 15) before the counter is judged, so the next frame may jump by up to init + 1
    (AUTOSAR's example: init 1 accepts +1 and +2). Call ``check(None)`` once per receive period
    without a frame: the window then widens with time, as lost frames would advance the counter.
    After WRONGSEQUENCE the reference counter is kept (R4.0: no SyncCounter), so a sender that
    jumped is accepted again when its counter comes round to the reference + 1: at most 15 frames.
    Counts are u32 and wrap; ``lost_frames`` sums the frames skipped by OKSOMELOST. Per frame: no
    allocation, one CRC (about 0.6 us in CPython 3.11 for the whole check).

    ``window_per_period=True`` ties the window to time instead of to check calls: it widens only
    in ``new_period()``, called once at the start of every receive period, so duplicates or
    replays arriving within one period cannot widen it. With ``max_delta_counter_init=0`` a frame
    may then jump the counter by at most the number of periods since the last accepted one (+1
    is always accepted), which refuses a stale frame whose counter came round (a replay 14 or 15
    periods old) while a lost frame still comes through as OKSOMELOST.
    """

    __slots__ = (
        "count_error",
        "count_nonewdata",
        "count_ok",
        "count_oksomelost",
        "count_repeated",
        "count_wrongsequence",
        "data_ids",
        "last_valid_counter",
        "lost_data",
        "lost_frames",
        "max_delta_counter",
        "max_delta_counter_init",
        "status",
        "wait_for_first_data",
        "window_per_period",
    )

    def __init__(
        self,
        data_ids: tuple[u8, ...],
        max_delta_counter_init: int = 1,
        *,
        window_per_period: bool = False,
    ) -> None:
        self.data_ids: tuple[u8, ...] = data_ids
        self.max_delta_counter_init: int = max_delta_counter_init
        self.window_per_period: bool = window_per_period
        self.count_ok: u32 = 0
        self.count_oksomelost: u32 = 0
        self.count_repeated: u32 = 0
        self.count_wrongsequence: u32 = 0
        self.count_error: u32 = 0
        self.count_nonewdata: u32 = 0
        self.lost_frames: u32 = 0
        self.status: E2EStatus = _NONEWDATA
        self.last_valid_counter: int = 0
        self.max_delta_counter: int = 0
        self.lost_data: int = 0
        self.wait_for_first_data: bool = True
        self.reset()

    def reset(self) -> None:
        """``E2E_P02CheckInit``: forget the sequence (the counts are kept)."""
        self.last_valid_counter = 0
        self.max_delta_counter = 0
        self.lost_data = 0
        self.wait_for_first_data = True
        self.status = _NONEWDATA

    def new_period(self) -> None:
        """Start a receive period: the window widens by one (up to 15)."""
        self.new_periods(1)

    def new_periods(self, periods: int) -> None:
        """Start ``periods`` (>= 0) receive periods at once: ``new_period`` that many times (C:
        one saturating add instead of the loop)."""
        widened = self.max_delta_counter + periods
        if widened > MAX_DELTA_COUNTER_LIMIT:
            widened = MAX_DELTA_COUNTER_LIMIT
        if widened > self.max_delta_counter:
            self.max_delta_counter = widened

    def check(self, frame: bytes | bytearray | None) -> E2EStatus:
        """Check one received frame (``None``: the period ended with none); count and return.

        Use the frame's data only when the result is OK or OKSOMELOST.
        """
        if not self.window_per_period and self.max_delta_counter < MAX_DELTA_COUNTER_LIMIT:
            self.max_delta_counter += 1
        if frame is None:
            self.count_nonewdata = wrap_u32(self.count_nonewdata + 1)
            self.status = _NONEWDATA
            return _NONEWDATA
        if len(frame) != FRAME_LEN:
            return self._error()
        counter = frame[1] & COUNTER_MASK
        if frame[0] != p02_crc(frame, self.data_ids[counter]):
            return self._error()
        if not self.wait_for_first_data and (counter - self.last_valid_counter) & COUNTER_MASK == 1:
            # The next counter (nearly every frame): ``_sequence``'s OK and ``_accept``, in line.
            self.last_valid_counter = counter
            self.max_delta_counter = self.max_delta_counter_init
            self.lost_data = 0
            self.count_ok = (self.count_ok + 1) & U32_MAX  # (uint32_t)
            self.status = _OK
            return _OK
        status = self._sequence(counter)
        self.status = status
        return status

    def accepted(self) -> u32:
        """Frames accepted (OK or OKSOMELOST), u32 wrapping: the ``*_E2E_OK`` status signal."""
        return wrap_u32(self.count_ok + self.count_oksomelost)

    def _error(self) -> E2EStatus:
        """Count a frame with a bad CRC or length."""
        self.count_error = wrap_u32(self.count_error + 1)
        self.status = _ERROR
        return _ERROR

    def _sequence(self, counter: int) -> E2EStatus:
        """The counter part of the check, for a frame whose CRC is valid."""
        if self.wait_for_first_data:
            self.wait_for_first_data = False
            return self._accept(counter, 0, _OK)
        delta = (counter - self.last_valid_counter) & COUNTER_MASK
        if delta == 1:
            return self._accept(counter, 0, _OK)
        if delta == 0:
            self.count_repeated = wrap_u32(self.count_repeated + 1)
            return _REPEATED
        if delta <= self.max_delta_counter:
            self.count_oksomelost = wrap_u32(self.count_oksomelost + 1)
            self.lost_frames = wrap_u32(self.lost_frames + delta - 1)
            return self._accept(counter, delta - 1, _OKSOMELOST)
        self.count_wrongsequence = wrap_u32(self.count_wrongsequence + 1)
        return _WRONGSEQUENCE

    def _accept(self, counter: int, lost: int, status: E2EStatus) -> E2EStatus:
        """Take ``counter`` as the last valid one and re-arm the delta window."""
        self.last_valid_counter = counter
        self.max_delta_counter = self.max_delta_counter_init
        self.lost_data = lost
        if status is _OK:
            self.count_ok = (self.count_ok + 1) & U32_MAX  # (uint32_t)
        return status
