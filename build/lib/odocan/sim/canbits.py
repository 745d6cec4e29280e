"""Classic CAN frames as bits on the wire: CRC-15, bit stuffing, exact lengths, arbitration order.

ISO 11898-1 (CAN 2.0A/B), a data or remote frame:

    standard: SOF | ID 11 | RTR | IDE=0 | r0 | DLC 4 | DATA 0..64 | CRC 15 | tail 10
    extended: SOF | ID-A 11 | SRR=1 | IDE=1 | ID-B 18 | RTR | r1 | r0 | DLC 4 | DATA | CRC 15 | tail
    tail:     CRC delimiter | ACK slot | ACK delimiter | EOF 7

Dominant is 0, recessive 1; identifiers go most significant bit first. The CRC-15 (generator
x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1, 0x4599, register cleared at SOF) covers SOF to
the end of the data field, unstuffed. From SOF to the end of the CRC sequence the transmitter
stuffs: after five equal bits it inserts one of the opposite value, which counts toward the next
run. The tail (CRC delimiter, ACK slot, ACK delimiter, seven EOF bits: 10 bits) is not stuffed.
After a frame the bus needs the 3-bit intermission (interframe space) before the next SOF.

So a standard 8-byte data frame is 108 bits + up to 24 stuff bits, and occupies the bus for 111 to
135 bit times with the interframe space (Davis et al. 2007, eq. 4: 8n + 47 + floor((34 + 8n - 1)/4)
at most; 67 + 8n + floor((54 + 8n - 1)/4) extended).

An error frame (python-can's ``is_error_frame``) is modelled as its error flag and delimiter:
6 + 8 = 14 bits, unstuffed, and wins any arbitration.
"""

from __future__ import annotations

import math
from typing import Final

import can

CRC15_POLY: Final = 0x4599
INTERFRAME_BITS: Final = 3
TAIL_BITS: Final = 10  # CRC delimiter, ACK slot, ACK delimiter, EOF
ERROR_FRAME_BITS: Final = 14  # error flag 6 + error delimiter 8
STUFF_RUN: Final = 5


def _crc15_table() -> tuple[int, ...]:
    """CRC-15/CAN of every byte fed into a zero register (most significant bit first)."""
    table = []
    for byte in range(256):
        crc = byte << 7
        for _ in range(8):
            crc = ((crc << 1) ^ CRC15_POLY) if crc & 0x4000 else crc << 1
            crc &= 0x7FFF
        table.append(crc)
    return tuple(table)


_CRC15_TABLE: Final = _crc15_table()


def crc15_bits(bits: str, crc: int = 0) -> int:
    """CRC-15/CAN of a string of '0'/'1' (continuing from ``crc``)."""
    for bit in bits:
        top = ((crc >> 14) & 1) ^ (bit == "1")
        crc = (crc << 1) & 0x7FFF
        if top:
            crc ^= CRC15_POLY
    return crc


def crc15_bytes(data: bytes | bytearray, crc: int) -> int:
    """CRC-15/CAN continued over whole bytes, a table lookup per byte."""
    for byte in data:
        crc = ((crc << 8) & 0x7FFF) ^ _CRC15_TABLE[((crc >> 7) ^ byte) & 0xFF]
    return crc


def header_bits(msg: can.Message) -> str:
    """SOF to the end of the DLC field, as '0'/'1' (arbitration and control fields)."""
    rtr = "1" if msg.is_remote_frame else "0"
    dlc = f"{msg.dlc & 0xF:04b}"
    if msg.is_extended_id:
        can_id = msg.arbitration_id & 0x1FFF_FFFF
        return f"0{can_id >> 18:011b}11{can_id & 0x3FFFF:018b}{rtr}00{dlc}"
    return f"0{msg.arbitration_id & 0x7FF:011b}{rtr}00{dlc}"


def payload(msg: can.Message) -> bytes:
    """The data field's bytes (none for a remote frame; at most 8)."""
    return b"" if msg.is_remote_frame else bytes(msg.data[:8])


def unstuffed_bits(msg: can.Message) -> str:
    """The frame from SOF to the end of the CRC sequence, before stuffing, as '0'/'1'."""
    value, nbits = _unstuffed(msg)
    return f"{value:0{nbits}b}"


def _unstuffed(msg: can.Message) -> tuple[int, int]:
    """``unstuffed_bits`` as an integer (SOF its most significant bit) and its length."""
    head, head_bits, crc = _header(msg)
    data = payload(msg)
    n = len(data)
    if n:
        crc = crc15_bytes(data, crc)
        head = (head << (8 * n)) | int.from_bytes(data, "big")
    return (head << 15) | crc, head_bits + 8 * n + 15


