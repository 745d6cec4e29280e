"""Two sources on one ID told from the firmware's pose frames (issue #11: "two sources on one ID
are reported"), for the log's judge (whole: ``pose_streams``; streamed: ``PoseStreams.feed``).

``host.judge.sources`` tells two firmwares on one node ID when their UPTIME offsets interleave;
two firmwares powered up within ``UPTIME_MATCH_S`` of each other (two robots started together,
one candump of both buses merged) keep one offset, and were judged as one: the second one's pose
frames, refused by E2E as REPEATED, left almost every pose unmatched (the encoder frames have a
twin at every COUNTER: ``samples.twinned_encoder_frames``), so the verdict rested on one sample
and PASSed a firmware 50 mm wrong.

The pose stream tells it whatever the UPTIMEs say. One sender's Profile 2 COUNTER goes +1 a
frame, mod 16; two senders interleaved break that at nearly every frame, by the two signatures of
``host.judge.twosenders.SenderWatch`` (a COUNTER repeated with other content; a frame continuing
one of the ``RECENT`` frames before the previous one but not the previous one). One sender makes
a signature only when it restarts its COUNTER (a reboot: one each) or when 12 or more of its
frames in a row are lost (a lap: one each), so ``SIGNATURES`` within ``WINDOW_FRAMES`` CRC-right
frames of ODOM_POSE_X (``livestreams.WATCHED``, the live judges' too: 12 within 32, where two
interleaved senders make about 16 and one sender's frames delayed and reordered on the bus,
``--faults delay``, made 4 within 16: ``tests/test_live_jitter_lockout.py``) is two sources.
Exact duplicates (a frame received twice; two robots standing at the same pose) are one pose and
no signature. ODOM_POSE_Y is not watched (the live judges hear each pose message's CRC by its
own route; two firmwares whose X frames are equal while their Y differ are not told). The
encoder frames are not watched: a forger's twins there are ``twins``' business (allowed: they
must not fail a correct firmware).

The verdict is the FAIL of two sources (``reboots.mark_two_sources``, the frames from the first
signature of the window not judged); the frames before it are judged as usual."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.io.frames import FrameArrays
from odocan.host.judge.livestreams import SIGNATURES, WATCHED, WINDOW_FRAMES
from odocan.host.judge.reboots import before_two_sources, two_sources
from odocan.host.judge.samples import AnalysisError
from odocan.host.judge.sources import two_sources_text
from odocan.host.judge.twosenders import (
    COUNTER_MASK,
    FRAME_BYTES,
    NOT_A_STANDARD_DATA_FRAME,
    RECENT,
)
from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_crc import crc8h2f_p02

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec
    from odocan.host.protocol.decode import BulkDecoder


@dataclass(frozen=True)
class Conflict:
    """Where the frames of two senders of one pose message were told apart: the log position and
    bus time of the first signature of the first window with ``SIGNATURES``."""

    position: int
    t_s: float
    message: str


@dataclass
class _Stream:
    """One watched message: its E2E DataIDs and the tail carried to the next chunk."""

    name: str
    data_ids: npt.NDArray[np.uint8]
    tail: npt.NDArray[np.uint8]  # the latest RECENT + 1 CRC-right frames' bytes
    flags: npt.NDArray[np.bool_]  # the latest WINDOW_FRAMES - 1 frames' signatures
    where: npt.NDArray[np.int64]  # their log positions
    times_s: npt.NDArray[np.float64]  # their bus times
    heard: int = 0  # CRC-right frames heard
    signatures: int = 0


class PoseStreams:
    """The watch over a log read in chunks, in bus order (module docstring)."""

    def __init__(self, db: DatabaseSpec) -> None:
        self._streams = {m.key: _Stream(m.name, np.asarray(m.data_ids, dtype=np.uint8),
                                        np.zeros((0, FRAME_BYTES), dtype=np.uint8),
                                        np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64),
                                        np.zeros(0))
                         for m in e2e_messages(db).values()
                         if m.name in WATCHED and m.data_ids is not None}
        self._offset = 0
        self.conflict: Conflict | None = None

    def feed(self, frames: FrameArrays) -> None:
        """The next chunk of the log."""
        for key, stream in self._streams.items():
            rows = np.flatnonzero((frames.can_id == key) & (frames.dlc == FRAME_BYTES)
                                  & ((frames.flags & NOT_A_STANDARD_DATA_FRAME) == 0))
            data = np.ascontiguousarray(frames.data[rows, :FRAME_BYTES], dtype=np.uint8)
            good = crc8h2f_p02(data, stream.data_ids[data[:, 1] & COUNTER_MASK]) == data[:, 0]
            rows = rows[good]
            self._take(stream, data[good], rows + self._offset, frames.timestamp_s[rows])
        self._offset += len(frames)

    def _take(self, stream: _Stream, data: npt.NDArray[np.uint8], where: npt.NDArray[np.int64],
              t_s: npt.NDArray[np.float64]) -> None:
        """One message's CRC-right frames of a chunk: their signatures, the first full window
        (with the frames carried from the chunk before)."""
        if len(data) == 0:
            return
        flags = signatures(np.concatenate((stream.tail, data)))[len(stream.tail):]
        stream.heard += len(data)
        stream.signatures += int(np.count_nonzero(flags))
        all_flags = np.concatenate((stream.flags, flags))
        all_where = np.concatenate((stream.where, where))
        all_t_s = np.concatenate((stream.times_s, t_s))
        first = first_full_window(all_flags)
        if first is not None and (self.conflict is None
                                  or int(all_where[first]) < self.conflict.position):
            self.conflict = Conflict(int(all_where[first]), float(all_t_s[first]), stream.name)
        stream.tail = np.concatenate((stream.tail, data))[-(RECENT + 1):]
        keep = WINDOW_FRAMES - 1
        stream.flags, stream.where, stream.times_s = (
            all_flags[-keep:], all_where[-keep:], all_t_s[-keep:])

    def counts(self) -> tuple[int, int]:
        """(signatures, CRC-right frames heard) of the message the conflict was told on."""
        name = self.conflict.message if self.conflict is not None else WATCHED[0]
        stream = next((s for s in self._streams.values() if s.name == name), None)
        return (0, 0) if stream is None else (stream.signatures, stream.heard)

    def told(self) -> tuple[int, float, str] | None:
        """The conflict's (log position, bus time, ``detail``); None: one sender so far."""
        return None if self.conflict is None else (self.conflict.position, self.conflict.t_s,
                                                   self.detail())

    def detail(self) -> str:
        """The verdict's reason (a conflict was told)."""
        assert self.conflict is not None
        found, heard = self.counts()
        return (f"two sources on one ID: two {self.conflict.message} streams interleave from "
                f"t={self.conflict.t_s:.3f} s ({found} of its {heard} CRC-right frames break one "
                "sender's E2E COUNTER sequence): whose pose each frame is cannot be told, the pose "
                "cannot be judged")


