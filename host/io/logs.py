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

Every problem a person can cause (a missing file, a malformed line, an empty log) is a one-line
``LogFormatError``. One exception: a ``.log`` whose last line has no newline and is incomplete (a
recorder killed mid-line leaves one: it does not parse, or carries fewer data bytes than the
other frames of its ID) is read without that line, with a one-line warning that counts it.
"""

from __future__ import annotations

import mmap
import os
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

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
    to_message,
)

if TYPE_CHECKING:
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



def _read_with_python_can(path: Path) -> FrameArrays:
    """Any format python-can reads, through ``can.LogReader``."""
    return concat_frames(list(_python_can_parts(path, 1 << 62)))


def _python_can_parts(path: Path, chunk_frames: int) -> Iterator[FrameArrays]:
    """Any format python-can reads, through ``can.LogReader`` (which streams), at most
    ``chunk_frames`` frames at a time."""
    import can  # python-can's readers: imported for the formats that need them

    from odocan.host.io.collector import FrameCollector

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
