"""``candump -L`` text (what ``can.Logger`` writes to ``.log``) to ``FrameArrays``: a parser
vectorised over a whole chunk of text, with a line-by-line path of python-can's semantics
(``can.io.canutils``) for whatever is not canonical (``host.io.logs`` module docstring)."""

from __future__ import annotations

import mmap
import re
from collections.abc import Iterator
from dataclasses import dataclass

import can
import numpy as np
import numpy.typing as npt

from odocan.host.io.frames import (
    FLAG_EXTENDED,
    MAX_DLC,
    FrameArrays,
    FrameCollector,
    LogFormatError,
    U8Array,
    concat_frames,
    empty_frames,
)

_CAN_ERR_FLAG = 0x20000000  # candump: error frame marker in the ID (can/error.h)
_CAN_ERR_BUSERROR = 0x00000080
_ID_MASK_29 = 0x1FFFFFFF
_MAX_TIMESTAMP_DIGITS = 18  # digits that fit an int64 exactly


def count_newlines(content: bytes | mmap.mmap, end: int) -> int:
    """Newlines in ``content[:end]``, counted a chunk at a time."""
    return sum(
        content[start : min(start + CHUNK_BYTES, end)].count(b"\n")
        for start in range(0, end, CHUNK_BYTES)
    )


CHUNK_BYTES = 8 << 20  # text parsed at once: its intermediates are a few times this


def parse_candump_chunks(
    content: bytes | mmap.mmap, end: int, name: str, chunk_bytes: int = CHUNK_BYTES
) -> FrameArrays:
    """``parse_candump`` of ``content[:end]``, ``chunk_bytes`` (at least) at a time cut after a
    newline; the same frames and the same ``NAME:LINE`` errors as one call on the whole. Pages
    of a mapped ``content`` are released once parsed."""
    return concat_releasing(list(candump_parts(content, end, name, chunk_bytes)))


def candump_parts(
    content: bytes | mmap.mmap, end: int, name: str, chunk_bytes: int = CHUNK_BYTES
) -> Iterator[FrameArrays]:
    """The frames of ``content[:end]`` (``candump -L`` text), one part per ``chunk_bytes`` (at
    least) of text cut after a newline, in order; errors as ``parse_candump`` on the whole."""
    start = line = 0
    while start < end:
        stop = content.find(b"\n", min(start + chunk_bytes, end) - 1, end) + 1 or end
        chunk = content[start:stop]
        part = parse_candump(chunk, name, first_line=line)
        line += chunk.count(b"\n")
        if isinstance(content, mmap.mmap):
            _release(content, stop)
        start = stop
        yield part



def concat_releasing(parts: list[FrameArrays]) -> FrameArrays:
    """``concat_frames(parts)``, one field at a time, each field's parts dropped once joined:
    at most one field is held twice (30 bytes a frame at the peak, not 44). Empties ``parts``."""
    if len(parts) <= 1:
        return concat_frames(parts)
    names = ("timestamp_s", "can_id", "dlc", "data", "flags")
    columns = {name: [getattr(p, name) for p in parts] for name in names}
    parts.clear()
    joined = {name: np.concatenate(columns.pop(name)) for name in names}
    return FrameArrays(**joined)


def _release(content: mmap.mmap, stop: int) -> None:
    """Give back the mapped pages before ``stop`` (read-only file pages: read again if need be)."""
    size = stop - stop % mmap.PAGESIZE
    if size > 0 and hasattr(mmap, "MADV_DONTNEED"):
        content.madvise(mmap.MADV_DONTNEED, 0, size)



