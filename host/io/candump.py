"""``candump -L`` text (what ``can.Logger`` writes to ``.log``) to ``FrameArrays``: a parser
vectorised over a whole chunk of text, with a line-by-line path of python-can's semantics
(``can.io.canutils``) for whatever is not canonical (``host.io.logs`` module docstring)."""

from __future__ import annotations

import mmap
import re
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.io.candump_line import (
    CAN_ERR_FLAG,
    ID_MASK_29,
    parse_candump_line,
)
from odocan.host.io.frames import (
    FLAG_EXTENDED,
    MAX_DLC,
    MAX_TIMESTAMP_S,
    FrameArrays,
    LogFormatError,
    U8Array,
    concat_frames,
    empty_frames,
)

_MAX_TIMESTAMP_DIGITS = 18  # digits that fit an int64 exactly


def count_newlines(content: bytes | mmap.mmap, end: int) -> int:
    """Newlines in ``content[:end]``, counted a chunk at a time."""
    return sum(
        content[start : min(start + CHUNK_BYTES, end)].count(b"\n")
        for start in range(0, end, CHUNK_BYTES)
    )


CHUNK_BYTES = 1 << 20  # text parsed at once: its intermediates (a few times this) stay in cache


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
    scratch = np.empty(0, dtype=np.uint8)  # one buffer for every chunk's text: no fresh pages
    while start < end:
        stop = content.find(b"\n", min(start + chunk_bytes, end) - 1, end) + 1 or end
        if len(scratch) < stop - start:
            scratch = np.empty(stop - start, dtype=np.uint8)
        chunk = scratch[: stop - start]
        chunk[:] = np.frombuffer(content, np.uint8, stop - start, start)  # (a view while copied)
        part, newlines = _parse_counting(chunk, name, line)
        line += newlines
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
_BAD_PAIR = 0x100  # _HEX_PAIR's value of a pair that is not two hex digits
_pairs = np.arange(1 << 16)
_first, _second = _HEX[_pairs & 0xFF], _HEX[_pairs >> 8]  # a little-endian uint16: text order
_HEX_PAIR = np.where((_first < 0) | (_second < 0), _BAD_PAIR, _first * 16 + _second).astype(
    np.uint16
)  # two hex digits read as one '<u2' -> their byte, or _BAD_PAIR: one lookup checks and decodes
del _pairs, _first, _second
_U16_LE, _U64_LE = np.dtype("<u2"), np.dtype("<u8")
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
    return _parse_counting(content, name, first_line)[0]


def _parse_counting(
    content: bytes | U8Array, name: str, first_line: int
) -> tuple[FrameArrays, int]:
    """``parse_candump`` (of text as bytes or uint8), and the newlines in it (found once)."""
    buf = np.frombuffer(content, dtype=np.uint8) if isinstance(content, bytes) else content
    starts, ends, newlines = _line_bounds(buf)
    lengths = ends - starts
    fast_parts: list[_Parsed] = []
    if len(lengths) and 0 < lengths.min() == lengths.max() <= _MAX_FAST_LENGTH:
        groups = [np.arange(len(lengths))]  # one length (a chunk often is): nothing to sort
        slow_parts = [groups[0][:0]]
    else:
        slow_parts = [np.flatnonzero((lengths == 0) | (lengths > _MAX_FAST_LENGTH))]
        candidates = np.flatnonzero((lengths > 0) & (lengths <= _MAX_FAST_LENGTH))
        order = candidates[np.argsort(lengths[candidates], kind="stable")]
        groups = np.split(order, np.flatnonzero(np.diff(lengths[order])) + 1)
    for lines in groups:
        if len(lines):
            parsed, rejected = _parse_group(buf, starts, int(lengths[lines[0]]), lines)
            fast_parts.extend(parsed)
            slow_parts.append(rejected)
    slow_lines = np.sort(np.concatenate(slow_parts))
    if len(slow_lines):
        fast_parts.append(_parse_slow(content, starts, ends, slow_lines, name, first_line))
    return _merge(fast_parts), newlines


