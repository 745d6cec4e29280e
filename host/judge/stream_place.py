"""The reference placed on the on-board samples in passes over them (issue #14.1): the start
pose of ``reference_path._start_pose`` and the segment offsets of
``reference_path._segment_offsets``, bit for bit, from the samples given chunk by chunk as
often as asked (``passes``: a function that gives them again from the first).

Pass 1: the first sample, the heading overlap of every sample (max and min: exact in any
order), the first ``START_FIT_SAMPLES`` samples kept, the samples of the first segment
counted; pass 2: the rotation fit's segment means (``stream_fit.SegmentSums``); pass 3: its
dot products (``stream_fit.BlockDot``). The segment offsets take one pass more (each
segment's first error and its max and min)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.judge.compare import error_summary
from odocan.host.judge.reference_path import (
    _overlap_mid,
    placed_start,
)
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    START_FIT_SAMPLES,
    FloatArray,
    IntArray,
    wrap_pi,
)
from odocan.host.judge.stream_fit import BlockDot, SegmentSums
from odocan.host.judge.turns import unwrapped_errors


@dataclass(frozen=True)
class PlacedChunk:
    """Consecutive on-board samples and the reference's increments from its start to each
    (``reference_path._Relative``), with the segment each lies in."""

    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray
    heading_raw: IntArray
    rel_x_m: FloatArray
    rel_y_m: FloatArray
    rel_heading_rad: FloatArray
    segment: IntArray
    rel_distance_m: FloatArray = field(default_factory=lambda: np.zeros(0))  # when needed
    enc: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # when needed

    def head(self, n: int) -> PlacedChunk:
        return PlacedChunk(*(getattr(self, k)[:n] for k in _FIELDS))


_FIELDS = ("x_m", "y_m", "heading_rad", "heading_raw", "rel_x_m", "rel_y_m",
           "rel_heading_rad", "segment", "rel_distance_m", "enc")
Passes = Callable[[], Iterable[PlacedChunk]]


def _joined(parts: list[PlacedChunk]) -> PlacedChunk:
    return PlacedChunk(*(np.concatenate([getattr(p, k) for p in parts]) for k in _FIELDS))


def start_pose(passes: Passes, *, power_up: bool) -> tuple[float, float, float, bool]:
    """``reference_path._start_pose`` of the samples ``passes`` gives."""
    first: list[PlacedChunk] = []
    kept = n_first = total = 0
    lo = -math.inf
    hi = math.inf
    h_first = 0.0
    for chunk in passes():
        if len(chunk.segment) == 0:
            continue
        if total == 0:
            h_first = chunk.heading_raw[0] * HEADING_LSB_RAD
        offsets = wrap_pi(chunk.heading_raw * HEADING_LSB_RAD - chunk.rel_heading_rad - h_first)
        lo = max(lo, float(np.max(offsets)) - 0.5 * HEADING_LSB_RAD)
        hi = min(hi, float(np.min(offsets)) + 0.5 * HEADING_LSB_RAD)
        if kept < START_FIT_SAMPLES:
            first.append(chunk.head(START_FIT_SAMPLES - kept))
            kept += len(first[-1].segment)
        n_first += int(np.count_nonzero(chunk.segment < 1))
        total += len(chunk.segment)
    if power_up:
        return 0.0, 0.0, 0.0, True
    head = _joined(first)
    n_first = max(1, n_first)
    if lo <= hi:  # consistent: the middle of the whole log's overlap, refined by the positions
        dh = 0.5 * (lo + hi)
        dh += _rotation_fit(passes, head, total, h_first + dh, (lo - dh, hi - dh))
    else:  # the samples disagree (a wrong firmware): place it on the first samples only
        offsets = wrap_pi(head.heading_raw * HEADING_LSB_RAD - head.rel_heading_rad - h_first)
        dh = _overlap_mid(offsets[:START_FIT_SAMPLES], HEADING_LSB_RAD)
    n = min(START_FIT_SAMPLES, n_first)
    return placed_start(h_first, dh, head.x_m[:n], head.y_m[:n], float(head.heading_rad[0]),
                        head.rel_x_m[:n], head.rel_y_m[:n])


def _terms(chunk: PlacedChunk, head: PlacedChunk, h0: float) -> tuple[FloatArray, ...]:
    """qx, qy, bx, by of ``reference_path._rotation_fit`` for a chunk."""
    cos0, sin0 = math.cos(h0), math.sin(h0)
    qx = cos0 * chunk.rel_x_m - sin0 * chunk.rel_y_m
    qy = sin0 * chunk.rel_x_m + cos0 * chunk.rel_y_m
    bx = chunk.x_m - head.x_m[0] - qx
    by = chunk.y_m - head.y_m[0] - qy
    return qx, qy, bx, by


def _rotation_fit(
    passes: Passes, head: PlacedChunk, total: int, h0: float, bounds: tuple[float, float]
) -> float:
    """``reference_path._rotation_fit`` in two passes (segment means, then the dots)."""
    sums = [SegmentSums() for _ in range(4)]
    for chunk in passes():
        for into, values in zip(sums, _terms(chunk, head, h0), strict=True):
            into.feed(chunk.segment, values)
    means = [s.means() for s in sums]
    dots = {key: BlockDot() for key in ("xx", "yy", "xby", "ybx")}
    for chunk in passes():
        qx_c, qy_c, bx_c, by_c = (v - m[chunk.segment] for v, m in
                                  zip(_terms(chunk, head, h0), means, strict=True))
        dots["xx"].feed(qx_c, qx_c)
        dots["yy"].feed(qy_c, qy_c)
        dots["xby"].feed(qx_c, by_c)
        dots["ybx"].feed(qy_c, bx_c)
    spread = dots["xx"].result() + dots["yy"].result()
    if spread <= (POSITION_LSB_M * POSITION_LSB_M) * total:  # no lever arm: nothing to learn
        return 0.0
    d = (dots["xby"].result() - dots["ybx"].result()) / spread
    return min(max(d, bounds[0]), bounds[1])


def segment_offsets(
    passes: Passes, start: tuple[float, float, float], n_segments: int
) -> tuple[FloatArray, FloatArray]:
    """``reference_path.raw_segment_offsets`` of x and y, per segment (``n_segments``: those of
    the encoder frames, ``segment[-1] + 1``; NaN for a segment without a sample), for the
    reference started at ``start`` (x0 m, y0 m, h0 rad): ``breaks.bound_offsets`` places
    them."""
    x0, y0, h0 = start
    cos0, sin0 = math.cos(h0), math.sin(h0)
    first = np.full((2, n_segments), np.nan)
    top = np.full((2, n_segments), -np.inf)
    bottom = np.full((2, n_segments), np.inf)
    for chunk in passes():
        if len(chunk.segment) == 0:
            continue
        errors = (chunk.x_m - (x0 + cos0 * chunk.rel_x_m - sin0 * chunk.rel_y_m),
                  chunk.y_m - (y0 + sin0 * chunk.rel_x_m + cos0 * chunk.rel_y_m))
        for axis, error in enumerate(errors):
            fresh = np.isnan(first[axis, chunk.segment])
            seg, at = np.unique(chunk.segment[fresh], return_index=True)
            first[axis, seg] = error[fresh][at]
            np.maximum.at(top[axis], chunk.segment, error)
            np.minimum.at(bottom[axis], chunk.segment, error)
    result = []
    for axis in range(2):
        offsets = np.full(n_segments, np.nan)
        offsets[0] = 0.0
        for k in np.flatnonzero(~np.isnan(first[axis])).tolist():
            if k == 0:  # the start's segment is not moved
                continue
            lo = float(top[axis, k]) - 0.5 * POSITION_LSB_M
            hi = float(bottom[axis, k]) + 0.5 * POSITION_LSB_M
            base = float(first[axis, k])
            offsets[k] = min(max(0.5 * (lo + hi), base - 0.5 * POSITION_LSB_M),
                             base + 0.5 * POSITION_LSB_M)
        result.append(offsets)
    return result[0], result[1]


def reference_errors(
    passes: Passes, start: tuple[float, float, float],
    offsets: tuple[FloatArray, FloatArray],
    allowance: Callable[[npt.NDArray[np.int64]], FloatArray] | None = None,
) -> dict[str, Any]:
    """``compare.error_summary`` of ``compare.pose_errors`` (on-board minus the placed
    reference at every sample, ``build_reference`` then ``Reference.at``) in one pass: the
    maxima and the last sample's errors; with an ``allowance`` (at the samples' encoder frames,
    ``losses.loss_allowance``) then ``loss_allowance_m`` and
    ``max_position_error_beyond_allowance_m`` as ``analysis._analyze_life`` adds them."""
    x0, y0, h0 = start
    cos0, sin0 = math.cos(h0), math.sin(h0)
    top_position = top_heading = top_beyond = -math.inf
    top_allowance = 0.0
    last: tuple[FloatArray, FloatArray] | None = None
    for chunk in passes():
        if len(chunk.segment) == 0:
            continue
        ref_x = x0 + cos0 * chunk.rel_x_m - sin0 * chunk.rel_y_m
        ref_x += offsets[0][chunk.segment]
        ref_y = y0 + sin0 * chunk.rel_x_m + cos0 * chunk.rel_y_m
        ref_y += offsets[1][chunk.segment]
        position = np.hypot(chunk.x_m - ref_x, chunk.y_m - ref_y)
        ref_h = h0 + chunk.rel_heading_rad
        heading = unwrapped_errors(chunk.heading_rad, ref_h,
                                   wrap_pi(chunk.heading_raw * HEADING_LSB_RAD - ref_h))
        top_position = max(top_position, float(np.max(position)))
        top_heading = max(top_heading, float(np.max(np.abs(heading))))
        allowed = allowance(chunk.enc) if allowance is not None else np.zeros(0)
        if allowance is not None:
            top_allowance = max(top_allowance, float(np.max(allowed)))
            top_beyond = max(top_beyond, float(np.max(position - allowed)))
        last = (position[-1:], heading[-1:])
    if last is None:
        return error_summary(np.zeros(0), np.zeros(0))
    summary = error_summary(*last)
    summary["max_position_error_m"] = top_position
    summary["max_heading_error_rad"] = top_heading
    if allowance is not None:
        summary["loss_allowance_m"] = top_allowance
        summary["max_position_error_beyond_allowance_m"] = top_beyond
    return summary
