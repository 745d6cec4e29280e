"""ODOM_TWIST against the reference's speeds chunk by chunk (issue #14.1):
``host.judge.compare.check_twist`` over a log fed in chunks, its result the whole log's.

``check_twist`` takes the twist frames naming an accepted encoder frame, in bus order, each at
or after every earlier one's (their encoder frames E, non-decreasing), and judges twist k >= 2
against the band of the per-step speeds over its window: the two segments (E[h-2], E[h-1]] and
(E[h-1], E[h]] of the frame h that first named its E (``compare.carried_windows``: a resend,
at any depth, has the window of its chain's head). Carried here:

* the last 16 accepted encoder frames (a twist frame names one -8..+7 from the latest before
  it, and only one before it: ``samples.match_encoder`` is causal) and the last twist frame
  (a repeat of its ENC_COUNTER names what it named: ``samples._held``, with its COUNTER);
* the per-step speeds from the last taken twist frame's encoder frame on (those no twist frame
  to come can name only as their band: min, max and widest gap are exact in any order), the
  last frame's window (its two segments' bands), and the last encoder frame (for the next
  step's speed);
* the maxima and the count of the judgments."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.compare import (
    TWIST_LSB,
    TWIST_SILENCE_S,
    _step_speeds,
    band_excess,
    carried_windows,
)
from odocan.host.judge.samples import Encoders, IntArray, _held, contract_cycle_s, match_encoder
from odocan.host.judge.stream import known_encoders
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.sim.robot import RobotProfile

# encoder frames kept: a twist frame names -8..+7 from the latest, and the one a lap before
# the frame named tells a flood (``samples.flooded_out``)
RECENT_ENCODERS = 32
KEEP_STEPS = 32  # steps kept whole below the latest encoder frame: more than a frame can name

Band = tuple[float, float, float]  # lowest, highest per-step speed, widest gap slack
EMPTY: Band = (math.inf, -math.inf, 0.0)
FloatArray = npt.NDArray[np.float64]


def _band(values: npt.NDArray[np.float64], gaps: npt.NDArray[np.float64]) -> Band:
    if len(values) == 0:
        return EMPTY
    return float(np.min(values)), float(np.max(values)), float(np.max(gaps))


def _joined(a: Encoders, b: Encoders, last: int | None = None) -> Encoders:
    """``a``'s frames then ``b``'s (``last``: only ``b``'s last ``last`` frames)."""
    if last is not None:
        return Encoders(index=b.index[-last:], counter=b.counter[-last:], seq=b.seq[-last:],
                        left=b.left[-last:], right=b.right[-last:],
                        timestamp_s=b.timestamp_s[-last:], cycle_s=b.cycle_s,
                        uptime=None if b.uptime is None else b.uptime[-last:])
    uptime = None if a.uptime is None or b.uptime is None else np.concatenate((a.uptime,
                                                                              b.uptime))
    return Encoders(
        index=np.concatenate((a.index, b.index)), counter=np.concatenate((a.counter, b.counter)),
        seq=np.concatenate((a.seq, b.seq)), left=np.concatenate((a.left, b.left)),
        right=np.concatenate((a.right, b.right)),
        timestamp_s=np.concatenate((a.timestamp_s, b.timestamp_s)), cycle_s=b.cycle_s,
        uptime=uptime)


def _join(a: tuple[Band, Band], b: tuple[Band, Band]) -> tuple[Band, Band]:
    """The bands of two sets of steps together (linear, angular)."""
    return tuple((min(x[0], y[0]), max(x[1], y[1]), max(x[2], y[2]))  # type: ignore[return-value]
                 for x, y in zip(a, b, strict=True))


@dataclass
class _Twist:
    """One twist frame whose encoder frame is known: E (number of the encoder frame in the
    log), LINEAR_VEL and ANGULAR_VEL (SI)."""

    e: int
    linear: float
    angular: float


@dataclass
class StreamTwist:
    """``check_twist`` chunk by chunk (module docstring): ``feed`` each chunk with its accepted
    mask and ``StreamEncoders``' frames, then ``finish`` for the result."""

    decoder: BulkDecoder
    robot: RobotProfile
    _offset: int = 0
    _enc_count: int = 0
    _recent: dict[str, np.ndarray] = field(default_factory=dict)  # g, index, counter, seq, t
    _pending: dict[str, np.ndarray] = field(default_factory=dict)  # this chunk's twist frames
    # the last twist frame: ENC_COUNTER, COUNTER, time, encoder frame named (-1: none), its
    # sequence number
    _last_row: tuple[int, int, float, int, int] | None = None
    _last_enc: Encoders | None = None  # the last accepted encoder frame (one element)
    _steps: dict[str, np.ndarray] = field(default_factory=dict)  # g, v, w, gap_v, gap_w
    _running_max: int = -1  # of every E named so far (-1 for a frame naming none)
    _ok: list[_Twist] = field(default_factory=list)  # the last two judged-order twist frames
    _count: int = 0  # twist frames taken (E non-decreasing)
    # the last frame's window (``compare.carried_windows``): its head's segment and the one
    # before it (linear, angular)
    _prev_band: tuple[Band, Band] = (EMPTY, EMPTY)
    _prev_a: tuple[Band, Band] = (EMPTY, EMPTY)
    _last_t: float = math.nan  # bus time of the last frame taken (s)
    _since: int = 2  # chains of resends from the last silence to the last frame (2: more)
    _folded: tuple[Band, Band] = (EMPTY, EMPTY)  # steps after the last E no longer kept
    samples: int = 0
    # told every twist frame in bus order: E (-1: none), DISTANCE raw, bus time (s)
    on_distance: Callable[[IntArray, IntArray, FloatArray], None] | None = None
    max_linear_excess_mps: float = 0.0
    max_angular_excess_rad_s: float = 0.0

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_], enc: Encoders) -> None:
        """Take the next chunk."""
        known = self._known(enc)
        self._add_steps(enc)
        try:
            rows = self.decoder.decode(chunk, "ODOM_TWIST")
        except DecodeError:
            rows = {"index": np.zeros(0, dtype=np.int64)}
        if len(rows["index"]):
            keep = accepted[rows["index"]]
            new = {"index": rows["index"][keep] + self._offset,
                   "enc_counter": rows["ENC_COUNTER"][keep].astype(np.int64),
                   "counter": rows["COUNTER"][keep].astype(np.int64),
                   "t": chunk.timestamp_s[rows["index"][keep]],
                   "linear": rows["LINEAR_VEL"][keep] * TWIST_LSB,
                   "angular": rows["ANGULAR_VEL"][keep] * TWIST_LSB,
                   "distance": rows.get("DISTANCE", np.full(len(keep), -1))[keep].astype(
                       np.int64)}
            self._pending = ({k: np.concatenate((self._pending[k], v)) for k, v in new.items()}
                             if self._pending else new)
        self._resolve(known)
        self._offset += len(chunk)
        self._enc_count += len(enc.index)
        self._recent = {k: v[-RECENT_ENCODERS:] for k, v in known.items()}
        self._trim_steps()

    def finish(self) -> dict[str, Any]:
        """The result ``check_twist`` gives for the whole log."""
        return {
            "samples": self.samples,
            "max_linear_excess_mps": self.max_linear_excess_mps,
            "max_angular_excess_rad_s": self.max_angular_excess_rad_s,
            "passed": bool(self.max_linear_excess_mps == 0.0
                           and self.max_angular_excess_rad_s == 0.0),
        }

    # --- encoder frames and their steps ---------------------------------------------------

    def _known(self, enc: Encoders) -> dict[str, np.ndarray]:
        now = {"g": self._enc_count + np.arange(len(enc.index), dtype=np.int64),
               "index": enc.index, "counter": enc.counter, "seq": enc.seq,
               "t": enc.timestamp_s}
        if not self._recent:
            return now
        return {k: np.concatenate((self._recent[k], v)) for k, v in now.items()}

    def _add_steps(self, enc: Encoders) -> None:
        """The per-step speeds into this chunk's encoder frames (``compare._step_speeds``)."""
        if len(enc.index) == 0:
            return
        window = enc if self._last_enc is None else _joined(self._last_enc, enc)
        (v, w), (gap_v, gap_w) = _step_speeds(window, self.robot, self.decoder)
        skip = 0 if self._last_enc is None else 1
        g = self._enc_count + np.arange(len(enc.index), dtype=np.int64)
        new = {"g": g, "v": v[skip:], "w": w[skip:], "gap_v": gap_v[skip:],
               "gap_w": gap_w[skip:]}
        self._steps = ({k: np.concatenate((self._steps[k], x)) for k, x in new.items()}
                       if self._steps else new)
        self._last_enc = _joined(enc, enc, last=1)

    def _trim_steps(self) -> None:
        """Keep the steps after the last taken twist frame's encoder frame; those more than
        ``KEEP_STEPS`` below the latest (no twist frame to come can name them) only as their
        band, ``_folded``."""
        if not self._steps:
            return
        g, top = self._steps["g"], self._enc_count - 1  # top: the latest encoder frame
        after = g > (self._ok[-1].e if self._ok else top)
        fold = after & (g <= top - KEEP_STEPS)
        if fold.any():
            self._folded = _join(self._folded, self._bands(fold))
        keep = (g > top - KEEP_STEPS) & (after if self._ok else True)
        self._steps = {k: v[keep] for k, v in self._steps.items()}

    def _bands(self, rows: npt.NDArray[np.bool_]) -> tuple[Band, Band]:
        s = self._steps
        return (_band(s["v"][rows], s["gap_v"][rows]), _band(s["w"][rows], s["gap_w"][rows]))

    # --- twist frames ---------------------------------------------------------------------

    def _resolve(self, known: dict[str, np.ndarray]) -> None:
        """Name the encoder frame of every waiting twist frame (``samples.match_encoder``:
        causal, so each names one in its own chunk; a repeated ENC_COUNTER carried by
        ``samples._held`` from the last frame before) and take those naming one."""
        p = self._pending
        if not p or len(p["index"]) == 0:
            return
        n = len(p["index"])
        e, seq = np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64)
        latest = np.full(n, np.iinfo(np.int64).min // 2, dtype=np.int64)
        cycle_s = contract_cycle_s(self.decoder, "WHEEL_ENCODERS")
        if len(known["seq"]):
            at = match_encoder(known_encoders(known, cycle_s), p["index"], p["enc_counter"],
                               p["t"])
            e = np.where(at >= 0, known["g"][np.maximum(at, 0)], -1).astype(np.int64)
            seq = np.where(at >= 0, known["seq"][np.maximum(at, 0)], -1).astype(np.int64)
            before = np.searchsorted(known["index"], p["index"]) - 1
            latest = np.where(before >= 0, known["seq"][np.maximum(before, 0)], latest)
        if cycle_s is not None:
            e, seq = self._held(e, seq, cycle_s)
            e = np.where((e >= 0) & (latest - seq >= ENC_COUNTER_LAP), -1, e)  # lapped_out
        if self.on_distance is not None:
            self.on_distance(e, p["distance"], p["t"])
        self._take_all(e, p["linear"], p["angular"], p["t"])
        self._pending = {}

    def _held(self, e: npt.NDArray[np.int64], seq: npt.NDArray[np.int64], cycle_s: float
              ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """``samples._held`` over the waiting frames (``e``, their sequence numbers ``seq``),
        the last frame before carried in front (its ENC_COUNTER, COUNTER, time and encoder
        frame named with its sequence number)."""
        p = self._pending
        ec, own, t = p["enc_counter"], p["counter"], p["t"]
        if self._last_row is not None:
            e0, c0, t0, n0, s0 = self._last_row
            ec, own, t = np.r_[e0, ec], np.r_[c0, own], np.r_[t0, t]
            e, seq = np.r_[n0, e], np.r_[s0, seq]
        run_start = _held(np.arange(len(e), dtype=np.int64), ec, own, t, cycle_s)
        e, seq = e[run_start], seq[run_start]
        self._last_row = (int(ec[-1]), int(own[-1]), float(t[-1]), int(e[-1]), int(seq[-1]))
        cut = len(e) - len(p["index"])
        return e[cut:], seq[cut:]

    def _take_all(self, e: npt.NDArray[np.int64], linear: FloatArray,
                  angular: FloatArray, t_s: FloatArray) -> None:
        """Twist frames naming encoder frames ``e`` (-1: none), in bus order: those at or after
        every earlier one's are taken and judged from the third on (``compare._outside_band``,
        its segments' bands from the steps kept and the band carried)."""
        if len(e) == 0:
            return
        running = np.maximum.accumulate(np.concatenate(([self._running_max], e)))[1:]
        self._running_max = int(running[-1])
        ok = (e >= 0) & (e >= running)
        e, linear, angular, t_s = e[ok], linear[ok], angular[ok], t_s[ok]
        if self._count == 0 and len(e):
            self._ok = [_Twist(int(e[0]), float(linear[0]), float(angular[0]))]
            self._count, self._last_t = 1, float(t_s[0])
            e, linear, angular, t_s = e[1:], linear[1:], angular[1:], t_s[1:]
        if len(e) == 0:
            return
        prev_e = self._ok[-1].e
        bands = self._segments(prev_e, e)  # per new frame: lo, hi, gap (linear), (angular)
        resent = np.concatenate(([False], e <= np.concatenate(([prev_e], e[:-1]))))
        head, before = carried_windows(resent)  # index 0: the frame taken before these
        zero = self._after_silence(t_s, head)
        k = self._count + np.arange(len(e))
        carried: list[tuple[tuple[FloatArray, ...], tuple[FloatArray, ...]]] = []
        for value, own, (a0, b0), best in (
            (linear, bands[0], (self._prev_a[0], self._prev_band[0]), "linear"),
            (angular, bands[1], (self._prev_a[1], self._prev_band[1]), "angular"),
        ):
            # the frame before as index 0: its own band is the window's head segment it had
            heads: tuple[FloatArray, ...] = tuple(
                np.concatenate(([x0], x)) for x0, x in zip(b0, own, strict=True))
            a: tuple[FloatArray, ...] = tuple(
                np.where(before >= 0, x[np.maximum(before, 0)], x0)[1:]
                for x, x0 in zip(heads, a0, strict=True))
            b: tuple[FloatArray, ...] = tuple(x[head][1:] for x in heads)
            carried.append((a, b))
            excess = band_excess(value, a, b, zero)
            judged = ~np.isnan(excess) & (k >= 2)
            if best == "linear":
                self.samples += int(np.count_nonzero(judged))
            if judged.any():
                top = float(np.max(excess[judged]))
                if best == "linear":
                    self.max_linear_excess_mps = max(self.max_linear_excess_mps, top)
                else:
                    self.max_angular_excess_rad_s = max(self.max_angular_excess_rad_s, top)
        self._prev_a = tuple(_last(a) for a, _ in carried)  # type: ignore[assignment]
        self._prev_band = tuple(_last(b) for _, b in carried)  # type: ignore[assignment]
        if int(e[-1]) > prev_e:
            self._folded = (EMPTY, EMPTY)  # every folded step lies before the new E
        self._ok = [_Twist(int(e[-1]), float(linear[-1]), float(angular[-1]))]
        self._count += len(e)

    def _after_silence(self, t_s: FloatArray, head: npt.NDArray[np.int64]
                       ) -> npt.NDArray[np.bool_]:
        """``compare.after_silence`` of the new frames (``head``: with the frame before as
        index 0), the chains since the last silence carried (``_since``)."""
        silent = np.diff(np.concatenate(([self._last_t], t_s))) >= TWIST_SILENCE_S
        self._last_t = float(t_s[-1])
        at = np.arange(1, len(head))
        last = np.maximum.accumulate(np.where(silent, at, 0))  # 0: none among these
        heads = np.cumsum(head == np.arange(len(head)))  # index 0 counts 1
        since = np.where(last > 0, heads[1:] - heads[last], self._since + heads[1:] - 1)
        self._since = min(int(since[-1]), 2)
        zero: npt.NDArray[np.bool_] = since <= 1
        return zero

    def _segments(
        self, prev_e: int, e: npt.NDArray[np.int64]
    ) -> tuple[tuple[FloatArray, FloatArray, FloatArray], ...]:
        """The bands (lo, hi, widest gap; linear then angular) of the steps (E before, E] of
        each new twist frame, the first from ``prev_e`` (the steps folded joining it)."""
        g = self._steps["g"]
        g0 = int(g[0]) if len(g) else prev_e + 1
        begins = np.concatenate(([prev_e], e[:-1]))
        empty = e <= begins
        starts = np.concatenate((np.maximum(begins + 1 - g0, 0), [int(e[-1]) + 1 - g0]))
        starts = np.minimum(starts, len(g))
        out = []
        for speed, gap, folded in (("v", "gap_v", self._folded[0]),
                                   ("w", "gap_w", self._folded[1])):
            values = np.concatenate((self._steps[speed], np.zeros(1)))
            gaps = np.concatenate((self._steps[gap], np.zeros(1)))
            lo = np.where(empty, np.inf, np.minimum.reduceat(values, starts)[:-1])
            hi = np.where(empty, -np.inf, np.maximum.reduceat(values, starts)[:-1])
            wide = np.where(empty, 0.0, np.maximum.reduceat(gaps, starts)[:-1])
            if not empty[0]:
                lo[0], hi[0] = min(lo[0], folded[0]), max(hi[0], folded[1])
                wide[0] = max(wide[0], folded[2])
            out.append((lo, hi, wide))
        return tuple(out)


def _last(band: tuple[FloatArray, ...]) -> Band:
    """The band of the last frame of a batch."""
    return float(band[0][-1]), float(band[1][-1]), float(band[2][-1])