def _line_bounds(buf: U8Array) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], int]:
    """Start and end (exclusive, without ``\\r\\n``) of every line; the count of newlines."""
    newlines = np.flatnonzero(buf == ord("\n")).astype(np.int64, copy=False)
    starts = np.concatenate(([0], newlines + 1))
    ends = np.concatenate((newlines, [len(buf)]))
    if len(buf) and buf[-1] == ord("\n"):
        starts, ends = starts[:-1], ends[:-1]
    if len(buf):  # a line's end - 1 is in buf (at 0 if the line is empty, then ignored)
        cr = (buf[np.maximum(ends - 1, 0)] == ord("\r")) & (ends > starts)
        ends = ends - cr
    return starts, ends, len(newlines)


def _template(buf: U8Array, start: int, length: int) -> _Columns | None:
    """The columns of a canonical line, or None when the line is not canonical."""
    m = _CANONICAL.fullmatch(bytes(buf[start : start + length]))
    if m is None or len(m.group(1)) + len(m.group(2)) > _MAX_TIMESTAMP_DIGITS:
        return None
    if len(m.group(4)) == 8 and int(m.group(4), 16) & CAN_ERR_FLAG:
        return None  # error frame marker: the slow path applies python-can's rules
    return _Columns(length, m.end(1), m.end(2), m.start(4), m.end(4), m.end(5))


def _parse_group(
    buf: U8Array, starts: npt.NDArray[np.int64], length: int, lines: npt.NDArray[np.int64]
) -> tuple[list[_Parsed], npt.NDArray[np.int64]]:
    """Parse lines of one length: take the first remaining line as the template, parse every
    line of that layout at once, repeat (a few rounds) on the rest; returns (parsed, rejected)."""
    parsed: list[_Parsed] = []
    block = _rows(buf, starts[lines], length)
    for _ in range(_TEMPLATE_ROUNDS):
        if len(lines) == 0:
            break
        cols = _template(buf, int(starts[lines[0]]), length)
        if cols is None:
            break
        ok, frames = _parse_block(block, cols)
        if ok.all():  # the usual case: nothing selected, nothing left over
            parsed.append(_Parsed(lines, frames))
            return parsed, lines[:0]
        if ok.any():
            parsed.append(_Parsed(lines[ok], frames.select(ok)))
        lines, block = lines[~ok], block[~ok]
    return parsed, lines


def _rows(buf: U8Array, first: npt.NDArray[np.int64], length: int) -> U8Array:
    """The ``length`` bytes of ``buf`` from each of ``first`` (ascending) as the rows of a 2-D
    array: a strided view when they are evenly spaced (a chunk's lines of one length, one after
    the other: no copy of the text), else a copy."""
    if len(first) > 1:
        step = int(first[1] - first[0])
        if step >= length and bool(np.all(np.diff(first) == step)):
            rows: U8Array = np.lib.stride_tricks.as_strided(
                buf[int(first[0]):], shape=(len(first), length), strides=(step, 1),
                writeable=False)
            return rows
    copied: U8Array = np.lib.stride_tricks.sliding_window_view(buf, length)[first]
    return copied