def without_partial_last_line(content: bytes | mmap.mmap) -> tuple[int, int]:
    """Where ``content`` ends less its last line when that line has no newline and is incomplete
    (it does not parse, or has fewer data bytes than the earlier frames of its ID); and the lines
    skipped (0 or 1)."""
    size = len(content)
    cut = content.rfind(b"\n") + 1
    tail = content[cut:]
    if not tail.strip():
        return size, 0
    try:
        msg = parse_candump_line(tail)
    except LogFormatError:
        return cut, 1
    if msg is None or msg.is_error_frame or msg.is_remote_frame:
        return size, 0
    token = f" {msg.arbitration_id:0{8 if msg.is_extended_id else 3}X}#"
    before = max(
        content.rfind(token.encode(), 0, cut), content.rfind(token.lower().encode(), 0, cut)
    )
    if before < 0:
        return size, 0
    line_end = content.find(b"\n", before, cut)
    line = content[before : line_end if line_end >= 0 else cut].split(b"#", 1)[1].split()[0]
    return (cut, 1) if len(line) > 2 * len(msg.data) else (size, 0)



# --- candump -L: the vectorised parser -----------------------------------------------------------

_HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"ABCDEF"):
    _HEX[_c] = 10 + _i
_HEX_U8 = _HEX.astype(np.uint8)  # the same for checked digits, without a cast per frame

_C_DIGIT, _C_HEX, _C_CHANNEL, _C_DIRECTION = 1, 2, 4, 8
_C_SPACE, _C_HASH, _C_DOT, _C_ANY = 0x10, 0x20, 0x40, 0x80  # a separator each; any byte
_CLASS = np.full(256, _C_ANY, dtype=np.uint8)  # character classes, a bit each
_CLASS[ord(" ")] |= _C_SPACE
_CLASS[ord("#")] |= _C_HASH
_CLASS[ord(".")] |= _C_DOT
_CLASS[np.frombuffer(b"0123456789", np.uint8)] |= _C_DIGIT
_CLASS[np.frombuffer(b"0123456789abcdefABCDEF", np.uint8)] |= _C_HEX
_CLASS[ord(" ") + 1 : 127] |= _C_CHANNEL
_CLASS[ord("#")] &= ~np.uint8(_C_CHANNEL)
_CLASS[np.frombuffer(b"RrTt", np.uint8)] |= _C_DIRECTION
_MAX_FAST_LENGTH = 200  # longer lines go the slow way
_TEMPLATE_ROUNDS = 4

_CANONICAL = re.compile(
    rb"\((\d+)\.(\d+)\) (\S+) ([0-9A-Fa-f]{1,8})#((?:[0-9A-Fa-f]{2}){0,8})(?: [RrTt])?"
)


@dataclass
class _Columns:
    """Where the fields of one canonical line shape are (columns, relative to the line start)."""

    length: int
    dot: int  # '.' of the timestamp
    close: int  # ')'
    id_start: int  # first hex digit of the ID
    hash: int  # '#'
    data_end: int  # one past the last data hex digit


@dataclass
class _Parsed:
    """Frames parsed so far, with the line number (0-based) of each."""

    line: npt.NDArray[np.int64]
    frames: FrameArrays


def parse_candump(content: bytes, name: str = "<log>", *, first_line: int = 0) -> FrameArrays:
    """Parse ``candump -L`` text (bytes of the whole file) into FrameArrays, in line order.

    ``name`` is used in error messages (``NAME:LINE: ...``), the lines numbered from
    ``first_line`` + 1 (``content`` a later part of a file).
    """
    buf = np.frombuffer(content, dtype=np.uint8)
    starts, ends = _line_bounds(buf)
    lengths = ends - starts
    fast_parts: list[_Parsed] = []
    slow_parts = [np.flatnonzero((lengths == 0) | (lengths > _MAX_FAST_LENGTH))]
    candidates = np.flatnonzero((lengths > 0) & (lengths <= _MAX_FAST_LENGTH))
    order = candidates[np.argsort(lengths[candidates], kind="stable")]
    sorted_lengths = lengths[order]
    bounds = np.flatnonzero(np.diff(sorted_lengths)) + 1
    for lines in np.split(order, bounds):
        if len(lines):
            parsed, rejected = _parse_group(buf, starts, int(lengths[lines[0]]), lines)
            fast_parts.extend(parsed)
            slow_parts.append(rejected)
    slow_lines = np.sort(np.concatenate(slow_parts))
    if len(slow_lines):
        fast_parts.append(_parse_slow(content, starts, ends, slow_lines, name, first_line))
    return _merge(fast_parts)


