"""CAN frames as numpy arrays: collected live from python-can, or read from a log file.

``FrameArrays`` (``host.io.frames``) holds N frames in bus order, one array per field, so that the
host can decode, check and align millions of frames with numpy instead of one ``can.Message`` at a
time. The ``candump -L`` parser is ``host.io.candump``; every name stays importable from here.

``read_log`` reads a whole log; ``iter_log`` streams it, a chunk of frames at a time (the
same frames, never the whole log in memory). Both read:

* ``.log`` (``candump -L``, also what ``can.Logger`` writes): with a parser of its own, vectorised
  over the whole file. Lines are grouped by shape (length and position of ``#``); each group is
  checked column by column against the canonical layout ``(SECONDS.FRACTION) CHANNEL ID#DATA``
  with an optional `` R``/`` T`` direction. Any line that is not canonical (remote, error or CAN FD
  frames, odd spacing, or something malformed) goes through a line-by-line parser with python-can's
  semantics (``can.io.canutils``) that names the file and line of whatever is wrong.
* anything else python-can reads (``.asc``, ``.blf``, ``.trc``, ``.csv``, ...): ``can.LogReader``.

Every problem a person can cause (a missing file, a malformed line, an empty log, a frame whose
time is no clock's in any format: ``frames.timestamp_fault``) is a one-line ``LogFormatError``.
A frame stamped far off both its neighbours (``host.io.stampglitch``) is set aside with a
warning.
One exception: a ``.log`` whose last line has no newline and is incomplete (a recorder killed
mid-line leaves one: it does not parse, or carries fewer data bytes than the other frames of
its ID) is read without that line, with a one-line warning that counts it.
"""

from __future__ import annotations

import locale
import math
import mmap
import os
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.io.blf_objects import blf_corruption, quiet_python_can_blf
from odocan.host.io.candump import (
    CHUNK_BYTES,
    candump_parts,
    count_newlines,
    parse_candump,
    parse_candump_chunks,
    without_partial_last_line,
)
from odocan.host.io.candump_line import parse_candump_line
from odocan.host.io.frames import (
    FLAG_ERROR,
    FLAG_EXTENDED,
    FLAG_FD,
    FLAG_REMOTE,
    MAX_DLC,
    FrameArrays,
    LogFormatError,
    concat_frames,
    empty_frames,
    timestamp_fault,
    to_message,
)
from odocan.host.io.stampglitch import StampGlitches

if TYPE_CHECKING:
    import can

    from odocan.host.io.asc import AscLines
    from odocan.host.io.collector import FrameCollector as FrameCollector


def __getattr__(name: str) -> object:
    """``FrameCollector`` on first use (``host.io.frames.__getattr__``: no python-can at
    start-up)."""
    if name == "FrameCollector":
        from odocan.host.io.collector import FrameCollector

        return FrameCollector
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "CHUNK_BYTES", "CHUNK_FRAMES", "FLAG_ERROR", "FLAG_EXTENDED", "FLAG_FD", "FLAG_REMOTE",
    "MAX_DLC", "FrameArrays", "FrameCollector", "LogFormatError", "candump_parts",
    "concat_frames", "empty_frames", "iter_log", "parse_candump", "parse_candump_chunks",
    "parse_candump_line", "read_log", "to_message", "warn_on_stderr",
]


def warn_on_stderr(message: str) -> None:
    """Print ``warning: MESSAGE`` on stderr (the CLI's one-line style)."""
    print(f"warning: {message}", file=sys.stderr)


def require_log_file(path: Path) -> None:
    """``LogFormatError`` saying what ``path`` is when it is not a regular file to read."""
    if path.is_file():
        return
    if path.is_dir():
        raise LogFormatError(f"{path}: a directory, not a log file")
    if path.exists():
        raise LogFormatError(f"{path}: not a regular file (a pipe, device or socket)")
    raise LogFormatError(f"{path}: no such log file")


