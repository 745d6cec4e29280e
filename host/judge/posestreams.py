"""Two sources on one ID told from the firmware's pose frames (issue #11: "two sources on one ID
are reported"), for the log's judges (whole: ``pose_streams``; streamed: ``PoseStreams.feed``;
replay): the CRC-right ODOM_POSE_X frames, in the log's order, through the rule of
``host.judge.livestreams`` (``TwinWatch``: its docstring derives it), the live judges' too.

``host.judge.sources`` tells two firmwares on one node ID when their UPTIME offsets interleave;
two firmwares powered up within ``UPTIME_MATCH_S`` of each other (two robots started together,
one candump of both buses merged) keep one offset, and were judged as one: the second one's pose
frames, refused by E2E as REPEATED, left almost every pose unmatched, so the verdict rested on
one sample and PASSed a firmware 50 mm wrong (the outside trial). The pose frames tell it
whatever the UPTIMEs say: the same COUNTER with other bytes within 200 ms, in 32 of 48 pose
periods, which two senders at one rate always make and one sender never (reordered by delays
under 120 ms, duplicated, resent, released after a bus-off, rebooted: ``livestreams``). A
signature of COUNTER order (a frame continuing one 2-4 frames back), as first tried, told one
firmware's frames reordered by ``--faults delay=0.2:30`` as two (``tests/test_one_sender_is_one``).

The verdict is the FAIL of two sources (``reboots.mark_two_sources``; the frames from the
earlier frame of the first pair of the span that told it are not judged); the frames before it
are judged as usual. A FAIL, not UNJUDGED: it is the verdict two firmwares told by UPTIME already
get (one fact, one verdict, the monitor's CONFLICT, the bridge's and fleet's FAIL), the log is
wrong for a judge of one firmware (a setup to fix, as a CI step must see), and its reason names
the two sources and no firmware's pose (none is judged from there: it blames neither). ``odocan
replay`` says UNJUDGED (exit 1) instead: it judges a replayed firmware against the log's poses,
and cannot say whose they are."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from odocan.host.io.frames import FrameArrays
from odocan.host.judge.livestreams import WATCHED, TwinWatch, detail_text, pose_told_first
from odocan.host.judge.reboots import before_two_sources, two_sources
from odocan.host.judge.samples import AnalysisError
from odocan.host.judge.sources import two_sources_text
from odocan.host.judge.twosenders import COUNTER_MASK, FRAME_BYTES, NOT_A_STANDARD_DATA_FRAME
from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_crc import crc8h2f_p02

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec
    from odocan.host.protocol.decode import BulkDecoder


class PoseStreams:
    """The watch over a log read in chunks, in the log's order (module docstring)."""

    def __init__(self, db: DatabaseSpec) -> None:
        self._streams = {m.key: (m.name, np.asarray(m.data_ids, dtype=np.uint8), TwinWatch())
                         for m in e2e_messages(db).values()
                         if m.name in WATCHED and m.data_ids is not None}
        self._offset = 0

    def feed(self, frames: FrameArrays) -> None:
        """The next chunk of the log: its CRC-right frames of the watched messages, heard."""
        for key, (_, data_ids, watch) in self._streams.items():
            rows = np.flatnonzero((frames.can_id == key) & (frames.dlc == FRAME_BYTES)
                                  & ((frames.flags & NOT_A_STANDARD_DATA_FRAME) == 0))
            data = np.ascontiguousarray(frames.data[rows, :FRAME_BYTES], dtype=np.uint8)
            good = crc8h2f_p02(data, data_ids[data[:, 1] & COUNTER_MASK]) == data[:, 0]
            watch.hear_block(data[good], frames.timestamp_s[rows[good]],
                             (rows[good] + self._offset).astype(np.int64))
        self._offset += len(frames)

    def _told(self) -> tuple[str, TwinWatch] | None:
        """The message (and its watch) that told two sources first in the log."""
        told = [(watch.told[1], name, watch) for name, _, watch in self._streams.values()
                if watch.told is not None]
        return None if not told else min(told, key=lambda t: t[0])[1:]

    def told(self) -> tuple[int, float, str] | None:
        """Two sources: (log position, bus time, the verdict's reason); None: one sender."""
        found = self._told()
        if found is None:
            return None
        name, watch = found
        assert watch.told is not None
        t_s, position = watch.told
        return position, t_s, detail_text(name, t_s, watch.paired, watch.heard)


def pose_streams(frames: FrameArrays, db: DatabaseSpec) -> PoseStreams:
    """The watch over a whole log."""
    streams = PoseStreams(db)
    streams.feed(frames)
    return streams


def one_source_cut(frames: FrameArrays, decoder: BulkDecoder, db: DatabaseSpec
                   ) -> tuple[int, float, str] | None:
    """Where the frames of one source end in a whole log: two UPTIME offsets
    (``reboots.two_sources``, cut at ``before_two_sources``), else, or where they come well
    before it (``livestreams.pose_told_first``), two pose streams (``pose_streams``, cut at the
    pair the span began with): (cut, bus time, the verdict's reason); None when the log has one
    source at a time. Raises ``AnalysisError`` when no frame
    comes before it."""
    uptime = two_sources(frames, decoder)
    told = pose_streams(frames, db).told()
    if uptime is not None:
        cut = before_two_sources(frames, decoder, uptime)
        if told is None or not pose_told_first(told[1], uptime[1]):
            return cut, uptime[1], two_sources_text(uptime[1])
    if told is None:
        return None
    if told[0] == 0:
        raise AnalysisError(f"{told[2]}, from the log's start")
    return told