def _header(msg: can.Message) -> tuple[int, int, int]:
    """``header_bits`` as (integer, length) and the CRC register after it, cached per header (a
    bus carries a few dozen identifiers, each mostly with one DLC)."""
    key = (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.dlc)
    cached = _HEADERS.get(key)
    if cached is None:
        bits = header_bits(msg)
        cached = (int(bits, 2), len(bits), crc15_bits(bits))
        if len(_HEADERS) < _HEADERS_CACHED:
            _HEADERS[key] = cached
    return cached


_HEADERS: dict[tuple[int, bool, bool, int], tuple[int, int, int]] = {}
_HEADERS_CACHED: Final = 4096


# Stuffing as a finite automaton. State = 5 * last bit + equal bits in a row (0..4; 0: none yet).
def _stuff_bit(state: int, bit: int) -> tuple[int, int]:
    """(stuff bits inserted, next state) after transmitting ``bit`` from ``state``."""
    last, run = divmod(state, STUFF_RUN)
    run = run + 1 if run and bit == last else 1
    if run == STUFF_RUN:  # the stuff bit, of the other value, is the first of the next run
        return 1, 5 * (1 - bit) + 1
    return 0, 5 * bit + run


def _stuff_byte_table() -> tuple[int, ...]:
    """Per (state, byte): stuff bits inserted << 4 | next state, the byte's bits MSB first."""
    table = []
    for state in range(2 * STUFF_RUN):
        for byte in range(256):
            stuffed, now = 0, state
            for shift in range(7, -1, -1):
                more, now = _stuff_bit(now, (byte >> shift) & 1)
                stuffed += more
            table.append(stuffed << 4 | now)
    return tuple(table)


_STUFF_BYTE: Final = _stuff_byte_table()


