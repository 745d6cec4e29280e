"""``--log``: a run's frames to python-can's log writer (``can.Logger``), a simulated second at a
time, a full disk stopping the recording and never the run.

``Recording`` is a ``FrameBatchListener``: the lockstep rig and the replay hand it the frames
their instant ``odocan`` handle queued (``sim.tickloop``), as ``(timestamp, id, payload)``
tuples, no ``Message`` built. For a candump ``.log`` (python-can's ``CanutilsLogWriter``) and a
Vector ``.asc`` (``ASCWriter``, its own line templates) it writes the lines that writer writes
for the ``Message`` the handle's ``recv`` would give (an 11-bit data frame received on
``channel``), byte for byte, a batch in one write: half a whole-process ``odocan run --log`` of
an hour went into building a ``Message`` per frame and formatting it (``bench/rig.py --whole``).
A ``.blf`` gets that ``Message`` (its writer packs binary objects into compressed containers).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable
from contextlib import suppress
from pathlib import Path
from typing import cast

import can
from can.io.asc import ASCWriter
from can.io.blf import FILE_HEADER_SIZE, LOG_CONTAINER, LOG_CONTAINER_STRUCT, OBJ_HEADER_BASE_STRUCT
from can.io.canutils import CanutilsLogWriter
from can.util import channel2int

from odocan.sim.framebatch import FrameBatchListener, Received
from odocan.sim.transport import data_frame

# python-can 4's ASCWriter line templates, which ``Recording._asc_line`` writes as an f-string.
_ASC_TEMPLATES = ("{channel}  {id:<15} {dir:<4} {dtype} {data}", "{timestamp: 9.6f} {message}\n")


class Recording(FrameBatchListener):
    """A python-can log writer (``can.Logger``) whose first write error -- a full disk, a
    vanished mount -- stops the recording, never the run that feeds it; ``stop()`` finishes the
    file and then raises that error as an ``OSError`` saying how many frames were written, for
    the caller to name the path (``odocan run --log``). ``channel``: the name of the handle
    whose batches it is given (what ``recv`` would have stamped on each frame). Passive: it only
    writes, so a run may hand it a simulated second at once (``FrameBatchListener.passive``)."""

    passive = True

    def __init__(self, writer: can.Listener, channel: str = "vcan0") -> None:
        self.writer = writer
        self.channel = channel
        self.frames = 0
        self.failure: OSError | None = None
        self.reason = ""  # the failure's words, once ``stop`` has finished the file
        self.kept_frames = 0  # the frames the file holds then (``stopped_after``)
        self._candump = type(writer) is CanutilsLogWriter and not channel.isdigit()
        self._asc = type(writer) is ASCWriter
        number = channel2int(channel)  # ASCWriter's channel number: counted from 1
        self._asc_channel = 0 if not self._asc else \
            cast(ASCWriter, writer).channel if number is None else number + 1
        self._asc_templates_known = self._asc and \
            (ASCWriter.FORMAT_MESSAGE, ASCWriter.FORMAT_EVENT) == _ASC_TEMPLATES

    def on_message_received(self, msg: can.Message) -> None:
        """Write ``msg`` (counted); after a failure, nothing more."""
        if self.failure is not None:
            return
        try:
            self.writer.on_message_received(msg)
        except OSError as exc:
            self.failure = exc
            return
        self.frames += 1

    def on_frames(self, frames: list[Received]) -> None:
        """Write a batch, in order: a candump or ASC log's data-frame tuples as its lines, in one
        write; anything else frame by frame through the writer (``on_message_received``)."""
        if self.failure is not None:
            return
        lines: list[str] = []
        line = self._line_format()
        for frame in frames:
            if line is not None and isinstance(frame, tuple):
                lines.append(line(*frame))
            else:
                self._write_lines(lines)
                lines = []
                self.on_message_received(self._message(frame))
                line = self._line_format()
        self._write_lines(lines)

    def _line_format(self) -> Callable[[float, int, bytes], str] | None:
        """How a data-frame tuple's line is formatted here: a candump log's always, an ASC log's
        once its writer wrote the header its first frame opens (python-can's path); else None."""
        if self._candump:
            return self._candump_line
        if self._asc and cast(ASCWriter, self.writer).header_written:
            return self._asc_line
        return None

    def _message(self, frame: Received) -> can.Message:
        """The ``Message`` ``recv`` gives for a queued frame (``OdocanBus.as_message``)."""
        if not isinstance(frame, tuple):
            return frame
        msg = data_frame(*frame)
        msg.channel = self.channel
        return msg

    def _candump_line(self, timestamp_s: float, can_id: int, data: bytes) -> str:
        """``CanutilsLogWriter``'s line for a received 11-bit data frame: its stamp never below
        the log's first (the writer's ``last_timestamp``, set by its first frame)."""
        writer = cast(CanutilsLogWriter, self.writer)
        first_s = writer.last_timestamp
        if first_s is None:
            first_s = writer.last_timestamp = timestamp_s or 0.0
        stamp_s = first_s if timestamp_s < first_s else timestamp_s
        return f"({stamp_s:f}) {self.channel} {can_id:03X}#{data.hex().upper()} R\n"

    def _asc_line(self, timestamp_s: float, can_id: int, data: bytes) -> str:
        """``ASCWriter``'s line for a received 11-bit data frame: its stamp relative to the log's
        first frame (``started``) unless earlier than it; its templates as an f-string when
        they are the ones of python-can 4 (``_ASC_TEMPLATES``), else themselves."""
        writer = cast(ASCWriter, self.writer)
        started_s = writer.started
        stamp_s = timestamp_s - started_s if timestamp_s >= started_s else timestamp_s
        data_hex = data.hex(" ").upper()
        if self._asc_templates_known:
            return f"{stamp_s: 9.6f} {self._asc_channel}  {can_id:<15X} Rx   d {len(data):x} " \
                f"{data_hex}\n"
        message = writer.FORMAT_MESSAGE.format(
            channel=self._asc_channel, id=f"{can_id:X}", dir="Rx", dtype=f"d {len(data):x}",
            data=data_hex,
        )
        return writer.FORMAT_EVENT.format(timestamp=stamp_s, message=message)

    def _write_lines(self, lines: list[str]) -> None:
        """Formatted lines, in one write, counted when written."""
        if not lines or self.failure is not None:
            return
        try:
            cast(CanutilsLogWriter | ASCWriter, self.writer).file.write("".join(lines))
        except OSError as exc:
            self.failure = exc
            return
        self.frames += len(lines)

    def stop(self) -> None:
        """Finish the file; then the first error, if any, with the frames the file holds
        (``stopped_after``; ``kept_frames`` and ``reason`` keep them for the run's report). A
        ``.blf`` a write stopped is finished by ``finish_blf``: python-can's ``stop`` would
        write its buffer first, fail again, and never write the header (0 objects counted in a
        file holding thousands), as it never does when its own last write fails."""
        blf = isinstance(self.writer, can.BLFWriter)
        try:
            if self.failure is None or not blf:
                self.writer.stop()
        except OSError as exc:
            self.failure = self.failure or exc
        if self.failure is not None:
            if blf:  # failed as a frame or the last container was written
                with suppress(OSError):  # the first error is the one to tell
                    finish_blf(cast(can.BLFWriter, self.writer))
            self.reason = self.failure.strerror or str(self.failure)
            path = _path_of(self.writer)
            whole = None if path is None else whole_frames(path)
            self.kept_frames = self.frames if whole is None else whole
            raise OSError(self.failure.errno,
                          f"{self.reason} ({said_kept(whole, self.frames)})")


def finish_blf(writer: can.BLFWriter) -> None:
    """The header of a ``.blf`` whose write failed, in place (no byte more: a full disk or
    RLIMIT_FSIZE still lets the file's own bytes be rewritten): the file's size, the frames
    python-can reads back (the last container, cut by the write, as far as it inflates) and
    the stamps of the first and last; the buffer the write left (frames not written) dropped.
    The cut container stays: its frames are read back by python-can, a stricter reader may
    stop before it (docs/rig.md)."""
    path = _path_of(writer)
    with suppress(OSError):  # the buffer the failed write left: closed, its bytes lost
        writer.file.close()
    if path is None:  # a stream without a name: nothing to rewrite
        return
    offsets_s = _read_back_offsets_s(path)
    writer.object_count = len(offsets_s)
    writer.uncompressed_size = _uncompressed_size(path)
    if offsets_s and writer.start_timestamp is not None:
        writer.stop_timestamp = writer.start_timestamp + offsets_s[-1]
    with open(path, "r+b") as blf:
        writer.file = blf
        writer._write_header(path.stat().st_size)  # python-can's own header, counting them


def _uncompressed_size(path: Path) -> int:
    """What python-can's writer counts in a ``.blf`` header's uncompressed size: the header's
    bytes, and each container's (its headers, the data it says it inflates to) whose header is
    in the file, walking the objects as its reader does."""
    size, base = path.stat().st_size, OBJ_HEADER_BASE_STRUCT.size
    heads = base + LOG_CONTAINER_STRUCT.size
    at = total = FILE_HEADER_SIZE
    with open(path, "rb") as blf:
        while at + heads <= size:
            blf.seek(at)
            head = blf.read(heads)
            signature, _, _, obj_size, obj_type = OBJ_HEADER_BASE_STRUCT.unpack_from(head)
            if signature != b"LOBJ" or obj_size < base:
                break
            if obj_type == LOG_CONTAINER:
                total += heads + LOG_CONTAINER_STRUCT.unpack_from(head, base)[1]
            at += obj_size + obj_size % 4
    return total


def _read_back_offsets_s(path: Path) -> list[float]:
    """The stamps of the frames python-can reads back from ``path``, from the first frame's
    (the header not yet written: the reader's start is no stamp)."""
    stamps: list[float] = []
    with suppress(OSError, ValueError, EOFError, zlib.error, struct.error), \
            can.BLFReader(path) as reader:
        for msg in reader:
            stamps.append(msg.timestamp)
    return [stamp - stamps[0] for stamp in stamps]


def stopped_after(path: Path | None, handed: int) -> str:
    """What a recording stopped by a write error says it kept: ``recording stopped after N
    frames``, N the whole frames in the candump or ASC file at ``path`` (``whole_frames``).
    ``handed``, the frames its writer took, was said before: neither bound (measured under
    RLIMIT_FSIZE: 11 said where the file held 125, 2531 where it held 2500 and a cut line --
    buffered lines reach the disk, or not, after the write that failed; a ``.blf`` said 2730
    where python-can reads back 449). A log it cannot count says what ``handed`` is."""
    return said_kept(None if path is None else whole_frames(path), handed)


def said_kept(whole: int | None, handed: int) -> str:
    """``stopped_after``'s words for ``whole`` frames counted in the file (None: it cannot be
    counted, ``handed`` said as what it is)."""
    if whole is None:
        return f"recording stopped after {handed} frames handed to its writer"
    return f"recording stopped after {whole} frames"


def whole_frames(path: Path) -> int | None:
    """The data lines of the candump (``.log``) or ``.asc`` log at ``path`` that end whole (a
    cut last line, the write that failed, is cut off the file: every frame in it is good); a
    ``.blf``'s frames python-can reads back. None for another format, or an unreadable file."""
    suffix = path.suffix.lower()
    if suffix == ".blf":
        return _blf_frames(path)
    if suffix not in (".log", ".asc"):
        return None
    count = end = 0
    try:
        with open(path, "rb+") as log:
            for line in log:
                if not line.endswith(b"\n"):
                    log.truncate(end)
                    break
                end += len(line)
                count += _is_frame_line(line, suffix)
    except OSError:
        return None
    return count


def _blf_frames(path: Path) -> int | None:
    """The frames python-can reads back from the ``.blf`` at ``path``, up to where it is cut
    (its last container, cut by the write that failed, is not read)."""
    count = 0
    try:
        with can.BLFReader(path) as reader:
            for _ in reader:
                count += 1
    except (OSError, ValueError, EOFError, zlib.error, struct.error):
        if count == 0:
            return None
    return count


def _is_frame_line(line: bytes, suffix: str) -> bool:
    """A candump frame ``(stamp) channel ID#DATA``, or an ASC event with a stamp that is not
    the measurement's start."""
    if suffix == ".log":
        return line.startswith(b"(")
    head = line.split(None, 1)
    return bool(head) and head[0].replace(b".", b"", 1).isdigit() and \
        b"Start of measurement" not in line


def _path_of(writer: can.Listener) -> Path | None:
    """The file a python-can text writer writes (None for a stream without a name)."""
    name = getattr(getattr(writer, "file", None), "name", None)
    return Path(name) if isinstance(name, str) else None
