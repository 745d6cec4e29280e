"""The first stages of the analysis over a log given chunk by chunk (``host.io.logs.iter_log``),
with their state carried across chunk boundaries, so that the result is the whole log's.

* ``StreamE2E``: AUTOSAR E2E Profile 2 (``host.protocol.e2e.check_frames``) a chunk at a time:
  the same counts and the same accepted frames as one check of the whole log. The state of one
  message is the tail of its frames from its last accepted one on (usually that one frame: the
  sequence check of a frame depends only on the frames of its ID since the last accepted one,
  and on the time since the previous frame of its ID); the tail is checked again in front of
  the next chunk and its own verdicts taken off (``counts(tail + chunk) - counts(tail)``).
* ``StreamEncoders``: the accepted WHEEL_ENCODERS frames and their place in the sender's sequence
  (``host.judge.samples.encoder_frames``: the COUNTER unwrapped, widened by 16 where the
  timestamps say more periods passed), carried by the last accepted frame's COUNTER, time and
  sequence number: the integer sequence numbers are those of the whole log.

Positions (``index``) are positions in the whole log (frames before the chunk counted).

Not done yet (issue #14.1): the later stages (alignment, reference, comparison) still take the
whole log, so ``odocan analyze`` still holds every frame (1 GB candump log: 2.5 GB max RSS,
``bench/analyze_memory.py``). The plan for them, so that a one-chunk run and an n-chunk run give
the same report bit for bit:

* carried state: the last 16 accepted encoder frames (ENC_COUNTER resolves -8..+7 from the
  latest), the unpaired pose halves and the encoder frames already paired (first of each), the
  last sample's send time (stalls), the refusal state machine of ``reference_path._refusals``,
  the integrator's last pose (``np.cumsum`` over the carried value followed by the chunk is
  the whole log's cumsum, element for element), the truth samples waiting for the next on-board
  one (``compare.onboard_at``), the last two twist frames and their step-speed window;
* the whole-log quantities of the start fit: max/min of the heading overlap and of each
  segment's position overlap are exact in any order; the rotation fit's sums (and the segment
  means) are not, so they are to be summed in fixed blocks of samples aligned on the sample
  number (a block's partial sum is complete only when its last sample arrives; the blocks are
  then added in order): the same additions whatever the chunking;
* passes over the file (``iter_log`` again): 1. samples, reference increments, overlaps -> the
  start heading of the overlap; 2. the rotation fit and the segment offsets; 3. errors, truth,
  twist, report; plot series decimated or written to disk.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cantools
import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays, concat_frames, empty_frames
from odocan.host.judge.samples import Encoders, contract_cycle_s
from odocan.host.protocol.decode import BulkDecoder, frame_keys
from odocan.host.protocol.e2e import check_frames, e2e_messages

Counts = dict[str, dict[str, int]]


def _add(total: Counts, part: Counts, sign: int = 1) -> None:
    """``total += sign * part``, per section and key."""
    for name, counts in part.items():
        into = total.setdefault(name, dict.fromkeys(counts, 0))
        for key, value in counts.items():
            into[key] = into.get(key, 0) + sign * value


@dataclass
class StreamE2E:
    """``check_frames`` over a log fed chunk by chunk (module docstring)."""

    db: cantools.database.can.Database
    counts: Counts = field(default_factory=dict)  # so far: ``check_frames``' first result
    _tail: FrameArrays = field(default_factory=empty_frames)

    def feed(self, chunk: FrameArrays) -> npt.NDArray[np.bool_]:
        """Check the next chunk; returns its accepted mask (the counts grow)."""
        n_tail = len(self._tail)
        both = concat_frames([self._tail, chunk]) if n_tail else chunk
        counts, accepted = check_frames(both, self.db)
        if n_tail:
            tail_counts, _ = check_frames(self._tail, self.db)
            _add(counts, tail_counts, -1)
        _add(self.counts, counts)
        self._tail = both.select(self._tails(both, accepted))
        return accepted[n_tail:]

    def _tails(self, frames: FrameArrays, accepted: npt.NDArray[np.bool_]) -> npt.NDArray[np.intp]:
        """Positions of each protected message's frames (of its DLC) from its last accepted one
        on, or its last frame when none was accepted, in bus order."""
        keys = frame_keys(frames)
        keep: list[npt.NDArray[np.intp]] = []
        for key, config in e2e_messages(self.db).items():
            if config.data_ids is None:
                continue
            of_id = np.flatnonzero((keys == key) & (frames.dlc == config.length))
            if len(of_id) == 0:
                continue
            good = np.flatnonzero(accepted[of_id])
            keep.append(of_id[int(good[-1]) if len(good) else len(of_id) - 1 :])
        if not keep:
            return np.zeros(0, dtype=np.intp)
        return np.sort(np.concatenate(keep))


@dataclass
class StreamEncoders:
    """The accepted WHEEL_ENCODERS frames of each chunk with their sequence numbers, as
    ``host.judge.samples.encoder_frames`` numbers them over the whole log."""

    decoder: BulkDecoder
    _offset: int = 0  # frames of the log before the next chunk
    _last: tuple[int, float, int] | None = None  # COUNTER, time s, seq of the last accepted

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> Encoders:
        """The chunk's accepted encoder frames (``index``: positions in the whole log)."""
        rows = self.decoder.decode(chunk, "WHEEL_ENCODERS")
        keep = accepted[rows["index"]]
        counter = rows["COUNTER"][keep].astype(np.int64)
        stamps = rows["timestamp_s"][keep]
        cycle_s = contract_cycle_s(self.decoder, "WHEEL_ENCODERS")
        seq = self._numbered(counter, stamps, cycle_s)
        encoders = Encoders(
            index=rows["index"][keep] + self._offset, counter=counter, seq=seq,
            left=rows["LEFT_COUNT"][keep].astype(np.int64),
            right=rows["RIGHT_COUNT"][keep].astype(np.int64),
            timestamp_s=stamps, cycle_s=cycle_s,
        )
        self._offset += len(chunk)
        if len(counter):
            self._last = (int(counter[-1]), float(stamps[-1]), int(seq[-1]))
        return encoders

    def _numbered(
        self, counter: npt.NDArray[np.int64], stamps: npt.NDArray[np.float64],
        cycle_s: float | None,
    ) -> npt.NDArray[np.int64]:
        """Sequence numbers, continuing from the last accepted frame of the chunks before."""
        if self._last is not None:
            counter = np.concatenate(([self._last[0]], counter))
            stamps = np.concatenate(([self._last[1]], stamps))
        step = (np.diff(counter) & 0xF).astype(np.int64)
        if cycle_s is not None and len(step):
            periods = np.rint(np.diff(stamps) / cycle_s).astype(np.int64)
            step = step + 16 * np.maximum(0, np.rint((periods - step) / 16)).astype(np.int64)
        if self._last is None:
            return np.concatenate(([0], np.cumsum(step))).astype(np.int64)
        return (self._last[2] + np.cumsum(step)).astype(np.int64)