def _stuff_count_int(value: int, nbits: int) -> int:
    """Stuff bits a transmitter inserts into the ``nbits`` bits of ``value`` (MSB first): the
    leading ``nbits % 8`` bits one at a time, then a table lookup per byte."""
    lead = nbits % 8
    stuffed, state = 0, 0
    for shift in range(nbits - 1, nbits - 1 - lead, -1):
        more, state = _stuff_bit(state, (value >> shift) & 1)
        stuffed += more
    table = _STUFF_BYTE
    rest = value & ((1 << (nbits - lead)) - 1)
    for byte in rest.to_bytes((nbits - lead) // 8, "big"):
        entry = table[state << 8 | byte]
        stuffed += entry >> 4
        state = entry & 0xF
    return stuffed


def stuff_count(bits: str) -> int:
    """How many stuff bits a transmitter inserts into ``bits`` ('0'/'1'): after five equal
    bits, one of the opposite value, which counts toward the next run."""
    return _stuff_count_int(int(bits, 2), len(bits)) if bits else 0


def frame_bits(msg: can.Message) -> int:
    """Bit times ``msg`` occupies the bus from SOF to the end of EOF (no interframe space)."""
    if msg.is_error_frame:
        return ERROR_FRAME_BITS
    if msg.is_fd:
        raise ValueError("CAN FD frames have no classic bit timing")
    value, nbits = _unstuffed(msg)
    return nbits + _stuff_count_int(value, nbits) + TAIL_BITS


def arbitration_key(msg: can.Message) -> tuple[int, int, int, int, int]:
    """Orders frames as bitwise arbitration does (smaller wins): the 11-bit base identifier,
    RTR or SRR, IDE, the 18-bit extension, the extended RTR. An error frame beats everything."""
    if msg.is_error_frame:
        return (-1, 0, 0, 0, 0)
    rtr = 1 if msg.is_remote_frame else 0
    if msg.is_extended_id:
        can_id = msg.arbitration_id & 0x1FFF_FFFF
        return (can_id >> 18, 1, 1, can_id & 0x3FFFF, rtr)
    return (msg.arbitration_id & 0x7FF, rtr, 0, 0, 0)


# --- measured latencies: a streaming histogram per identifier ----------------------------------

LATENCY_EXACT_BITS: Final = 8192  # below this, one bin per bit time
LATENCY_COARSE_SHIFT: Final = 8  # above it, bins of 256 bit times
LATENCY_MAX_BINS: Final = 16384  # latencies past the last bin share it (their max stays exact)
LATENCY_MAX_IDS: Final = 1024  # identifiers tracked one by one; the rest share LATENCY_OTHER_IDS
LATENCY_OTHER_IDS: Final = (-2, False)


class LatencyHistogram:
    """One message's latencies in whole bit times (rounded up), in bounded memory.

    Exact per bit time up to ``LATENCY_EXACT_BITS``, then in bins of 2**``LATENCY_COARSE_SHIFT``
    bit times, at most ``LATENCY_MAX_BINS`` bins; the count and the maximum are exact. A quantile
    is the upper edge of its bin, so it never understates.
    """

    __slots__ = ("bins", "count", "max_bits")

    def __init__(self) -> None:
        self.bins: dict[int, int] = {}
        self.count = 0
        self.max_bits = 0

    @staticmethod
    def _bin(bits: int) -> int:
        if bits < LATENCY_EXACT_BITS:
            return bits
        coarse = LATENCY_EXACT_BITS + ((bits - LATENCY_EXACT_BITS) >> LATENCY_COARSE_SHIFT)
        return min(coarse, LATENCY_MAX_BINS - 1)

    @staticmethod
    def _upper_bits(index: int) -> int:
        if index < LATENCY_EXACT_BITS:
            return index
        return LATENCY_EXACT_BITS + ((index - LATENCY_EXACT_BITS + 1) << LATENCY_COARSE_SHIFT) - 1

    def add(self, bits: int) -> None:
        """Count one latency of ``bits`` bit times."""
        index = self._bin(bits)
        self.bins[index] = self.bins.get(index, 0) + 1
        self.count += 1
        if bits > self.max_bits:
            self.max_bits = bits

    def merge(self, other: LatencyHistogram) -> None:
        """Add ``other``'s latencies to these (same bins)."""
        for index, count in other.bins.items():
            self.bins[index] = self.bins.get(index, 0) + count
        self.count += other.count
        self.max_bits = max(self.max_bits, other.max_bits)

    def count_above(self, bits: int) -> int:
        """Latencies above ``bits`` (exact below ``LATENCY_EXACT_BITS``; above it, a bin that
        straddles ``bits`` counts whole: never understated)."""
        return sum(c for i, c in self.bins.items() if self._upper_bits(i) > bits)

    def quantile_bits(self, fraction: float) -> int:
        """The smallest bin edge at or below which ``fraction`` of the latencies lie (0 if none);
        never above the exact maximum."""
        if not self.count:
            return 0
        need = max(1, math.ceil(fraction * self.count - 1e-9))
        seen = 0
        for index in sorted(self.bins):
            seen += self.bins[index]
            if seen >= need:
                if index == LATENCY_MAX_BINS - 1:  # the overflow bin: no upper edge but the max
                    return self.max_bits
                return min(self._upper_bits(index), self.max_bits)
        return self.max_bits


class LatencyStats:
    """Per identifier, the queuing + transmission latency of every frame a bit-timed wire
    carried: from the moment it was ready in its transmit buffer to its end of frame.

    Keys are ``(arbitration_id, is_extended_id)``; error frames are ``(-1, False)``; past
    ``LATENCY_MAX_IDS`` identifiers (a babbling node sends random ones) the rest share
    ``(-2, False)``, so memory stays bounded. The span runs from the first frame's start of frame
    to the last one's end of frame.
    """

    def __init__(self, bitrate: int) -> None:
        self.bitrate = bitrate
        self.by_id: dict[tuple[int, bool], LatencyHistogram] = {}
        self.first_start_s = math.inf
        self.last_end_s = -math.inf

    def record(self, msg: can.Message, ready_s: float, start_s: float, end_s: float) -> None:
        """One frame on the wire: ready at ``ready_s``, SOF at ``start_s``, EOF at ``end_s``."""
        key = (-1, False) if msg.is_error_frame else (msg.arbitration_id, msg.is_extended_id)
        hist = self.by_id.get(key)
        if hist is None:
            if len(self.by_id) >= LATENCY_MAX_IDS:
                key = LATENCY_OTHER_IDS
                hist = self.by_id.get(key)
            if hist is None:
                hist = self.by_id[key] = LatencyHistogram()
        # Rounded up to whole bit times; the 1e-6 bit absorbs float rounding of the timestamps.
        hist.add(max(0, math.ceil((end_s - ready_s) * self.bitrate - 1e-6)))
        if start_s < self.first_start_s:
            self.first_start_s = start_s
        self.last_end_s = end_s  # the wire ends its frames in time order
