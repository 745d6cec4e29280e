"""CAN frames as numpy arrays: collected live from python-can, or read from a log file.

``FrameArrays`` holds N frames in bus order, one array per field, so that the host can decode,
check and align millions of frames with numpy instead of one ``can.Message`` at a time.

``read_log`` reads a whole log; ``iter_log`` streams it, a chunk of frames at a time (the
same frames, never the whole log in memory). Both read:

* ``.log`` (``candump -L``, also what ``can.Logger`` writes): with a parser of its own, vectorised
  over the whole file. Lines are grouped by shape (length and position of ``#``); each group is
  checked column by column against the canonical layout ``(SECONDS.FRACTION) CHANNEL ID#DATA``
  with an optional `` R``/`` T`` direction. Any line that is not canonical (remote, error or CAN FD
  frames, odd spacing, or something malformed) goes through a line-by-line parser with python-can's
  semantics (``can.io.canutils``) that names the file and line of whatever is wrong.
* anything else python-can reads (``.asc``, ``.blf``, ``.trc``, ``.csv``, ...): ``can.LogReader``.

Every problem a person can cause (a missing file, a malformed line, an empty log) is a one-line
``LogFormatError``. One exception: a ``.log`` whose last line has no newline and is incomplete (a
recorder killed mid-line leaves one: it does not parse, or carries fewer data bytes than the
other frames of its ID) is read without that line, with a one-line warning that counts it.
"""

from __future__ import annotations

import mmap
import os
import re
import sys
from array import array
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np
import numpy.typing as npt

from odocan.sim.exceptions import OdocanError

FLAG_EXTENDED = 0x01  # 29-bit identifier
FLAG_REMOTE = 0x02  # remote transmission request
FLAG_ERROR = 0x04  # error frame (can_id 0, no data)
FLAG_FD = 0x08  # CAN FD frame (of at most 8 bytes)
MAX_DLC = 8  # classic CAN payload; longer frames are refused

_CAN_ERR_FLAG = 0x20000000  # candump: error frame marker in the ID (can/error.h)
_CAN_ERR_BUSERROR = 0x00000080
_ID_MASK_29 = 0x1FFFFFFF
_MAX_TIMESTAMP_DIGITS = 18  # digits that fit an int64 exactly

U8Array = npt.NDArray[np.uint8]


class LogFormatError(OdocanError):
    """A log file that cannot be read: ``LOG:LINE: what is wrong`` (one line)."""


@dataclass(frozen=True)
class FrameArrays:
    """N CAN frames in bus order, one numpy array per field.

    Attributes:
        timestamp_s: float64 (N,), seconds (simulated seconds for the lockstep rig).
        can_id: uint32 (N,), the 11- or 29-bit identifier (0 for error frames).
        dlc: uint8 (N,), payload length in bytes, 0..8.
        data: uint8 (N, 8), the payload, zero padded after ``dlc`` bytes.
        flags: uint8 (N,): bit 0 extended ID, bit 1 remote, bit 2 error frame, bit 3 CAN FD.
    """

    timestamp_s: npt.NDArray[np.float64]
    can_id: npt.NDArray[np.uint32]
    dlc: U8Array
    data: U8Array
    flags: U8Array

    def __len__(self) -> int:
        return int(self.timestamp_s.shape[0])

    @property
    def arbitration_id(self) -> npt.NDArray[np.uint32]:
        """Alias of ``can_id`` (python-can's name)."""
        return self.can_id

    def select(
        self, mask: npt.NDArray[np.bool_] | npt.NDArray[np.intp] | slice
    ) -> FrameArrays:
        """The frames picked by a boolean mask, an index array or a slice (a view), in the order
        given."""
        return FrameArrays(
            self.timestamp_s[mask], self.can_id[mask], self.dlc[mask], self.data[mask],
            self.flags[mask],
        )


class FrameCollector(can.Listener):
    """A python-can ``Listener`` that keeps every frame, cheaply, for ``arrays()``.

    Each frame costs a few appends to typed arrays (no ``can.Message`` is kept).
    """

    def __init__(self) -> None:
        self._timestamp = array("d")
        self._can_id = array("I")
        self._dlc = array("B")
        self._flags = array("B")
        self._data = bytearray()

    def on_message_received(self, msg: can.Message) -> None:
        """Append one frame (payloads longer than 8 bytes are cut to 8)."""
        payload = bytes(msg.data[:MAX_DLC])
        self._timestamp.append(msg.timestamp)
        self._can_id.append(msg.arbitration_id)
        self._dlc.append(min(msg.dlc, MAX_DLC))
        self._flags.append(_message_flags(msg))
        self._data += payload
        if len(payload) < MAX_DLC:
            self._data += bytes(MAX_DLC - len(payload))

    def __len__(self) -> int:
        return len(self._timestamp)

    def arrays(self) -> FrameArrays:
        """The frames collected so far (copies)."""
        n = len(self._timestamp)
        return FrameArrays(
            timestamp_s=np.array(self._timestamp, dtype=np.float64),
            can_id=np.array(self._can_id, dtype=np.uint32),
            dlc=np.array(self._dlc, dtype=np.uint8),
            data=np.frombuffer(bytes(self._data), dtype=np.uint8).reshape(n, MAX_DLC).copy(),
            flags=np.array(self._flags, dtype=np.uint8),
        )