def read_log(path: str | Path, *, warn: Callable[[str], None] = warn_on_stderr) -> FrameArrays:
    """Read a CAN log (``.log`` candump by the fast parser, anything else via ``can.LogReader``).

    Raises ``LogFormatError`` (one line) for a missing or unreadable file, a malformed line (named
    ``LOG:LINE``), a frame of more than 8 bytes, or a log without a single frame. A partial last
    line of a ``.log`` (module docstring) is skipped and reported through ``warn``.
    """
    path = Path(path)
    require_log_file(path)
    if path.suffix.lower() == ".log":
        frames, skipped, line = _read_candump_file(path)
        if skipped:
            warn(
                f"{path}: skipped {skipped} partial line at the end (line {line}, cut mid-line: "
                "a recorder killed while writing?)"
            )
    else:
        frames = _read_with_python_can(path, warn)
    if len(frames) == 0:
        raise LogFormatError(f"{path}: empty log (not a single CAN frame)")
    glitches = StampGlitches()
    frames = glitches.whole(frames)
    glitches.report(path, warn)
    order = TimeOrder()
    order.feed(frames)
    order.report(path, warn)
    return frames


# A frame stamped earlier than a frame before it by no more than this is a recorder's stamping
# (a reader thread's or a socket's receive stamps of two senders' frames, a few us apart), not a
# clock problem: it can change no verdict (the judges read a capture's stamps within 0.45 of a
# 10 ms period, ``e2e_periods.CAPTURE_TOLERANCE_CYCLES``, and judge frames in log order) nor a
# duration (said to 10 ms); a clock set back or logs merged go back by far more.
STAMPING_S = 0.001


