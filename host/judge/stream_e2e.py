"""``StreamE2E``: AUTOSAR E2E Profile 2 (``host.protocol.e2e.check_frames``) over a log fed
chunk by chunk (moved out of ``host.judge.stream``, whose docstring describes it).

Exact where the stamps decide every verdict. Where the whole log's check changes a verdict of
the stamps (a starved recorder's releases, a lock-out after a late frame, a jittered capture:
``e2e_evidence``, ``e2e_pages``), it settles the encoder frames from evidence that comes after
them (the poses naming them, the next ENC_E2E page): a chunk's verdicts, given out with the
chunk, are the whole log's only where that evidence lies in the chunk (issue #11: at 97 to
1 000 frames a chunk, 3 to 67 of a starved capture's 1 439 frames judged otherwise). The
streamed analysis feeds chunks re-cut where no frame so settled lies within
``stream_carry.HORIZON_S`` of a cut (``stream_carry.carried``); ``exact`` turns False where a
frame the evidence settled (``check_frames``' ``touched``) still lies within ``HORIZON_S`` of a
chunk's start (after the first chunk) or of its end (but the log's last chunk): the carry
exceeded its horizon, or the chunks were not re-cut, and the streamed analysis refuses the log
(``NotStreamable``: the whole log's path judges it), as the other stages whose ``exact`` flag
says so.

The silences (``e2e_silence``: steps between two accepted frames, pairs, not frames) are not
taken as the difference of two checks but counted from each message's last accepted frame
given out (``StreamE2E._silences``): whatever the chunking, those of the frames accepted."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays, concat_frames, empty_frames
from odocan.host.judge.stream_carry import HORIZON_S
from odocan.host.protocol.decode import frame_keys
from odocan.host.protocol.e2e import E2EMessage, check_frames, e2e_messages
from odocan.host.protocol.e2e_silence import SILENCE_KEYS, silences

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.protocol.dbcplan import DatabaseSpec

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

    db: DatabaseSpec
    counts: Counts = field(default_factory=dict)  # so far: ``check_frames``' first result
    _tail: FrameArrays = field(default_factory=empty_frames)
    _settled: bool = False  # a frame settled by the evidence near a chunk's edge (docstring)
    _late: bool = False  # one near the latest chunk's end: inexact if another chunk comes
    _chunks: int = 0  # chunks fed
    _last_ok_s: dict[str, float] = field(default_factory=dict)  # per message: its last accepted
    # frame given out, bus time (s): the silences are counted from it (``_silences``)

    @cached_property
    def _messages(self) -> dict[int, E2EMessage]:
        """``e2e_messages(db)``, read once (three passes a chunk)."""
        return e2e_messages(self.db)

    @property
    def exact(self) -> bool:
        """Whether the verdicts given out are the whole log's: no verdict of the stamps changed
        by the evidence, or the log fed in one chunk (the whole log's check itself)."""
        return not self._settled or self._chunks <= 1

    def feed(self, chunk: FrameArrays) -> npt.NDArray[np.bool_]:
        """Check the next chunk; returns its accepted mask (the counts grow)."""
        n_tail = len(self._tail)
        both = concat_frames([self._tail, chunk]) if n_tail else chunk
        touched: list[npt.NDArray[np.intp]] = []
        counts, accepted = check_frames(both, self.db, touched=touched)
        if n_tail:
            tail_counts, _ = check_frames(self._tail, self.db)
            _add(counts, tail_counts, -1)
        for section in counts.values():  # pairs, not frames: counted by ``_silences``
            for key in SILENCE_KEYS:
                section.pop(key, None)
        self._settled = self._settled or self._near_edges(both, n_tail, touched)
        self._chunks += 1
        _add(self.counts, counts)
        keys = frame_keys(both)
        _add(self.counts, self._silences(chunk, keys[n_tail:], accepted[n_tail:]))
        self.counts = self._ordered(self.counts)
        self._tail = both.select(self._tails(both, keys, accepted))
        return accepted[n_tail:]

    def _near_edges(self, both: FrameArrays, n_tail: int,
                    touched: list[npt.NDArray[np.intp]]) -> bool:
        """Whether a frame the evidence settled (``touched``: positions in ``both``, the tail
        then the chunk) lies within ``HORIZON_S`` of this chunk's start (after the first chunk)
        or, a chunk ago, of that chunk's end: its evidence may lie in the next chunk (module
        docstring). The end is known only when the next chunk comes (the log's end: none)."""
        if len(both) == n_tail:  # no frame: the end not known yet
            return False
        late, self._late = self._late, False
        at = np.concatenate(touched) if touched else np.zeros(0, dtype=np.intp)
        if len(at) == 0:
            return late
        t_s = np.maximum.accumulate(both.timestamp_s)
        start_s = float(t_s[n_tail]) + HORIZON_S if self._chunks else -np.inf
        self._late = bool((t_s[at] > t_s[-1] - HORIZON_S).any())
        return late or bool((t_s[at] < start_s).any())

    def _silences(self, chunk: FrameArrays, keys: npt.NDArray[np.int64],
                  accepted: npt.NDArray[np.bool_]) -> Counts:
        """The silences ending in ``chunk`` (its ``frame_keys``: ``keys``) between the frames
        accepted (``accepted``: the verdicts given out), the first from the message's last
        accepted frame before it.

        Not the difference of two checks as the other counts: the tail checked alone, out of
        its context, may take frames the log refused (a late frame after its last accepted
        one), which split a silence into shorter steps (issue #11: 17 silences against 18 on
        tests/files/recorder_gap16_pmir.blf at 97 frames a chunk, the same frames accepted)."""
        heard: Counts = {}
        for key, config in self._messages.items():
            if config.data_ids is None:
                continue
            t_s = chunk.timestamp_s[(keys == key) & (chunk.dlc == config.length) & accepted]
            if len(t_s) == 0:
                continue
            last_s = self._last_ok_s.get(config.name)
            if last_s is not None:
                t_s = np.concatenate([np.array([last_s]), t_s])
            self._last_ok_s[config.name] = float(t_s[-1])
            if part := silences(t_s, config.cycle_s):
                heard[config.name] = part
        return heard

    def _ordered(self, counts: Counts) -> Counts:
        """The sections in ``check_frames``' order: messages by frame key, ``unknown`` last."""
        rank = {config.name: key for key, config in self._messages.items()}
        names = sorted((n for n in counts if n in rank), key=rank.__getitem__)
        return {n: counts[n] for n in names + [n for n in counts if n not in rank]}

    def _tails(self, frames: FrameArrays, keys: npt.NDArray[np.int64],
               accepted: npt.NDArray[np.bool_]) -> npt.NDArray[np.intp]:
        """Positions of each protected message's frames (of its DLC; ``keys``: their
        ``frame_keys``) from its last accepted one on, or its last frame when none was
        accepted, in bus order."""
        keep: list[npt.NDArray[np.intp]] = []
        for key, config in self._messages.items():
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