def signatures(data: npt.NDArray[np.uint8]) -> npt.NDArray[np.bool_]:
    """Which of the frames (8 bytes each, in bus order) show a second sender against the ones
    before them (``twosenders.SenderWatch._signature``, vectorised): a COUNTER repeated with
    other bytes, or one continuing a frame 2 to ``RECENT`` + 1 back but not the previous one."""
    counter = (data[:, 1] & COUNTER_MASK).astype(np.int64)
    flags = np.zeros(len(data), dtype=bool)
    if len(data) < 2:
        return flags
    now, before = counter[1:], counter[:-1]
    repeated = (now == before) & (data[1:] != data[:-1]).any(axis=1)
    stepped = now == (before + 1) & COUNTER_MASK
    continues = np.zeros(len(now), dtype=bool)
    for back in range(2, min(RECENT + 2, len(data))):
        earlier = np.full(len(now), -1, dtype=np.int64)
        earlier[back - 1:] = counter[:len(counter) - back]
        continues |= (earlier >= 0) & (now == (earlier + 1) & COUNTER_MASK)
    flags[1:] = repeated | ((now != before) & ~stepped & continues)
    return flags


def first_full_window(flags: npt.NDArray[np.bool_]) -> int | None:
    """The first signature of the first ``WINDOW_FRAMES`` frames holding ``SIGNATURES``."""
    count = np.cumsum(flags, dtype=np.int64)
    lagged = np.concatenate((np.zeros(WINDOW_FRAMES, dtype=np.int64), count))[:len(count)]
    full = count - lagged >= SIGNATURES  # the window ending at each frame
    if not full.any():
        return None
    start = max(0, int(np.argmax(full)) - WINDOW_FRAMES + 1)
    return start + int(np.argmax(flags[start:]))


def pose_streams(frames: FrameArrays, db: DatabaseSpec) -> PoseStreams:
    """The watch over a whole log."""
    streams = PoseStreams(db)
    streams.feed(frames)
    return streams


def one_source_cut(frames: FrameArrays, decoder: BulkDecoder, db: DatabaseSpec
                   ) -> tuple[int, float, str] | None:
    """Where the frames of one source end in a whole log, the earlier of the two tellings (two
    UPTIME offsets: ``reboots.two_sources``, cut at ``before_two_sources``; two pose streams:
    ``pose_streams``, cut at the conflict): (cut, bus time, the verdict's reason); None when the
    log has one source at a time. Raises ``AnalysisError`` when no frame comes before it."""
    uptime = two_sources(frames, decoder)
    streams = pose_streams(frames, db)
    told = streams.conflict
    if uptime is not None:
        cut = before_two_sources(frames, decoder, uptime)
        if told is None or cut <= told.position:
            return cut, uptime[1], two_sources_text(uptime[1])
    if told is None:
        return None
    if told.position == 0:
        raise AnalysisError(f"{streams.detail()}, from the log's start")
    return told.position, told.t_s, streams.detail()
