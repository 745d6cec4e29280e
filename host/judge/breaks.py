"""The bound on the reference's re-placement after a firmware stall or hold (rule 5: a PASS must
never hide a wrong pose), shared by the whole-log, the streamed and the live judge.

After a stall (silent while the encoder frames came on time) or a hold (it kept naming one
frame), the firmware took the frames it missed as one step, or as several: which frames it took
the log cannot say (its CAN FIFO and mailbox kept some, dropped others, refused some by E2E).
The reference follows the fine steps, so the on-board position may leave it there by the merge
error of the steps the firmware did take. The placement after such a break may move the
reference by no more than the worst of them (``merge_allowance_m``: over every set of runs of
frames lost between the last frame the firmware is known to have taken before the break and the
first one after it, the largest sum of the runs' merge errors, ``losses.merge_error``; their
errors are vectors, the heading after each run exact, so the sum of lengths bounds them), summed
over the breaks since the reference's position was last free (its start), plus the pose
tolerance (the rounding of the samples the placement rests on). A gap of the log (frames the
logger missed, which the firmware may have integrated one by one) is such a break too, its
allowance the worst merge error of any split of the merged step into the gap's periods within
the plausibility bound (``host.judge.gapbound``); only a gap whose bound is unknown (inf: no
plausibility bound configured) still places freely. Where the firmware's E2E pages prove
it took exactly the log's frames (``host.judge.gapseen``) a gap or a stall earns no allowance.
A larger offset is not absorbed: the placement stops at the bound and the samples after the
break show the rest (``bound_offsets``, ``clamp_offset``).

Spans of more than ``MAX_MERGE_FRAMES`` frames take a cheaper bound: twice the path length
(``path_bound_m``: a run's merge error is at most its fine path plus its merged step).

A stall whose span holds a gap of the log (``overlap_allowance_m``): the firmware's steps may
start or end inside the gap (a step from before it to one of its frames), which neither the
merge allowance (runs of the log's frames, the gap one step) nor the gap's (splits of the gap's
own counts) covers: their sum was seen 7.3 times short by brute force. The firmware's position
P there is within ``gap_allowance_m`` of the whole span as one merged step M (every step of it
within the plausibility bound, however split and merged), and M within the span's merge
allowance of the reference R (the run of every frame of the span lost is one of the sets it
maximises over): |P - R| <= |P - M| + |M - R|. So such a stall's allowance is its merge
allowance plus the gap allowance of the whole span; the gap's own allowance is still added (a
bound, not tight: proven by brute force in tests/test_break_overlap.py).

One step at a time (``placed_step``). The bound above is on the offset from the last free
placement: the allowances of every break since, summed. Summed over a drive with a gap at
nearly every frame held back (``--faults delay``: 92 gaps in 10 s on kobuki, seed 2), it
reached 1.86 mm by 5 s, most of it the E2E lock-out gaps' 0.25 to 0.76 mm each, so a log edited
to add 1 mm of X from 5 s on PASSed every judge: the gap at the edit asked 1.04 mm against
1.96 mm, although its own allowance was 0.05 mm. But what a break allows is where the
firmware's position may lie after it *relative to where it was before it*: with D_k the
firmware's offset from the reference path (the fine steps, not placed) over segment k (constant
there: between breaks both take the same steps, and the heading is exact), D_k - D_j is what the
firmware's steps over the breaks between segment j and k did differently from the reference's,
each within its allowance, so |D_k - D_j| <= the allowances of the breaks after j up to k (j
the segment last placed on samples). A placement rests on its samples' rounding: within
``slack_m`` of D (the premise of the bound from the start too), so the step between two
placements is within those allowances plus ``step_slack_m`` (twice ``slack_m``). Each
placement is kept within both bounds; a correct firmware meets both, so neither moves it, and
a firmware that jumped at one break is not absorbed by the allowances of the others."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from odocan.host.judge.gapbound import gap_allowance_of_counts, period_bounds
from odocan.host.judge.losses import OneSteps, merge_error
from odocan.host.judge.lossgate import gated_counts
from odocan.host.judge.reference import Geometry, SpeedBound, wrap_delta
from odocan.host.judge.samples import FloatArray, IntArray

MAX_MERGE_FRAMES = 480  # frames between the ends beyond which the path bound is used (4.8 s)


def merge_allowance_m(
    left: IntArray, right: IntArray, geometry: Geometry, bits: int, integrator: str,
    seq: IntArray | None = None,
) -> float:
    """The worst merge error (m) across a break: ``left``, ``right`` are the wire counts of the
    encoder frames from the last one the firmware is known to have taken before it to the first
    one after it (both taken, any between may be lost, in runs; ``bits``: the wire counter
    width). With the frames' sender sequence numbers ``seq``, the counts are the firmware's
    (``lossgate.gated_counts`` from the first frame: a forger's frame it refuses as implausible
    takes the last accepted frame's counts, so it cannot widen the allowance). Dynamic
    programming over the frame last taken (module docstring)."""
    n = len(left)
    if n < 3:
        return 0.0
    if seq is not None:
        left, right, _ = gated_counts(np.asarray(left, dtype=np.int64),
                                      np.asarray(right, dtype=np.int64),
                                      np.asarray(seq, dtype=np.int64), period_bounds(geometry),
                                      bits)
    dl: IntArray = wrap_delta(np.diff(np.asarray(left, dtype=np.int64)).astype(np.int64), bits)
    dr: IntArray = wrap_delta(np.diff(np.asarray(right, dtype=np.int64)).astype(np.int64), bits)
    if n - 2 > MAX_MERGE_FRAMES:
        return path_bound_m(int(np.sum(np.abs(dl))), int(np.sum(np.abs(dr))), geometry)
    steps = OneSteps.of_deltas(dl, dr, geometry, integrator)
    error = np.zeros((n, n))  # error[a, t]: the merge error from frame a to frame t (a < t)
    a, t = np.triu_indices(n, k=1)
    error[a, t] = merge_error(steps, a, t)  # every pair at once, each element as one by one
    best = np.zeros(n)  # best[t]: the largest sum with frame t taken (runs before it)
    for t_taken in range(1, n):
        best[t_taken] = float(np.max(best[:t_taken] + error[:t_taken, t_taken]))
    return float(best[-1])


def overlap_allowance_m(
    first: tuple[int, int, int], last: tuple[int, int, int], frames: int, geometry: Geometry,
    bits: int, integrator: str, max_wheel_speed_mm_s: SpeedBound,
) -> float:
    """What a stall's span that holds a gap of the log adds to its merge allowance (m; module
    docstring): ``first`` and ``last`` the (sender's sequence number, left, right wire counts) of
    its ends, ``frames`` the log's encoder frames in it (both ends counted); 0 when its periods
    are its frames' (no gap), inf without a plausibility bound."""
    periods = last[0] - first[0]
    if periods <= frames - 1:
        return 0.0
    return gap_allowance_of_counts(first[1:], last[1:], periods, geometry, bits, integrator,
                                   max_wheel_speed_mm_s)


def path_bound_m(counts_left: int, counts_right: int, geometry: Geometry) -> float:
    """A bound (m) on any merge error across steps of ``counts_*`` counts in all (the sums of
    their absolute values, exact in any order): a run's merged step and its fine path are each
    at most its path, and twice a step's travel |dS_L + dS_R| is at most |dS_L| + |dS_R|."""
    return counts_left * geometry.m_per_count_left + counts_right * geometry.m_per_count_right


def clamp_offset(dx_m: float, dy_m: float, limit_m: float) -> tuple[float, float]:
    """The offset (m) shortened to ``limit_m`` when it is longer (its direction kept)."""
    length = math.hypot(dx_m, dy_m)
    if length <= limit_m:
        return dx_m, dy_m
    scale = limit_m / length
    return dx_m * scale, dy_m * scale


@dataclass
class BreakSummary:
    """What the placements after stalls and holds (and after gaps) absorbed, for the report."""

    stalls: int = 0  # placements after a stall or hold (segments with a sample)
    max_absorbed_m: float = 0.0  # the longest offset such a placement asked for (m)
    allowance_m: float = 0.0  # that placement's bound (merge allowance + tolerance, m)
    max_beyond_m: float = 0.0  # the most an offset went beyond its bound, not absorbed (m)
    gaps: int = 0  # placements after a gap of the log (bounded as a stall's)
    max_gap_absorbed_m: float = 0.0  # the longest offset such a placement asked for (m)
    gap_allowance_m: float = 0.0  # that placement's bound (gap and merge allowances + tolerance)
    free: int = 0  # placements after a gap without a bound (none configured: not checked)
    twins: int = 0  # encoder frames with a twin after the reference's start (host.judge.twins)
    twin_allowance_m: float = 0.0  # their detours summed: the largest twin allowance (m)

    def add_stall(self, asked_m: float, limit_m: float) -> None:
        self.stalls += 1
        if asked_m >= self.max_absorbed_m:
            self.max_absorbed_m, self.allowance_m = asked_m, limit_m
        self.max_beyond_m = max(self.max_beyond_m, asked_m - limit_m)

    def add_gap(self, asked_m: float, limit_m: float) -> None:
        self.gaps += 1
        if asked_m >= self.max_gap_absorbed_m:
            self.max_gap_absorbed_m, self.gap_allowance_m = asked_m, limit_m
        self.max_beyond_m = max(self.max_beyond_m, asked_m - limit_m)

    def rebound(self, asked_m: float, gap: bool, limit_m: float) -> None:
        """A placement that asked ``asked_m`` (after a gap: ``gap``) made again within its bound
        lowered to ``limit_m`` (the pages withdrew a part's allowance after it was placed:
        ``liveplace.StallPlacer.withdraw``): the report gives the bound the verdict used, not
        the one at its placement, and what it asked beyond that."""
        if gap and asked_m == self.max_gap_absorbed_m:
            self.gap_allowance_m = min(self.gap_allowance_m, limit_m)
        elif not gap and asked_m == self.max_absorbed_m:
            self.allowance_m = min(self.allowance_m, limit_m)
        self.max_beyond_m = max(self.max_beyond_m, asked_m - limit_m)

    def as_dict(self) -> dict[str, Any]:
        """The report's ``reference_breaks``."""
        return {
            "stall_placements": self.stalls,
            "max_offset_absorbed_m": self.max_absorbed_m,
            "offset_allowance_m": self.allowance_m,
            "max_offset_beyond_allowance_m": self.max_beyond_m,
            "gap_placements": self.gaps,
            "max_gap_offset_absorbed_m": self.max_gap_absorbed_m,
            "gap_offset_allowance_m": self.gap_allowance_m,
            "free_gap_placements": self.free,
            "twins": self.twins,
            "twin_allowance_m": self.twin_allowance_m,
        }


def merged_breaks(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """``reference_breaks`` of several lives in one (counts summed, the worst kept)."""
    out = dict(parts[0])
    for part in parts[1:]:
        out["stall_placements"] += part["stall_placements"]
        out["gap_placements"] += part["gap_placements"]
        out["free_gap_placements"] += part["free_gap_placements"]
        out["twins"] += part["twins"]
        for asked, limit in (("max_offset_absorbed_m", "offset_allowance_m"),
                             ("max_gap_offset_absorbed_m", "gap_offset_allowance_m")):
            if part[asked] >= out[asked]:
                out[asked], out[limit] = part[asked], part[limit]
        for key in ("max_offset_beyond_allowance_m", "twin_allowance_m"):
            out[key] = max(out[key], part[key])
    return out


def bound_offsets(
    raw_x_m: FloatArray, raw_y_m: FloatArray, gap: IntArray, allowance_m: FloatArray,
    slack_m: float,
) -> tuple[FloatArray, FloatArray, BreakSummary]:
    """The segments' position offsets (m) as placed: per segment, the offset its samples ask for
    (``raw_*``: NaN for a segment without a sample, which keeps the previous one; segment 0 is
    0), whether a gap of the log opened it (``gap``, nonzero) or a stall or hold, its allowance
    (``allowance_m``: a stall's ``merge_allowance_m``, a gap's ``gapbound.gap_allowance_m``
    plus that if a stall ended there too; inf: unknown, the placement is free), and the
    tolerance ``slack_m``. An offset from the last free placement is kept within the allowances
    summed since plus ``slack_m`` (module docstring)."""
    n = len(raw_x_m)
    x, y = np.zeros(n), np.zeros(n)
    summary = BreakSummary()
    anchor = (0.0, 0.0)
    budget = step_budget = 0.0
    opened_by_gap = False  # a gap since the last placement with a sample
    for k in range(1, n):
        opened_by_gap = opened_by_gap or bool(gap[k])
        budget += float(allowance_m[k])
        step_budget += float(allowance_m[k])
        if math.isnan(raw_x_m[k]):
            x[k], y[k] = x[k - 1], y[k - 1]
            continue
        if math.isinf(budget):  # a gap without a bound: free
            summary.free += 1
            anchor, budget, opened_by_gap = (float(raw_x_m[k]), float(raw_y_m[k])), 0.0, False
            x[k], y[k] = anchor
            step_budget = 0.0
            continue
        dx, dy = float(raw_x_m[k]) - anchor[0], float(raw_y_m[k]) - anchor[1]
        limit = budget + slack_m
        if opened_by_gap:
            summary.add_gap(math.hypot(dx, dy), limit)
        else:
            summary.add_stall(math.hypot(dx, dy), limit)
        opened_by_gap = False
        dx, dy = clamp_offset(dx, dy, limit)
        x[k], y[k] = placed_step((x[k - 1], y[k - 1]), (anchor[0] + dx, anchor[1] + dy),
                                 (float(raw_x_m[k]), float(raw_y_m[k])),
                                 step_budget + step_slack_m(slack_m), summary)
        step_budget = 0.0
    return x, y, summary


def step_slack_m(slack_m: float) -> float:
    """The tolerance of one placement's step from the placement before (m): each of the two
    rests on its samples' rounding, within ``slack_m`` of where the firmware is."""
    return 2.0 * slack_m


def placed_step(before: tuple[float, float], placed: tuple[float, float],
                asked: tuple[float, float], limit_m: float, summary: BreakSummary
                ) -> tuple[float, float]:
    """A placement (``placed``: already within its bound from the last free placement) kept
    within ``limit_m`` of the placement before it (``before``; module docstring, "One step at a
    time"); the step its samples asked beyond it (``asked``) goes into ``summary``."""
    summary.max_beyond_m = max(summary.max_beyond_m, math.hypot(
        asked[0] - before[0], asked[1] - before[1]) - limit_m)
    dx, dy = clamp_offset(placed[0] - before[0], placed[1] - before[1], limit_m)
    return before[0] + dx, before[1] + dy


def placed_offsets(
    raw_x_m: FloatArray, raw_y_m: FloatArray, openings: list[tuple[int, bool]],
    allowance_of: Callable[[int], float], gap_allowance_of: Callable[[int], float],
    slack_m: float,
) -> tuple[FloatArray, FloatArray, BreakSummary]:
    """``bound_offsets`` of segments 1, 2, ... opened at ``openings`` (their first encoder
    frame, and whether a gap of the log opened it), a stall's allowance by ``allowance_of``
    (its first frame; 0 where no stall ended), a gap's by ``gap_allowance_of`` (the frame after
    it) plus ``allowance_of``: the whole-log and the streamed judge's one way."""
    allowance = np.zeros(len(raw_x_m))
    gap = np.zeros(len(raw_x_m), dtype=np.int64)
    for k, (first, by_gap) in enumerate(openings, start=1):
        gap[k] = by_gap
        allowance[k] = allowance_of(first) + (gap_allowance_of(first) if by_gap else 0.0)
    return bound_offsets(raw_x_m, raw_y_m, gap, allowance, slack_m)
