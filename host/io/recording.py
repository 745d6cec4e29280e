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
from pathlib import Path
from typing import cast

import can
from can.io.asc import ASCWriter
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
        (``stopped_after``)."""
        try:
            self.writer.stop()
        except OSError as exc:
            self.failure = self.failure or exc
        if self.failure is not None:
            reason = self.failure.strerror or str(self.failure)
            stopped = stopped_after(_path_of(self.writer), self.frames)
            raise OSError(self.failure.errno, f"{reason} ({stopped})")


def stopped_after(path: Path | None, handed: int) -> str:
    """What a recording stopped by a write error says it kept: ``recording stopped after N
    frames``, N the whole frames in the candump or ASC file at ``path`` (``whole_frames``).
    ``handed``, the frames its writer took, was said before: neither bound (measured under
    RLIMIT_FSIZE: 11 said where the file held 125, 2531 where it held 2500 and a cut line --
    buffered lines reach the disk, or not, after the write that failed; a ``.blf`` said 2730
    where python-can reads back 449). A log it cannot count says what ``handed`` is."""
    whole = None if path is None else whole_frames(path)
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