def _column_ranges(c: _Columns) -> tuple[U8Array, U8Array]:
    """Per column of the layout ``c``, the bytes it allows as a range: ``byte - low <= span``
    (uint8 arithmetic, so a byte below ``low`` wraps above every span). Separators are a range
    of one byte; hex digits get the range ``0``..``f`` and the direction ``R``..``t``, both
    checked exactly when decoded."""
    low = np.zeros(c.length, dtype=np.uint8)
    span = np.zeros(c.length, dtype=np.uint8)

    def allow(first: int, stop: int, chars: bytes) -> None:
        low[first:stop], span[first:stop] = chars[0], chars[-1] - chars[0]

    allow(0, 1, b"(")
    allow(1, c.close, b"09")
    allow(c.dot, c.dot + 1, b".")
    allow(c.close, c.close + 1, b")")
    allow(c.close + 1, c.close + 2, b" ")
    allow(c.close + 2, c.id_start - 1, b"!~")  # the channel: printable, no space (nor '#')
    allow(c.id_start - 1, c.id_start, b" ")
    allow(c.id_start, c.hash, b"0f")
    allow(c.hash, c.hash + 1, b"#")
    allow(c.hash + 1, c.data_end, b"0f")
    if c.data_end < c.length:  # " R" / " T"
        allow(c.data_end, c.data_end + 1, b" ")
        allow(c.data_end + 1, c.data_end + 2, b"Rt")
    return low, span


def _rows_with(bad: npt.NDArray[np.bool_]) -> npt.NDArray[np.intp]:
    """The rows of a 2-D ``bad`` with a True (found from the flat, usually empty, hits)."""
    if not bad.any():
        return np.zeros(0, dtype=np.intp)
    rows: npt.NDArray[np.intp] = np.flatnonzero(bad.ravel()) // bad.shape[1]
    return rows


def _parse_block(block: U8Array, c: _Columns) -> tuple[npt.NDArray[np.bool_], FrameArrays]:
    """The rows of ``block`` (lines of one length: a copy, or a view with rows apart by more than
    their length, ``_rows``) that have the canonical layout ``c``, and the frames of all rows
    (those of the other rows are meaningless).

    One range test of every byte against its column's range (``_column_ranges``), then the
    decoding checks what a range cannot: hex digits by the tables that decode them, the
    direction letter, no error-frame flag (0x20000000) in an 8-digit ID. The timestamp is the
    exact integer of all its digits divided by a power of ten: one correctly rounded division,
    so it is the very double ``float(text)`` gives.
    """
    n = block.shape[0]
    low, span = _column_ranges(c)
    bad_rows = [_rows_with(np.subtract(block, low) > span)]  # uint8: broadcast by column
    bad_rows.append(_rows_with(block[:, c.close + 2 : c.id_start - 1] == ord("#")))  # channel
    id_digits = np.take(_HEX, block[:, c.id_start : c.hash])  # take: faster than [] here
    bad_rows.append(_rows_with(id_digits < 0))
    can_id = np.zeros(n, dtype=np.int64)
    for j in range(c.hash - c.id_start):
        can_id = can_id * 16 + id_digits[:, j]
    if c.hash - c.id_start == 8:
        bad_rows.append(np.flatnonzero(id_digits[:, 0] & 0x2))  # the error-frame flag
    nbytes = (c.data_end - c.hash - 1) // 2
    pairs = block[:, c.hash + 1 : c.hash + 1 + 2 * nbytes].view(_U16_LE)  # in place, unaligned
    payload = np.take(_HEX_PAIR, pairs)
    bad_rows.append(_rows_with(payload == _BAD_PAIR))
    if c.data_end < c.length:
        direction = block[:, c.data_end + 1] | 0x20  # lower case
        bad_rows.append(np.flatnonzero((direction != ord("r")) & (direction != ord("t"))))
    seconds = _timestamps_s(block, c)
    bad_rows.append(np.flatnonzero(seconds > MAX_TIMESTAMP_S))  # the line parser says why
    ok = np.ones(n, dtype=bool)
    for rows in bad_rows:
        ok[rows] = False
    data = np.zeros((n, MAX_DLC), dtype=np.uint8)
    data[:, :nbytes] = payload
    flags = FLAG_EXTENDED if c.hash - c.id_start > 3 else 0
    frames = FrameArrays(
        timestamp_s=seconds,
        can_id=(can_id & ID_MASK_29).astype(np.uint32),
        dlc=np.full(n, nbytes, dtype=np.uint8),
        data=data,
        flags=np.full(n, flags, dtype=np.uint8),
    )
    return ok, frames