def _message_flags(msg: can.Message) -> int:
    """The ``FrameArrays.flags`` bits of one python-can message."""
    return (
        (FLAG_EXTENDED if msg.is_extended_id else 0)
        | (FLAG_REMOTE if msg.is_remote_frame else 0)
        | (FLAG_ERROR if msg.is_error_frame else 0)
        | (FLAG_FD if msg.is_fd else 0)
    )


def empty_frames() -> FrameArrays:
    """A FrameArrays of no frame."""
    return FrameArrays(
        np.zeros(0, np.float64), np.zeros(0, np.uint32), np.zeros(0, np.uint8),
        np.zeros((0, MAX_DLC), np.uint8), np.zeros(0, np.uint8),
    )


def warn_on_stderr(message: str) -> None:
    """Print ``warning: MESSAGE`` on stderr (the CLI's one-line style)."""
    print(f"warning: {message}", file=sys.stderr)


def read_log(path: str | Path, *, warn: Callable[[str], None] = warn_on_stderr) -> FrameArrays:
    """Read a CAN log (``.log`` candump by the fast parser, anything else via ``can.LogReader``).

    Raises ``LogFormatError`` (one line) for a missing or unreadable file, a malformed line (named
    ``LOG:LINE``), a frame of more than 8 bytes, or a log without a single frame. A partial last
    line of a ``.log`` (module docstring) is skipped and reported through ``warn``.
    """
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(f"{path}: no such log file")
    if path.suffix.lower() == ".log":
        frames, skipped, line = _read_candump_file(path)
        if skipped:
            warn(
                f"{path}: skipped {skipped} partial line at the end (line {line}, cut mid-line: "
                "a recorder killed while writing?)"
            )
    else:
        frames = _read_with_python_can(path)
    if len(frames) == 0:
        raise LogFormatError(f"{path}: empty log (not a single CAN frame)")
    return frames


def _read_candump_file(path: Path) -> tuple[FrameArrays, int, int]:
    """A ``.log`` file's frames, the partial last lines skipped (0 or 1) and that line's number.

    The file is mapped, not read, and parsed ``CHUNK_BYTES`` at a time (cut at line ends), each
    chunk's pages given back once parsed: the text of a big log never sits in memory whole; the
    frames do (22 bytes each)."""
    try:
        with path.open("rb") as file:
            if os.fstat(file.fileno()).st_size == 0:  # empty, or a file with no size (/proc)
                return _parse_whole(file.read(), str(path))
            with mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as content:
                return _parse_whole(content, str(path))
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _parse_whole(content: bytes | mmap.mmap, name: str) -> tuple[FrameArrays, int, int]:
    """``_read_candump_file`` on the file's content (bytes or a map of it)."""
    end, skipped = _without_partial_last_line(content)
    line = _count_newlines(content, end) + 1 if skipped else 0
    return parse_candump_chunks(content, end, name), skipped, line


def _count_newlines(content: bytes | mmap.mmap, end: int) -> int:
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
    return _concat_releasing(list(candump_parts(content, end, name, chunk_bytes)))


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


CHUNK_FRAMES = 1 << 18  # frames per chunk of ``iter_log``: about 6 MB of FrameArrays


def iter_log(
    path: str | Path, *, chunk_frames: int = CHUNK_FRAMES,
    warn: Callable[[str], None] = warn_on_stderr,
) -> Iterator[FrameArrays]:
    """The frames of a log in bus order, ``chunk_frames`` at a time (the last chunk may hold
    fewer), never the whole log in memory: a ``.log`` is mapped and parsed a text chunk at a
    time, anything else streams through ``can.LogReader``. The frames and the errors are those
    of ``read_log`` (concatenated, the chunks are ``read_log(path)``), raised when reached."""
    if chunk_frames < 1:
        raise ValueError(f"chunk_frames must be at least 1, got {chunk_frames}")
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(f"{path}: no such log file")
    parts = _candump_file_parts(path, warn) if path.suffix.lower() == ".log" else (
        _python_can_parts(path, chunk_frames))
    total = 0
    for chunk in _rechunk(parts, chunk_frames):
        total += len(chunk)
        yield chunk
    if total == 0:
        raise LogFormatError(f"{path}: empty log (not a single CAN frame)")


def _candump_file_parts(path: Path, warn: Callable[[str], None]) -> Iterator[FrameArrays]:
    """``candump_parts`` of a mapped ``.log``, its partial last line skipped with a warning."""
    try:
        with path.open("rb") as file:
            if os.fstat(file.fileno()).st_size == 0:
                content: bytes | mmap.mmap = file.read()
            else:
                content = mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ)
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        end, skipped = _without_partial_last_line(content)
        if skipped:
            warn(
                f"{path}: skipped {skipped} partial line at the end (line "
                f"{_count_newlines(content, end) + 1}, cut mid-line: a recorder killed while "
                "writing?)"
            )
        yield from candump_parts(content, end, str(path))
    finally:
        if isinstance(content, mmap.mmap):
            content.close()


