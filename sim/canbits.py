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
    head, crc = _header_and_crc(msg)
    data = payload(msg)
    if not data:
        return f"{head}{crc:015b}"
    crc = crc15_bytes(data, crc)
    return f"{head}{int.from_bytes(data, 'big'):0{8 * len(data)}b}{crc:015b}"


def _header_and_crc(msg: can.Message) -> tuple[str, int]:
    """``header_bits`` and the CRC register after them, cached per header (a bus carries a
    few dozen identifiers, each mostly with one DLC)."""
    key = (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.dlc)
    cached = _HEADERS.get(key)
    if cached is None:
        head = header_bits(msg)
        cached = (head, crc15_bits(head))
        if len(_HEADERS) < _HEADERS_CACHED:
            _HEADERS[key] = cached
    return cached


_HEADERS: dict[tuple[int, bool, bool, int], tuple[str, int]] = {}
_HEADERS_CACHED: Final = 4096


def stuff_count(bits: str) -> int:
    """How many stuff bits a transmitter inserts into ``bits`` (after five equal bits, one of the
    opposite value, which opens the next run).

    Only runs of four or more equal bits can be stuffed. A run of r bits entered with c equal
    bits already sent (c = 1 right after a stuff bit of its value, else 0) takes its first stuff
    bit after 5 - c bits and one more every 5 bits: 1 + (r - 5 + c) // 5 of them; when the last
    lands on the run's final bit, that stuff bit is the first of the next run (c = 1 there).
    """
    stuffed = 0
    carry_at = -1  # where a run would start with one equal (stuff) bit already sent
    for start, end in sorted(_long_runs(bits, "0") + _long_runs(bits, "1")):
        first = STUFF_RUN - (1 if start == carry_at else 0)
        extra = end - start - first
        if extra >= 0:
            stuffed += 1 + extra // STUFF_RUN
            if extra % STUFF_RUN == 0:
                carry_at = end
    return stuffed


def _long_runs(bits: str, value: str) -> list[tuple[int, int]]:
    """(start, end) of every run of four or more ``value`` bits (shorter runs are never
    stuffed); ``str.find`` scans in C, far faster than a regular expression here."""
    other = "1" if value == "0" else "0"
    four = value * 4
    runs = []
    start = bits.find(four)
    while start >= 0:
        end = bits.find(other, start + 4)
        if end < 0:
            end = len(bits)
        runs.append((start, end))
        start = bits.find(four, end)
    return runs


def frame_bits(msg: can.Message) -> int:
    """Bit times ``msg`` occupies the bus from SOF to the end of EOF (no interframe space)."""
    if msg.is_error_frame:
        return ERROR_FRAME_BITS
    if msg.is_fd:
        raise ValueError("CAN FD frames have no classic bit timing")
    bits = unstuffed_bits(msg)
    return len(bits) + stuff_count(bits) + TAIL_BITS


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