_EXACT_DOUBLE_INT = 1 << 53  # integers below this are exact doubles


def _timestamps_s(block: U8Array, c: _Columns) -> npt.NDArray[np.float64]:
    """The timestamp of every row, the very double ``float(text)`` gives: the digits' integer
    and the power of ten are exact doubles, so one correctly rounded division is the correctly
    rounded decimal. A row whose integer is 2^53 or more (16+ digits, e.g. a Unix time in ns) is
    not an exact double: its text goes through ``float`` itself."""
    value = _timestamp_value(block, c)
    seconds: npt.NDArray[np.float64] = value / float(10 ** (c.close - c.dot - 1))
    for row in np.flatnonzero(value >= _EXACT_DOUBLE_INT):
        seconds[row] = float(bytes(block[row, 1 : c.close]))
    return seconds


def _timestamp_value(block: U8Array, c: _Columns) -> npt.NDArray[np.int64]:
    """The integer of the timestamp digits of every row, the ``.`` left out (at most
    ``_MAX_TIMESTAMP_DIGITS``: it fits an int64; a row with a non-digit gets a meaningless
    value)."""
    fraction = _digits_value(block, c.dot + 1, c.close)
    value: npt.NDArray[np.int64] = _digits_value(block, 1, c.dot) * 10 ** (c.close - c.dot - 1)
    return value + fraction


_ASCII_ZEROS = 0x3030303030303030  # "00000000" as a little-endian uint64


def _digits_value(block: U8Array, first: int, stop: int) -> npt.NDArray[np.int64]:
    """The value of the decimal digit columns ``first:stop`` of every row (most significant
    first), 8 digits at a time: the 8 bytes from a digit read as one little-endian uint64 and
    summed in three multiply-and-mask steps (SWAR), the bytes after a shorter run shifted out
    and ``0`` put before it; a run that would read past the row goes a column at a time."""
    n, length = block.shape
    value = np.zeros(n, dtype=np.int64)
    for start in range(first, stop, 8):
        count = min(8, stop - start)
        if start + 8 > length:
            for column in range(start, start + count):
                value = value * 10 + (block[:, column].astype(np.int64) - ord("0"))
            continue
        x = block[:, start : start + 8].view(_U64_LE)[:, 0]  # in place, unaligned
        if count < 8:
            x = (x << np.uint64(8 * (8 - count))) | np.uint64(_ASCII_ZEROS >> (8 * count))
        x = x - np.uint64(_ASCII_ZEROS)
        x = (x * np.uint64(10) + (x >> np.uint64(8))) & np.uint64(0x00FF00FF00FF00FF)
        x = (x * np.uint64(100) + (x >> np.uint64(16))) & np.uint64(0x0000FFFF0000FFFF)
        x = (x * np.uint64(10000) + (x >> np.uint64(32))) & np.uint64(0xFFFFFFFF)
        value = value * 10**count + x.astype(np.int64)
    return value


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
    content: bytes | U8Array,
    starts: npt.NDArray[np.int64],
    ends: npt.NDArray[np.int64],
    lines: npt.NDArray[np.int64],
    name: str,
    first_line: int = 0,
) -> _Parsed:
    """Parse the given lines one by one (blank lines skipped); the first bad one raises (named
    ``NAME:LINE``, lines counted from ``first_line`` + 1)."""
    from odocan.host.io.collector import FrameCollector  # python-can's Listener: when needed

    collector = FrameCollector()
    kept: list[int] = []
    for line in lines.tolist():
        raw = bytes(content[int(starts[line]) : int(ends[line])])
        msg = parse_candump_line(raw, f"{name}:{first_line + line + 1}")
        if msg is not None:
            collector.on_message_received(msg)
            kept.append(line)
    return _Parsed(np.array(kept, dtype=np.int64), collector.arrays())
