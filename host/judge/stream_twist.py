"""ODOM_TWIST against the reference's speeds chunk by chunk (issue #14.1):
``host.judge.compare.check_twist`` over a log fed in chunks, its result the whole log's.

``check_twist`` takes the twist frames naming an accepted encoder frame, in bus order, each at
or after every earlier one's (their encoder frames E, non-decreasing), and judges twist k >= 2
against the band of the per-step speeds over the two segments (E[k-2], E[k-1]] and
(E[k-1], E[k]]. Carried here:

* the last 16 accepted encoder frames (a twist frame names one -8..+7 from the latest before
  it) and the twist frames naming one the log has not reached yet (they wait, and the later
  ones with them: the order matters);
* the per-step speeds from the last taken twist frame's encoder frame on (those no twist frame
  to come can name only as their band: min, max and widest gap are exact in any order), the
  previous segment's band, and the last encoder frame (for the next step's speed);
* the maxima and the count of the judgments."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.compare import TWIST_LSB, TWIST_RANGE, TWIST_RELATIVE, _step_speeds
from odocan.host.judge.samples import Encoders, contract_cycle_s
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.sim.robot import RobotProfile

RECENT_ENCODERS = 16  # encoder frames kept: a twist frame names -8..+7 from the latest
KEEP_STEPS = 32  # steps kept whole below the latest encoder frame: more than a frame can name

Band = tuple[float, float, float]  # lowest, highest per-step speed, widest gap slack
EMPTY: Band = (math.inf, -math.inf, 0.0)
Judgment = tuple[float, float] | None  # linear and angular excess; None: not judged


def _band(values: npt.NDArray[np.float64], gaps: npt.NDArray[np.float64]) -> Band:
    if len(values) == 0:
        return EMPTY
    return float(np.min(values)), float(np.max(values)), float(np.max(gaps))


def _joined(a: Encoders, b: Encoders, last: int | None = None) -> Encoders:
    """``a``'s frames then ``b``'s (``last``: only ``b``'s last ``last`` frames)."""
    if last is not None:
        return Encoders(index=b.index[-last:], counter=b.counter[-last:], seq=b.seq[-last:],
                        left=b.left[-last:], right=b.right[-last:],
                        timestamp_s=b.timestamp_s[-last:], cycle_s=b.cycle_s)
    return Encoders(
        index=np.concatenate((a.index, b.index)), counter=np.concatenate((a.counter, b.counter)),
        seq=np.concatenate((a.seq, b.seq)), left=np.concatenate((a.left, b.left)),
        right=np.concatenate((a.right, b.right)),
        timestamp_s=np.concatenate((a.timestamp_s, b.timestamp_s)), cycle_s=b.cycle_s)


def _join(a: tuple[Band, Band], b: tuple[Band, Band]) -> tuple[Band, Band]:
    """The bands of two sets of steps together (linear, angular)."""
    return tuple((min(x[0], y[0]), max(x[1], y[1]), max(x[2], y[2]))  # type: ignore[return-value]
                 for x, y in zip(a, b, strict=True))


def _excess(value: float, a: Band, b: Band) -> float | None:
    """``compare._outside_band`` of one value over segments ``a`` then ``b``; None: unknown."""
    lo, hi = min(a[0], b[0]), max(a[1], b[1])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return None
    lo, hi = float(np.clip(lo, *TWIST_RANGE)), float(np.clip(hi, *TWIST_RANGE))
    slack = TWIST_LSB + TWIST_RELATIVE * max(abs(lo), abs(hi))
    slack += max(a[2], b[2])
    return max(0.0, max(value - hi - slack, lo - slack - value))


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
    _pending: dict[str, np.ndarray] = field(default_factory=dict)  # twist frames waiting
    _last_enc: Encoders | None = None  # the last accepted encoder frame (one element)
    _steps: dict[str, np.ndarray] = field(default_factory=dict)  # g, v, w, gap_v, gap_w
    _running_max: int = -1  # of every E named so far (-1 for a frame naming none)
    _ok: list[_Twist] = field(default_factory=list)  # the last two judged-order twist frames
    _count: int = 0  # twist frames taken (E non-decreasing)
    _prev_band: tuple[Band, Band] = (EMPTY, EMPTY)  # segment (E[k-2], E[k-1]]: linear, angular
    _folded: tuple[Band, Band] = (EMPTY, EMPTY)  # steps after the last E no longer kept
    samples: int = 0
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
                   "t": chunk.timestamp_s[rows["index"][keep]],
                   "linear": rows["LINEAR_VEL"][keep] * TWIST_LSB,
                   "angular": rows["ANGULAR_VEL"][keep] * TWIST_LSB}
            self._pending = ({k: np.concatenate((self._pending[k], v)) for k, v in new.items()}
                             if self._pending else new)
        self._resolve(known, final=False)
        self._offset += len(chunk)
        self._enc_count += len(enc.index)
        self._recent = {k: v[-RECENT_ENCODERS:] for k, v in known.items()}
        self._trim_steps()

    def finish(self) -> dict[str, Any]:
        """The result ``check_twist`` gives for the whole log."""
        if self._pending:
            self._resolve(self._recent, final=True)
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

    def _segment(self, a: int, b: int) -> tuple[Band, Band]:
        """The bands of the steps into encoder frames (a, b], ``a`` the last taken twist
        frame's encoder frame: linear, angular."""
        inside = (self._steps["g"] > a) & (self._steps["g"] <= b)
        return _join(self._folded, self._bands(inside))

    # --- twist frames ---------------------------------------------------------------------

    def _resolve(self, known: dict[str, np.ndarray], *, final: bool) -> None:
        """Name the encoder frame of every waiting twist frame that can be named (in order),
        and take those naming one."""
        p = self._pending
        if not p or len(p["index"]) == 0:
            return
        n = len(p["index"])
        if len(known["seq"]) == 0:
            e = np.full(n, -1, dtype=np.int64)
            cut = n
        else:
            cycle_s = contract_cycle_s(self.decoder, "WHEEL_ENCODERS")
            latest = np.searchsorted(known["index"], p["index"]) - 1
            has = latest >= 0
            at = np.maximum(latest, 0)
            if cycle_s is not None:
                has &= p["t"] - known["t"][at] < 8 * cycle_s
            offset = ((p["enc_counter"] - known["counter"][at] + 8) & 0xF) - 8
            target = known["seq"][at] + offset
            waits = has & (target > int(known["seq"][-1])) & (not final)
            cut = int(np.argmax(waits)) if waits.any() else n
            found = np.minimum(np.searchsorted(known["seq"], target[:cut]), len(known["seq"]) - 1)
            hit = has[:cut] & (known["seq"][found] == target[:cut])
            e = np.where(hit, known["g"][found], -1)
        for j in range(cut):
            self._running_max = max(self._running_max, int(e[j]))
            if e[j] >= 0 and e[j] >= self._running_max:
                self._take_twist(_Twist(int(e[j]), float(p["linear"][j]),
                                        float(p["angular"][j])))
        self._pending = {k: v[cut:] for k, v in p.items()}

    def _take_twist(self, twist: _Twist) -> None:
        """Twist frame k (k = ``_count``): its segment, and its judgment when k >= 2."""
        k = self._count
        self._count += 1
        if k == 0:
            self._ok = [twist]
            return
        prev = self._ok[-1]
        segment = self._segment(prev.e, twist.e) if twist.e > prev.e else (EMPTY, EMPTY)
        if k >= 2:
            self._take(self._judge(twist, self._prev_band, segment))
        self._prev_band = segment
        self._ok = [prev, twist]
        if twist.e > prev.e:
            self._folded = (EMPTY, EMPTY)  # every folded step lies before the new E

    def _judge(self, twist: _Twist, a: tuple[Band, Band], b: tuple[Band, Band]) -> Judgment:
        v = _excess(twist.linear, a[0], b[0])
        w = _excess(twist.angular, a[1], b[1])
        if v is None or w is None:
            return None
        return v, w

    def _take(self, judged: Judgment) -> None:
        if judged is None:
            return
        self.samples += 1
        if self.samples == 1:
            self.max_linear_excess_mps, self.max_angular_excess_rad_s = judged
        else:
            self.max_linear_excess_mps = max(self.max_linear_excess_mps, judged[0])
            self.max_angular_excess_rad_s = max(self.max_angular_excess_rad_s, judged[1])