def _line_bounds(buf: U8Array) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Start and end (exclusive, without ``\\r\\n``) of every line."""
    newlines = np.flatnonzero(buf == ord("\n")).astype(np.int64)
    starts = np.concatenate(([0], newlines + 1))
    ends = np.concatenate((newlines, [len(buf)]))
    if len(buf) and buf[-1] == ord("\n"):
        starts, ends = starts[:-1], ends[:-1]
    if len(ends):
        cr = np.zeros(len(ends), dtype=bool)
        nonempty = ends > starts
        cr[nonempty] = buf[ends[nonempty] - 1] == ord("\r")
        ends = ends - cr
    return starts, ends


def _template(buf: U8Array, start: int, length: int) -> _Columns | None:
    """The columns of a canonical line, or None when the line is not canonical."""
    m = _CANONICAL.fullmatch(bytes(buf[start : start + length]))
    if m is None or len(m.group(1)) + len(m.group(2)) > _MAX_TIMESTAMP_DIGITS:
        return None
    if len(m.group(4)) == 8 and int(m.group(4), 16) & _CAN_ERR_FLAG:
        return None  # error frame marker: the slow path applies python-can's rules
    return _Columns(length, m.end(1), m.end(2), m.start(4), m.end(4), m.end(5))


def _parse_group(
    buf: U8Array, starts: npt.NDArray[np.int64], length: int, lines: npt.NDArray[np.int64]
) -> tuple[list[_Parsed], npt.NDArray[np.int64]]:
    """Parse lines of one length: take the first remaining line as the template, parse every
    line of that layout at once, repeat (a few rounds) on the rest; returns (parsed, rejected)."""
    parsed: list[_Parsed] = []
    windows = np.lib.stride_tricks.sliding_window_view(buf, length)
    for _ in range(_TEMPLATE_ROUNDS):
        if len(lines) == 0:
            break
        cols = _template(buf, int(starts[lines[0]]), length)
        if cols is None:
            break
        block = windows[starts[lines]]
        ok = _check_block(block, cols)
        if ok.all():  # the usual case: no copy of the block, nothing left over
            parsed.append(_Parsed(lines, _decode_block(block, cols)))
            return parsed, lines[:0]
        if ok.any():
            parsed.append(_Parsed(lines[ok], _decode_block(block[ok], cols)))
        lines = lines[~ok]
    return parsed, lines


def _check_block(block: U8Array, c: _Columns) -> npt.NDArray[np.bool_]:
    """Rows of ``block`` (lines of one length) that have the canonical layout ``c``: a character
    of the right class in every column, the separators ``.``, `` ``, ``#`` being classes of their
    own (one class lookup and one reduction for the whole block), then ``(`` and ``)``."""
    need = np.full(c.length, _C_ANY, dtype=np.uint8)
    need[1 : c.close] = _C_DIGIT
    need[c.dot] = _C_DOT
    need[c.close + 1] = _C_SPACE
    need[c.close + 2 : c.id_start - 1] = _C_CHANNEL
    need[c.id_start - 1] = _C_SPACE
    need[c.id_start : c.hash] = _C_HEX
    need[c.hash] = _C_HASH
    need[c.hash + 1 : c.data_end] = _C_HEX
    if c.data_end < c.length:  # " R" / " T"
        need[c.data_end] = _C_SPACE
        need[c.data_end + 1] = _C_DIRECTION
    classes = _CLASS[block]  # a fresh C-contiguous copy: its rows are consecutive
    classes &= need
    ok = np.ones(block.shape[0], dtype=bool)
    ok[np.flatnonzero(classes.ravel() == 0) // c.length] = False  # rows with a wrong class
    ok &= block[:, 0] == ord("(")
    ok &= block[:, c.close] == ord(")")
    if c.hash - c.id_start == 8:
        ok &= (_HEX[block[:, c.id_start]] & 0x2) == 0  # no error-frame flag (0x20000000)
    return ok


def _hex_value(cols: U8Array) -> npt.NDArray[np.int64]:
    """The value of hex digit columns (most significant first)."""
    value = np.zeros(cols.shape[0], dtype=np.int64)
    for j in range(cols.shape[1]):
        value = value * 16 + _HEX[cols[:, j]]
    return value


def _decimal_value(cols: U8Array) -> npt.NDArray[np.int64]:
    """The value of decimal digit columns (most significant first; already checked to be
    ASCII digits, at most ``_MAX_TIMESTAMP_DIGITS`` of them, so every sum fits an int64): one
    integer matrix product with the powers of ten instead of a pass per column."""
    powers = 10 ** np.arange(cols.shape[1] - 1, -1, -1, dtype=np.int64)
    value: npt.NDArray[np.int64] = (cols - np.uint8(ord("0"))).astype(np.int64) @ powers
    return value


def _decode_block(block: U8Array, c: _Columns) -> FrameArrays:
    """FrameArrays of canonical lines (already checked).

    The timestamp is the exact integer of all its digits divided by a power of ten: one correctly
    rounded division, so it is the very double ``float(text)`` gives.
    """
    n = block.shape[0]
    digits = np.concatenate((block[:, 1 : c.dot], block[:, c.dot + 1 : c.close]), axis=1)
    timestamp = _decimal_value(digits) / float(10 ** (c.close - c.dot - 1))
    can_id = _hex_value(block[:, c.id_start : c.hash]) & _ID_MASK_29
    nbytes = (c.data_end - c.hash - 1) // 2
    data = np.zeros((n, MAX_DLC), dtype=np.uint8)
    hexes = _HEX_U8[block[:, c.hash + 1 : c.data_end]]
    data[:, :nbytes] = (hexes[:, 0::2] << 4) | hexes[:, 1::2]
    flags = FLAG_EXTENDED if c.hash - c.id_start > 3 else 0
    return FrameArrays(
        timestamp_s=timestamp,
        can_id=can_id.astype(np.uint32),
        dlc=np.full(n, nbytes, dtype=np.uint8),
        data=data,
        flags=np.full(n, flags, dtype=np.uint8),
    )


def _merge(parts: list[_Parsed]) -> FrameArrays:
    """Concatenate parsed parts and put the frames back in line order."""
    if not parts:
        return empty_frames()
    line = np.concatenate([p.line for p in parts])
    in_order = bool(np.all(line[1:] > line[:-1]))  # one part (the usual chunk): no reordering
    order = None if in_order else np.argsort(line, kind="stable")

    def cat(field: str) -> npt.NDArray[np.generic]:
        columns = [getattr(p.frames, field) for p in parts]
        joined = columns[0] if len(columns) == 1 else np.concatenate(columns)
        return joined if order is None else joined[order]

    return FrameArrays(  # the parts' arrays are fresh: kept as they are when the type is right
        timestamp_s=cat("timestamp_s").astype(np.float64, copy=False),
        can_id=cat("can_id").astype(np.uint32, copy=False),
        dlc=cat("dlc").astype(np.uint8, copy=False),
        data=cat("data").astype(np.uint8, copy=False),
        flags=cat("flags").astype(np.uint8, copy=False),
    )


# --- candump -L: one line at a time (python-can's rules, precise errors) -------------------------


def _parse_slow(
    content: bytes,
    starts: npt.NDArray[np.int64],
    ends: npt.NDArray[np.int64],
    lines: npt.NDArray[np.int64],
    name: str,
    first_line: int = 0,
) -> _Parsed:
    """Parse the given lines one by one (blank lines skipped); the first bad one raises (named
    ``NAME:LINE``, lines counted from ``first_line`` + 1)."""
    collector = FrameCollector()
    kept: list[int] = []
    for line in lines.tolist():
        raw = content[int(starts[line]) : int(ends[line])]
        msg = parse_candump_line(raw, f"{name}:{first_line + line + 1}")
        if msg is not None:
            collector.on_message_received(msg)
            kept.append(line)
    return _Parsed(np.array(kept, dtype=np.int64), collector.arrays())


def parse_candump_line(raw: bytes, where: str = "<line>") -> can.Message | None:
    """One ``candump -L`` line as python-can reads it (None for a blank line).

    Raises ``LogFormatError`` naming ``where`` (``LOG:LINE``) and what is wrong.
    """
    try:
        text = raw.decode("ascii").strip()
    except UnicodeDecodeError:
        raise LogFormatError(f"{where}: not ASCII text") from None
    if not text:
        return None
    fields = text.split()
    is_rx = True
    if len(fields) == 4 and fields[3].lower() in ("r", "t"):
        is_rx = fields.pop().lower() == "r"
    if len(fields) != 3:
        raise LogFormatError(
            f"{where}: expected '(TIMESTAMP) CHANNEL ID#DATA', got {len(fields)} field(s)"
        )
    timestamp = _parse_timestamp(fields[0], where)
    can_id_text, sep, data_text = fields[2].partition("#")
    if not sep:
        raise LogFormatError(f"{where}: no '#' between CAN ID and data in {fields[2]!r}")
    can_id = _parse_can_id(can_id_text, where)
    if can_id & _CAN_ERR_FLAG and can_id & _CAN_ERR_BUSERROR:
        return can.Message(timestamp=timestamp, is_error_frame=True)
    is_fd = data_text.startswith("#")
    if is_fd:
        data_text = data_text[2:]
    if data_text[:1].lower() == "r":
        dlc = _parse_remote_dlc(data_text[1:], where)
        return can.Message(
            timestamp=timestamp, arbitration_id=can_id & _ID_MASK_29,
            is_extended_id=len(can_id_text) > 3, is_remote_frame=True, dlc=dlc, is_rx=is_rx,
        )
    return can.Message(
        timestamp=timestamp, arbitration_id=can_id & _ID_MASK_29,
        is_extended_id=len(can_id_text) > 3, data=_parse_data(data_text, where), is_fd=is_fd,
        is_rx=is_rx,
    )


def _parse_timestamp(text: str, where: str) -> float:
    """``(SECONDS)`` -> float seconds."""
    if not (text.startswith("(") and text.endswith(")")):
        raise LogFormatError(f"{where}: missing timestamp: expected '(SECONDS)', got {text!r}")
    try:
        return float(text[1:-1])
    except ValueError:
        raise LogFormatError(f"{where}: bad timestamp {text!r}") from None


def _parse_can_id(text: str, where: str) -> int:
    """1..8 hex digits."""
    if not 1 <= len(text) <= 8 or any(ch not in "0123456789abcdefABCDEF" for ch in text):
        raise LogFormatError(f"{where}: bad CAN ID {text!r} (1 to 8 hex digits)")
    return int(text, 16)


def _parse_remote_dlc(text: str, where: str) -> int:
    """The optional DLC digit(s) after ``R``."""
    if not text:
        return 0
    if not text.isdigit() or int(text) > MAX_DLC:
        raise LogFormatError(f"{where}: bad remote frame length {text!r} (0..8)")
    return int(text)


def _parse_data(text: str, where: str) -> bytes:
    """Hex data, two digits a byte, at most 8 bytes."""
    if len(text) % 2:
        raise LogFormatError(f"{where}: odd number of hex digits in data {text!r}")
    if len(text) > 2 * MAX_DLC:
        raise LogFormatError(
            f"{where}: {len(text) // 2} data bytes (more than 8: CAN FD frames of more than "
            "8 bytes are not supported)"
        )
    try:
        return bytes.fromhex(text)
    except ValueError:
        raise LogFormatError(f"{where}: bad hex in data {text!r}") from None