class TimeOrder:
    """Counts the frames of a log, fed in order a chunk at a time, whose time is before a
    frame's before them by more than ``STAMPING_S``: a merged, edited or clock-stepped log. Its
    times are kept as recorded (they order nothing: the frames are judged in log order), but a
    report's duration from them can be wrong (``-4.99 s simulated``), so it is said, with the
    first such frame. Less is a recorder's stamping, said nothing of."""

    def __init__(self) -> None:
        self.back = 0
        self.frames = 0
        self.last_s = -math.inf  # the latest time so far
        self.first: tuple[int, float, float] | None = None  # (frame number, time, before it)

    def feed(self, chunk: FrameArrays) -> None:
        """Account the next frames of the log."""
        if len(chunk) == 0:
            return
        times = chunk.timestamp_s
        latest = np.maximum.accumulate(np.concatenate(([self.last_s], times)))
        previous = latest[:-1]  # the latest time before each frame
        back = np.flatnonzero(times < previous - STAMPING_S)
        if len(back) and self.first is None:
            k = int(back[0])
            self.first = (self.frames + k + 1, float(times[k]), float(previous[k]))
        self.back += len(back)
        self.frames += len(chunk)
        self.last_s = float(latest[-1])

    def out_of_order(self) -> str | None:
        """What is wrong when most frames go back (a reversed or shuffled log: no E2E sequence
        nor summary reads in order), in words; None otherwise."""
        if 2 * self.back <= self.frames:
            return None
        return (f"the log is not in time order ({self.back} of {self.frames} frames earlier "
                "than the latest frame before them: reversed or shuffled?)")

    def report(self, path: Path, warn: Callable[[str], None]) -> None:
        """One warning when any frame's time went back beyond the recorder's stamping."""
        if self.first is None:
            return
        number, t_s, before_s = self.first
        warn(f"{path}: {self.back} frame{'s' if self.back > 1 else ''} of {self.frames} "
             f"earlier than the latest frame before them (first: frame {number}, {t_s:.6f} s, "
             f"{(before_s - t_s) * 1e3:.4g} ms back from {before_s:.6f} s; frames back by "
             f"{STAMPING_S * 1e3:g} ms or less, a recorder's stamping, are not counted): times "
             "kept as recorded; the log's duration may be wrong")


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
    end, skipped = without_partial_last_line(content)
    line = count_newlines(content, end) + 1 if skipped else 0
    return parse_candump_chunks(content, end, name), skipped, line



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
    require_log_file(path)
    parts = _candump_file_parts(path, warn) if path.suffix.lower() == ".log" else (
        _python_can_parts(path, chunk_frames, warn))
    order, glitches = TimeOrder(), StampGlitches()
    for chunk in _rechunk(glitches.through(parts), chunk_frames):
        order.feed(chunk)
        yield chunk
    if order.frames == 0:
        raise LogFormatError(f"{path}: empty log (not a single CAN frame)")
    glitches.report(path, warn)
    order.report(path, warn)


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
        end, skipped = without_partial_last_line(content)
        if skipped:
            warn(
                f"{path}: skipped {skipped} partial line at the end (line "
                f"{count_newlines(content, end) + 1}, cut mid-line: a recorder killed while "
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



def _read_with_python_can(path: Path, warn: Callable[[str], None]) -> FrameArrays:
    """Any format python-can reads, through ``can.LogReader``."""
    return concat_frames(list(_python_can_parts(path, 1 << 62, warn)))


def _python_can_parts(
    path: Path, chunk_frames: int, warn: Callable[[str], None]
) -> Iterator[FrameArrays]:
    """Any format python-can reads, through ``can.LogReader`` (which streams), at most
    ``chunk_frames`` frames at a time; an ``.asc``'s garbage lines and a ``.blf`` cut short
    are skipped with a warning (``host.io.asc``, ``blf_warning``)."""

    from odocan.host.io.collector import FrameCollector

    collector = FrameCollector()
    count = 0
    short: list[int] = []  # frames with fewer data bytes than their DLC (a line cut mid-frame)
    lines = None
    reader: Iterable[can.Message] | None = None
    try:
        reader, lines = _reader(path)
        for msg in reader:
            count += 1
            _check_time(path, lines, count, msg.timestamp)
            if len(msg.data) > MAX_DLC:
                raise LogFormatError(
                    f"{path}: frame {count}: {len(msg.data)} data bytes (more than 8: CAN FD "
                    "frames of more than 8 bytes are not supported)"
                )
            if len(msg.data) < msg.dlc and not (msg.is_remote_frame or msg.is_error_frame):
                short.append(count)
                continue
            collector.on_message_received(msg)
            if len(collector) >= chunk_frames:
                yield collector.arrays()
                collector = FrameCollector()
    except LogFormatError:
        _stop(reader)  # its file closed now, not left to the collector (a ResourceWarning)
        raise
    except ValueError as exc:  # python-can: unknown suffix, bad file contents
        raise LogFormatError(f"{path}: {_first_line(exc)}") from None
    except Exception as exc:  # readers raise anything from struct.error to IndexError
        _raise_if_blf_corrupt(path, count)
        raise LogFormatError(f"{path}: cannot read frame {count + 1}: {_cause(exc)}") from None
    if len(collector):
        yield collector.arrays()
    if short:
        warn(f"{path}: skipped {len(short)} frame{'s' if len(short) > 1 else ''} with fewer data "
             f"bytes than {'their' if len(short) > 1 else 'its'} DLC (first: frame {short[0]} of "
             f"{count}; a line cut mid-frame: a recorder killed while writing?)")
    _format_warnings(path, lines, count, warn)


def _check_time(path: Path, lines: AscLines | None, count: int, seconds: float | None) -> None:
    """``LogFormatError`` naming frame ``count`` (an ``.asc``'s line) when its time is no
    clock's (``timestamp_fault``: the candump parser's rule) or none (a ``.db``'s NULL, what
    python-can's writer makes of NaN)."""
    fault = "no timestamp" if seconds is None else timestamp_fault(seconds)
    if fault is None:
        return
    where = f"{path}:{lines.line}" if lines is not None else f"{path}: frame {count}"
    raise LogFormatError(f"{where}: {fault}" if seconds is None
                         else f"{where}: bad timestamp {seconds!r} ({fault})")


def _stop(reader: object) -> None:
    """Close a python-can reader's file (``stop``), if it has one."""
    stop = getattr(reader, "stop", None)
    if callable(stop):
        stop()


def _reader(path: Path) -> tuple[Iterable[can.Message], AscLines | None]:
    """python-can's reader of ``path``; an ``.asc``'s through ``AscLines`` (returned too)."""
    import can

    if path.suffix.lower() == ".blf":
        quiet_python_can_blf()
    if path.suffix.lower() != ".asc":
        return can.LogReader(path), None
    from odocan.host.io.asc import AscLines

    lines = AscLines(path.open(encoding=locale.getpreferredencoding(False)))
    return can.ASCReader(lines), lines  # type: ignore[arg-type]


def _format_warnings(
    path: Path, lines: AscLines | None, frames: int, warn: Callable[[str], None]
) -> None:
    """An ``.asc``'s skipped lines, a ``.blf`` cut short, said after its frames were read."""
    if lines is not None and lines.skipped:
        warn(f"{path}: skipped {lines.skipped} line{'s' if lines.skipped > 1 else ''} that "
             f"{'are' if lines.skipped > 1 else 'is'} no ASC frame or event (first: line "
             f"{lines.first_skipped})")
    if path.suffix.lower() == ".blf":
        _blf_notes(path, frames, warn)


def _blf_notes(path: Path, frames: int, warn: Callable[[str], None]) -> None:
    """A ``.blf`` cut short or unfinished (``blf_warning``); one with a corrupt object header
    (``blf_objects``): an error when no frame was read, else a warning (python-can skipped it)."""
    if frames == 0:
        _raise_if_blf_corrupt(path, frames)
    if (note := blf_warning(path, frames)) is not None:
        warn(note)
    if (where := blf_corruption(path)) is not None:
        warn(f"{path}: corrupt {where}: skipped (the frames it held, if any, not read; "
             f"{frames} frames read from the rest)")


def _raise_if_blf_corrupt(path: Path, frames: int) -> None:
    """A ``.blf`` read to no frame, or failing, because of a corrupt object header: that, as
    one line (not "empty log", not the reader's bare exception)."""
    if path.suffix.lower() == ".blf" and (where := blf_corruption(path)) is not None:
        read = f"{frames} frames read before" if frames else "not a single CAN frame read"
        raise LogFormatError(f"{path}: corrupt BLF: {where} ({read})")


def blf_warning(path: Path, frames: int) -> str | None:
    """What a ``.blf``'s header says against the file: shorter than the header's size (cut:
    python-can stops at the cut without a word), or a header never finished (a recorder
    killed before it closed the file); None when they agree."""
    import can

    try:
        with path.open("rb") as file:
            reader = can.BLFReader(file)
            size_in_header, objects = reader.file_size, reader.object_count
    except Exception:  # the frames were read: a header python-can cannot read is said there
        return None
    actual = path.stat().st_size
    if 0 < actual < size_in_header:
        return (f"{path}: cut short: {actual} of the {size_in_header} bytes its header gives "
                f"({frames} frames read up to the cut; a copy or a disk that ran out?)")
    if objects == 0 and frames > 0:
        return (f"{path}: its header was never finished (0 objects; {frames} frames read): "
                "a recorder killed before it closed the file?")
    return None


def _cause(exc: BaseException) -> str:
    """A reader's exception in words, without its ``error`` class name: zlib's ``error: Error -3
    while decompressing data: ...`` (a ``.blf``'s compressed container) is "zlib error -3
    (compressed data corrupt): ...", struct's ``error`` "struct error: ..."."""
    import zlib

    text = _first_line(exc)
    if isinstance(exc, zlib.error):
        code, _, why = text.partition(" while decompressing data: ")
        number = code.removeprefix("Error ").strip()
        if why and number.lstrip("-").isdigit():
            what = _ZLIB_ERRORS.get(int(number), "compressed data unreadable")
            return f"zlib error {number} ({what}): {why}"
        return f"zlib error: {text}"
    name = type(exc).__name__
    kind = f"{type(exc).__module__} error" if name == "error" else name
    return f"{kind}: {text}"


_ZLIB_ERRORS = {-2: "stream state inconsistent", -3: "compressed data corrupt",
                -4: "out of memory", -5: "compressed data cut short"}


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]