def _rechunk(parts: Iterable[FrameArrays], size: int) -> Iterator[FrameArrays]:
    """The frames of ``parts`` again, ``size`` at a time (the last chunk may hold fewer)."""
    pending: list[FrameArrays] = []
    held = 0
    for part in parts:
        while len(part):
            take = min(size - held, len(part))
            pending.append(part if take == len(part) else part.select(slice(0, take)))
            part = part.select(slice(take, None)) if take < len(part) else empty_frames()
            held += take
            if held == size:
                yield concat_frames(pending)
                pending, held = [], 0
    if held:
        yield concat_frames(pending)


def _concat_releasing(parts: list[FrameArrays]) -> FrameArrays:
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


def concat_frames(parts: list[FrameArrays]) -> FrameArrays:
    """The frames of ``parts``, one after the other."""
    if len(parts) == 1:
        return parts[0]
    if not parts:
        return empty_frames()
    return FrameArrays(
        timestamp_s=np.concatenate([p.timestamp_s for p in parts]),
        can_id=np.concatenate([p.can_id for p in parts]),
        dlc=np.concatenate([p.dlc for p in parts]),
        data=np.concatenate([p.data for p in parts]),
        flags=np.concatenate([p.flags for p in parts]),
    )


def _without_partial_last_line(content: bytes | mmap.mmap) -> tuple[int, int]:
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


def _read_with_python_can(path: Path) -> FrameArrays:
    """Any format python-can reads, through ``can.LogReader``."""
    return concat_frames(list(_python_can_parts(path, 1 << 62)))


def _python_can_parts(path: Path, chunk_frames: int) -> Iterator[FrameArrays]:
    """Any format python-can reads, through ``can.LogReader`` (which streams), at most
    ``chunk_frames`` frames at a time."""
    collector = FrameCollector()
    count = 0
    try:
        for msg in can.LogReader(path):
            count += 1
            if len(msg.data) > MAX_DLC:
                raise LogFormatError(
                    f"{path}: frame {count}: {len(msg.data)} data bytes (more than 8: CAN FD "
                    "frames of more than 8 bytes are not supported)"
                )
            collector.on_message_received(msg)
            if len(collector) >= chunk_frames:
                yield collector.arrays()
                collector = FrameCollector()
    except LogFormatError:
        raise
    except ValueError as exc:  # python-can: unknown suffix, bad file contents
        raise LogFormatError(f"{path}: {_first_line(exc)}") from None
    except Exception as exc:  # readers raise anything from struct.error to IndexError
        raise LogFormatError(
            f"{path}: cannot read frame {count + 1}: {type(exc).__name__}: {_first_line(exc)}"
        ) from None
    if len(collector):
        yield collector.arrays()


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


# --- candump -L: the vectorised parser -----------------------------------------------------------

_HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"ABCDEF"):
    _HEX[_c] = 10 + _i
_DIGIT = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789"):
    _DIGIT[_c] = _i

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
    classes = _CLASS[block]
    classes &= need
    ok: npt.NDArray[np.bool_] = np.asarray(classes.all(axis=1))
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
    """The value of decimal digit columns (most significant first)."""
    value = np.zeros(cols.shape[0], dtype=np.int64)
    for j in range(cols.shape[1]):
        value = value * 10 + _DIGIT[cols[:, j]]
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
    hexes = _HEX[block[:, c.hash + 1 : c.data_end]].astype(np.uint8)
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
    order = np.argsort(line, kind="stable")

    def cat(field: str) -> npt.NDArray[np.generic]:
        return np.concatenate([getattr(p.frames, field) for p in parts])[order]

    return FrameArrays(
        timestamp_s=cat("timestamp_s").astype(np.float64),
        can_id=cat("can_id").astype(np.uint32),
        dlc=cat("dlc").astype(np.uint8),
        data=cat("data").astype(np.uint8),
        flags=cat("flags").astype(np.uint8),
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


def to_message(frames: FrameArrays, i: int) -> can.Message:
    """Frame ``i`` as a python-can message (its logged timestamp, flags and payload)."""
    flags = int(frames.flags[i])
    dlc = int(frames.dlc[i])
    remote = bool(flags & FLAG_REMOTE)
    return can.Message(
        timestamp=float(frames.timestamp_s[i]),
        arbitration_id=int(frames.can_id[i]),
        is_extended_id=bool(flags & FLAG_EXTENDED),
        is_remote_frame=remote,
        is_error_frame=bool(flags & FLAG_ERROR),
        is_fd=bool(flags & FLAG_FD),
        dlc=dlc,
        data=None if remote else bytes(frames.data[i, :dlc]),
    )
