"""The firmware's stalls chunk by chunk (issue #14.1): ``host.judge.stalls.after_stalls`` over
the on-board samples as ``host.judge.stream.StreamPoses`` gives them out (in encoder order).

``after_stalls`` looks at the samples in the order they were sent (ODOM_POSE_Y's time, ties
in encoder order): a sample sent ``SILENCE_CYCLES`` cycles or more after the one before while
``SILENCE_CYCLES - 1`` or more accepted encoder frames were logged between the two (counted by
time: ``searchsorted`` on their timestamps) is left out, and the reference's position restarts
at the encoder frame after the one before. Here the samples wait in a buffer until no sample
to come can have been sent before them: the caller gives a watermark (the earliest time of a
pose frame ``StreamPoses`` still holds, and the chunk's last frame time); they are then taken
in send order with the last one taken carried, and given out again in encoder order once every
sample before them is decided.

``exact`` says whether the result is the whole log's: it is unless a sample sent before one
already taken arrives later, an encoder frame arrives older than a sample already taken, or
the encoder frames' timestamps go back (then the whole log's ``searchsorted`` itself counts on
an unsorted array); a log whose frames are in time order never does that (the awkward test log,
with frames swapped and repeated, does not either). A streamed analysis that finds a log not
exact must say so or fall back to the whole log."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from odocan.host.judge.breaks import (
    MAX_MERGE_FRAMES,
    merge_allowance_m,
    overlap_allowance_m,
    path_bound_m,
)
from odocan.host.judge.gapbound import period_bounds
from odocan.host.judge.gapseen import NOTHING, Seen
from odocan.host.judge.lossgate import Gate, gated_counts
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound, wrap_delta
from odocan.host.judge.samples import SILENCE_CYCLES, Encoders
from odocan.host.judge.spanfill import filled_span_allowance_m
from odocan.host.judge.stalls import frozen_breaks, quiet_in, silent

COLUMNS = ("enc", "x_m", "y_m", "heading_rad", "heading_raw", "seq")


def _empty() -> dict[str, np.ndarray]:
    return {"enc": np.zeros(0, dtype=np.int64), "x_m": np.zeros(0), "y_m": np.zeros(0),
            "heading_rad": np.zeros(0), "heading_raw": np.zeros(0, dtype=np.int64),
            "seq": np.zeros(0, dtype=np.int64)}


def _cat(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: np.concatenate((a[k], b[k])) for k in a}


@dataclass
class StreamStalls:
    """``after_stalls`` chunk by chunk (module docstring); ``cycle_s``: the encoder cycle
    (None: no stall is found, as in the whole log)."""

    cycle_s: float | None
    exact: bool = True
    _buffer: dict[str, np.ndarray] = field(default_factory=_empty)  # not yet taken
    _sent: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    _decided: dict[str, np.ndarray] = field(default_factory=_empty)  # kept, not given out
    _enc_t: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    _enc_before: int = 0  # encoder frames dropped from _enc_t (all before the last taken)
    _last_enc_t: float = -np.inf
    _prev: tuple[float, int, int] | None = None  # last taken: sent, enc, encoders before it
    _pose_t: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))  # ODOM_POSE_Y
    _breaks: set[int] = field(default_factory=set)
    _last_given: tuple[int, int, float] | None = None  # the last given out: enc, seq, sent
    named_again: set[int] | None = None  # frames named again (StreamPoses'), None: every one
    _sent_of: dict[int, float] = field(default_factory=dict)  # a sample's send time, by enc
    _quiet: list[tuple[float, float]] = field(default_factory=list)  # pose silences (s, s)
    _last_pose_t: float = np.nan  # the last pose time fed (a silence across chunks)

    def feed(
        self, samples: dict[str, np.ndarray], sent_s: npt.NDArray[np.float64],
        encoder_t_s: npt.NDArray[np.float64], watermark_s: float,
        pose_t_s: npt.NDArray[np.float64] | None = None,
    ) -> dict[str, np.ndarray]:
        """Take samples (``StreamPoses``' output: columns and send times), the chunk's accepted
        encoder frames' times and its accepted ODOM_POSE_Y frames' times (the silence before a
        sample is counted from the last pose the firmware sent, a sample or not); returns the
        samples kept that are final, in encoder order. No sample to come may have been sent
        before ``watermark_s``."""
        if pose_t_s is not None and len(pose_t_s):
            if (len(self._pose_t) and pose_t_s[0] < self._pose_t[-1]) or np.any(
                    np.diff(pose_t_s) < 0) or (self._prev is not None
                                               and float(pose_t_s[0]) < self._prev[0]):
                self.exact = False  # the whole log's searchsorted on them: unsorted, or late
            self._pose_t = np.concatenate((self._pose_t, pose_t_s))
            if self.cycle_s is not None:  # stalls.quiet_between's silences, as they come
                times = np.r_[self._last_pose_t, pose_t_s]
                gap = np.flatnonzero(np.diff(times) >= (SILENCE_CYCLES - 0.5) * self.cycle_s)
                self._quiet += zip(times[gap].tolist(), times[gap + 1].tolist(), strict=True)
                self._last_pose_t = float(pose_t_s[-1])
        if len(encoder_t_s):
            if encoder_t_s[0] < self._last_enc_t or np.any(np.diff(encoder_t_s) < 0):
                self.exact = False
            if self._prev is not None and float(encoder_t_s[0]) < self._prev[0]:
                self.exact = False  # a count already taken would have included it
            self._last_enc_t = float(encoder_t_s[-1])
            self._enc_t = np.concatenate((self._enc_t, encoder_t_s))
        if self._prev is not None and len(sent_s) and float(np.min(sent_s)) < self._prev[0]:
            self.exact = False  # sent before a sample already taken
        self._buffer = _cat(self._buffer, {k: samples[k] for k in COLUMNS})
        self._sent_of.update(zip(samples["enc"].tolist(), sent_s.tolist(), strict=True))
        self._sent = np.concatenate((self._sent, sent_s))
        self._take(self._sent < watermark_s)
        return self._give()

    def finish(self) -> dict[str, np.ndarray]:
        """The samples kept that are left."""
        self._take(np.ones(len(self._sent), dtype=bool))
        return self._give()

    @property
    def breaks(self) -> npt.NDArray[np.int64]:
        """The encoder frames where the firmware resumed after a stall (sorted)."""
        return np.array(sorted(self._breaks), dtype=np.int64)

    def _take(self, ready: npt.NDArray[np.bool_]) -> None:
        """Decide the ``ready`` samples of the buffer, in send order."""
        if not ready.any():
            return
        part = {k: v[ready] for k, v in self._buffer.items()}
        sent = self._sent[ready]
        self._buffer = {k: v[~ready] for k, v in self._buffer.items()}
        self._sent = self._sent[~ready]
        order = np.lexsort((part["enc"], sent))
        sent, enc = sent[order], part["enc"][order]
        drop = np.zeros(len(sent), dtype=bool)
        if self.cycle_s is not None:
            heard_to = self._enc_before + np.searchsorted(self._enc_t, sent)
            if self._prev is not None:
                p_sent, p_enc, _ = self._prev
                all_sent = np.concatenate(([p_sent], sent))
                all_enc = np.concatenate(([p_enc], enc))
            else:
                all_sent, all_enc = sent, enc
            talked = all_sent[:-1]  # stalls.after_stalls: from the last pose sent before
            if len(self._pose_t):
                k = np.searchsorted(self._pose_t, all_sent[1:], side="left") - 1
                talked = np.maximum(talked, np.where(k >= 0, self._pose_t[np.maximum(k, 0)],
                                                     -np.inf))
            heard = (self._enc_before + np.searchsorted(self._enc_t, all_sent[1:])
                     - (self._enc_before + np.searchsorted(self._enc_t, talked)))
            after = np.flatnonzero(silent(all_sent[1:] - talked, heard, self.cycle_s)) + 1
            self._breaks.update((all_enc[after - 1] + 1).tolist())
            shift = 0 if self._prev is None else 1
            drop[after - shift] = True
            self._prev = (float(sent[-1]), int(enc[-1]), int(heard_to[-1]))
            gone = int(np.searchsorted(self._enc_t, sent[-1]))
            self._enc_before += gone
            self._enc_t = self._enc_t[gone:]
            self._pose_t = self._pose_t[max(int(np.searchsorted(self._pose_t, sent[-1])) - 1, 0):]
        kept = order[~drop]
        self._decided = _cat(self._decided, {k: v[kept] for k, v in part.items()})

    def _give(self) -> dict[str, np.ndarray]:
        """The decided samples before every sample still waiting, in encoder order."""
        limit = int(np.min(self._buffer["enc"])) if len(self._buffer["enc"]) else None
        order = np.argsort(self._decided["enc"], kind="stable")
        decided = {k: v[order] for k, v in self._decided.items()}
        n = (len(order) if limit is None
             else int(np.searchsorted(decided["enc"], limit)))
        out = {k: v[:n] for k, v in decided.items()}
        self._decided = {k: v[n:] for k, v in decided.items()}
        self._frozen(out)
        return out

    def _frozen(self, given: dict[str, np.ndarray]) -> None:
        """``stalls._frozen`` over the samples given out (in encoder order), the last one
        before carried in front: where the firmware held its pose, a break."""
        if self.cycle_s is None or len(given["enc"]) == 0:
            return
        enc, seq = given["enc"], given["seq"]
        if self._last_given is not None:
            enc, seq = np.r_[self._last_given[0], enc], np.r_[self._last_given[1], seq]
        sent = np.array([self._sent_of.pop(e, np.nan) for e in enc.tolist()])
        if self._last_given is not None:
            sent[0] = self._last_given[2]
        evidence = None
        if self.named_again is not None:  # stalls.hold_evidence
            again = np.array([e in self.named_again for e in enc[:-1].tolist()], dtype=bool)
            quiet = np.array(self._quiet, dtype=np.float64).reshape(-1, 2)
            evidence = again | quiet_in(sent[:-1], sent[1:], quiet[:, 0], quiet[:, 1],
                                         self.cycle_s)
        self._breaks.update(frozen_breaks(enc, seq, evidence=evidence).tolist())
        self._last_given = (int(enc[-1]), int(seq[-1]), float(sent[-1]))


@dataclass
class StreamBreakCounts:
    """``breakspan.break_allowance`` of every break after e0 (``breaks``, sorted), from
    two passes over a life: the first tells each break the first kept sample at or after it
    (``named``, the samples in encoder order, as often as asked: the same answer); the second
    feeds the encoder frames (``feed``, from the life's first), of which only those from the
    frame before each break to that sample are kept (or, for a span beyond
    ``breaks.MAX_MERGE_FRAMES``, only the sums of their steps' absolute counts, exact in any
    chunking); ``allowance`` then gives ``breaks.merge_allowance_m`` bit for bit (plus
    ``breaks.overlap_allowance_m`` from the span's ends, as ``breakspan.break_allowance``)."""

    breaks: list[int]
    geometry: Geometry
    bits: int
    integrator: str
    max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED  # a gap in a span's bound
    _ends: dict[int, int] = field(default_factory=dict)  # break -> the first sample after
    _edges: dict[int, dict[int, tuple[int, int, int]]] = field(default_factory=dict)  # seq, l, r
    _count: int = 0  # encoder frames fed
    _left: dict[int, list[np.ndarray]] = field(default_factory=dict)
    _right: dict[int, list[np.ndarray]] = field(default_factory=dict)
    _seq: dict[int, list[np.ndarray]] = field(default_factory=dict)
    _sums: dict[int, list[int]] = field(default_factory=dict)  # |dl|, |dr| sums, last l, r
    _gates: dict[int, Gate | None] = field(default_factory=dict)  # a long span's gate state

    def named(self, sample_enc: npt.NDArray[np.int64]) -> None:
        """Kept samples' encoder frames (in encoder order over the passes)."""
        if len(sample_enc) == 0:
            return
        for b in self.breaks:
            if b in self._ends:
                continue
            k = int(np.searchsorted(sample_enc, b))
            if k < len(sample_enc):
                self._ends[b] = int(sample_enc[k])

    def feed(self, enc: Encoders) -> None:
        """The life's next accepted encoder frames (after every ``named``)."""
        lo, hi = self._count, self._count + len(enc.index)
        self._count = hi
        for b, j in self._ends.items():
            a0, a1 = max(b - 1, lo), min(j + 1, hi)
            if a1 <= a0:
                continue
            for at in (b - 1, j):  # the span's ends: a gap within it (overlap_allowance_m)
                if a0 <= at < a1:
                    self._edges.setdefault(b, {})[at] = (
                        int(enc.seq[at - lo]), int(enc.left[at - lo]), int(enc.right[at - lo]))
            left = enc.left[a0 - lo : a1 - lo].astype(np.int64)
            right = enc.right[a0 - lo : a1 - lo].astype(np.int64)
            seq = enc.seq[a0 - lo : a1 - lo].astype(np.int64)
            if j - (b - 1) - 1 <= MAX_MERGE_FRAMES:
                self._left.setdefault(b, []).append(left)
                self._right.setdefault(b, []).append(right)
                self._seq.setdefault(b, []).append(seq)
                continue
            left, right, self._gates[b] = gated_counts(  # the firmware's counts, as whole
                left, right, seq, period_bounds(self.geometry), self.bits, self._gates.get(b))
            sums = self._sums.get(b)
            if sums is not None:
                left, right = np.r_[sums[2], left], np.r_[sums[3], right]
            else:
                sums = self._sums[b] = [0, 0, 0, 0]
            sums[0] += int(np.sum(np.abs(wrap_delta(np.diff(left), self.bits))))
            sums[1] += int(np.sum(np.abs(wrap_delta(np.diff(right), self.bits))))
            sums[2], sums[3] = int(left[-1]), int(right[-1])

    def allowance(self, b: int, seen: Seen = NOTHING,
                  reprimed: frozenset[int] = frozenset()) -> float:
        """The allowance (m) of the break at encoder frame ``b`` (0 without a sample after,
        and where the firmware's pages prove it took exactly the log's frames across it:
        ``seen``, ``breakspan.seen_whole``)."""
        if b in self._ends and seen.took_all(b - 1, self._ends[b], reprimed):
            return 0.0
        if b in self._sums:
            merged = path_bound_m(self._sums[b][0], self._sums[b][1], self.geometry)
        elif b in self._left:
            left, right = np.concatenate(self._left[b]), np.concatenate(self._right[b])
            seq = np.concatenate(self._seq[b])
            filled = filled_span_allowance_m(  # the log fills its gaps: spanfill
                left, right, seq, lambda k: seen.filled(b - 1 + k, reprimed), self.geometry,
                self.bits, self.integrator, self.max_wheel_speed_mm_s)
            if filled is not None:
                return filled
            merged = merge_allowance_m(left, right, self.geometry, self.bits, self.integrator,
                                       seq)
        else:
            return 0.0
        j, edges = self._ends[b], self._edges[b]
        return merged + overlap_allowance_m(edges[b - 1], edges[j], j - b + 2, self.geometry,
                                            self.bits, self.integrator, self.max_wheel_speed_mm_s)
