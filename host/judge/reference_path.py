"""The reference along a log: the count steps as the firmware takes them (plausibility,
counter restarts), the start pose (exact at power-up, else fitted), and the segments after gaps
and stalls (``host.judge.analysis`` module docstring, step 4)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.firmware.encoders import RESYNC_FRAMES
from odocan.host.judge.ambiguity import least_ambiguous_periods
from odocan.host.judge.blockdot import block_dot, centred
from odocan.host.judge.breaks import BreakSummary, placed_offsets
from odocan.host.judge.breakspan import break_allowance as break_allowance
from odocan.host.judge.breakspan import seen_whole
from odocan.host.judge.ctrlrestart import (
    confirmed_holds,
    ctrl_restarts,
    young_counts,
)
from odocan.host.judge.cutreprime import Backlog, cut_reprime
from odocan.host.judge.fifolate import Judged, Refused
from odocan.host.judge.fitsegments import fit_segments
from odocan.host.judge.gapfill import gap_allowance_at
from odocan.host.judge.gapreceived import received_at
from odocan.host.judge.gapseen import NOTHING, Seen
from odocan.host.judge.gapskips import skipped_at
from odocan.host.judge.lossgate import beyond_width
from odocan.host.judge.nearthreshold import Resets, ambiguity_rule, least_of, near_candidates
from odocan.host.judge.newstartfit import refit_new_starts
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound, integrate, wrap_delta
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    START_FIT_SAMPLES,
    WIRE_COUNTER_BITS,
    Encoders,
    FloatArray,
    IntArray,
    Poses,
    wrap_pi,
)
from odocan.host.judge.stallreprime import (
    Reprime,
    declared_stalls,
    left_out,
    left_out_at,
    stall_reprimes,
)
from odocan.host.judge.stallrestart import Window, stall_windows, told_otherwise
from odocan.host.judge.step_periods import (
    doubted_bound_periods,
    pair_bound_periods,
    step_bound_periods,
)
from odocan.host.judge.unseenrestart import heading_offsets, restarted_path, unseen_restarts
from odocan.host.judge.unseenrestart import restart_detail as restart_detail
from odocan.sim.robot import RobotProfile


@dataclass(frozen=True)
class Reference:
    """The reference pose at every accepted encoder frame from the first on-board sample's on
    (element k: encoder frame ``start + k``)."""

    start: int  # index into Encoders of the first on-board sample
    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray
    distance_m: FloatArray
    restarts: int = 0  # gaps in the encoder sequence where the position was placed again
    exact_start: bool = False  # started at the power-up pose (0, 0, 0), not fitted
    counter_restarts: tuple[int, ...] = ()  # encoder frames the firmware re-primed on
    implausible_frames: int = 0  # encoder frames the firmware refuses (not integrated)
    placements: BreakSummary = field(default_factory=BreakSummary)  # after stalls and gaps
    ctrl_restarts: frozenset[int] = frozenset()  # counter restarts told by CTRL_UPTIME
    unseen_restarts: frozenset[int] = frozenset()  # of them, new starts (``unseenrestart``)
    ambiguous: frozenset[int] = frozenset()  # counter restarts on an ambiguous step (``ambiguity``)
    stall_reprimes: dict[int, Reprime] = field(default_factory=dict)  # ``stallreprime``
    stalled: tuple[Window, ...] = ()  # the stalls' windows (``stallrestart.stall_windows``)

    def at(self, enc: IntArray) -> Reference:
        """The reference at the encoder frames ``enc`` (all >= start)."""
        k = enc - self.start
        return Reference(
            self.start, self.x_m[k], self.y_m[k], self.heading_rad[k], self.distance_m[k],
            self.restarts, self.exact_start, self.counter_restarts, self.implausible_frames,
            self.placements, self.ctrl_restarts, self.unseen_restarts, self.ambiguous,
            self.stall_reprimes, self.stalled,
        )


def build_reference(
    enc: Encoders, onboard: Poses, robot: RobotProfile, integrator: str, *, power_up: bool,
    max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED,
    breaks: IntArray | None = None,
    slack_m: float = POSITION_LSB_M,
    start_pose: tuple[float, float, float] | None = None,
    seen: Seen = NOTHING,
    reprime_lost: dict[int, int] | None = None,
    cut: Backlog | None = None,
    lossy: Sequence[int] = (),
    late: Refused | None = None,
) -> Reference:
    """Integrate the encoder deltas from the first on-board sample on; the position placed
    again after gaps and after the stalls' ``breaks`` (within ``breaks.bound_offsets``' bound,
    ``slack_m``: the position tolerance; a gap's allowance from ``max_wheel_speed_mm_s``).
    ``start_pose``: the exact start at the first encoder frame (x m, y m, heading rad: a
    set-pose's, ``host.judge.setposes``), as at power-up. ``seen``: what the firmware's E2E pages
    prove it took (``host.judge.gapseen``): a gap it missed too, a stall over which it took
    exactly the log's frames, is placed with no allowance. ``reprime_lost``: the re-primes'
    ENC_E2E_LOST by break (``reprimecount.power_up_lost``); ``cut``: a set-pose's life whose
    first sample names a backlog frame (``cutreprime``: its re-prime may come after the APPLY);
    ``lossy``: the frames the firmware's loss spans start after (``losses.firmware_losses``),
    where a fitted start's samples end (``fitsegments``); ``late``: ``fifolate``'s frames."""
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    exact_at_first = power_up or start_pose is not None
    e0 = 0 if exact_at_first else int(onboard.enc[0])  # at power-up: pose 0 at the first frame
    geometry = Geometry.of(robot)
    windows = stall_windows(breaks, onboard.enc)  # stallrestart
    steps = firmware_steps(enc, e0, geometry, bits, max_wheel_speed_mm_s, through=seen.through,
                           resets=seen.resets, stalled=windows)
    d_left, d_right = steps.d_left, steps.d_right
    rel = integrate(d_left, d_right, geometry, integrator)
    zero = np.zeros(1)
    rel_x, rel_y = np.concatenate((zero, rel.x_m)), np.concatenate((zero, rel.y_m))
    rel_h = np.concatenate((zero, rel.heading_rad))
    at = onboard.enc - e0
    least = least_of(geometry, bits, max_wheel_speed_mm_s)
    reprimes = stall_reprimes(declared_stalls(breaks, enc, e0, seen.resets, least), onboard, e0,
                              (rel_x, rel_y, rel_h), start_pose or (
        (0.0, 0.0, 0.0) if power_up else None), reprime_lost,
        (enc, late, Judged(geometry, integrator, bits)))  # stallreprime: as it said
    reprimes |= cut_reprime(cut, start_pose, enc, onboard, seen.resets, least,
                            (rel_x, rel_y, rel_h))  # re-primed after the APPLY: cutreprime
    if reprimes:
        left_out(d_left, d_right, reprimes)
        rel = integrate(d_left, d_right, geometry, integrator)
        rel_x, rel_y = np.concatenate((zero, rel.x_m)), np.concatenate((zero, rel.y_m))
        rel_h = np.concatenate((zero, rel.heading_rad))
    unseen = unseen_restarts(enc, e0, steps.by_uptime, seen)
    rel_x, rel_y, rel_h = restarted_path(unseen, rel_x, rel_y, rel_h, heading_offsets(
        unseen, rel_h, HEADING_LSB_RAD * onboard.heading_raw.astype(np.float64), at,
        onboard.heading_rad))
    gaps = np.concatenate(([False], np.diff(enc.seq[e0:]) > 1))
    starts = gaps.copy()
    if breaks is not None:  # encoder frames where the firmware resumed after a stall
        inside = breaks[(breaks > e0) & (breaks < len(enc.seq))] - e0
        starts[inside] = True
    segment = np.cumsum(starts)
    x0, y0, h0, exact = (*start_pose, True) if start_pose is not None else _start_pose(
        onboard, _Relative(rel_x[at], rel_y[at], rel_h[at], fit_segments(starts, lossy, e0)[at]),
        power_up=power_up)
    cos0, sin0 = math.cos(h0), math.sin(h0)
    x_m = x0 + cos0 * rel_x - sin0 * rel_y
    y_m = y0 + sin0 * rel_x + cos0 * rel_y
    x_m, y_m, rel_h = refit_new_starts(unseen, x_m, y_m, rel_h, h0, (
        at, onboard.x_m, onboard.y_m, onboard.heading_rad), segment)  # newstartfit
    opened = np.flatnonzero(starts)  # the first frame (from e0) of segments 1, 2, ...
    stalled = frozenset(breaks.tolist()) if breaks is not None else frozenset()

    uptime_reprimed = frozenset(e0 + k for k in steps.by_uptime)
    reprimed = frozenset(e0 + k for k in steps.reprimed)

    def gap_allowance(b: int) -> float:
        if b - e0 in unseen:  # frames lost before a restart: a new start, placed freely
            return math.inf
        if b in uptime_reprimed or left_out_at(b - e0, reprimes):  # a controller restart,
            return 0.0  # an ambiguous step, a stall's re-prime: nothing integrated across it
        if seen.gap_missed(b, reprimed):
            return 0.0  # the firmware took the gap as the reference's one step
        return min(gap_allowance_at(enc, b, seen.filled(b, reprimed), geometry, bits, integrator,
                                    max_wheel_speed_mm_s),  # gapbound's, or gapfill's known counts
                   skipped_at(enc, b, seen.skipped(b, reprimed), geometry, bits, integrator),
                   received_at(enc, b, seen, reprimed, geometry, bits, integrator,
                               max_wheel_speed_mm_s))  # none the log lacks taken: gapreceived

    off_x, off_y, placed = placed_offsets(
        raw_segment_offsets(segment, at, onboard.x_m - x_m[at]),
        raw_segment_offsets(segment, at, onboard.y_m - y_m[at]),
        list(zip((opened + e0).tolist(), gaps[opened].tolist(), strict=True)),
        lambda b: (break_allowance(enc, b, onboard.enc, geometry, bits, integrator,
                                   max_wheel_speed_mm_s=max_wheel_speed_mm_s,
                                   fills=lambda i: seen.filled(i, reprimed))  # spanfill
                   if b in stalled and not seen_whole(seen, b, onboard.enc, reprimed)
                   else 0.0) if b - e0 not in reprimes else break_allowance(
                       enc, b, np.array([e0 + reprimes[b - e0].f]), geometry, bits, integrator),
        gap_allowance, slack_m)
    x_m += off_x[segment]
    y_m += off_y[segment]
    return Reference(
        start=e0,
        x_m=x_m,
        y_m=y_m,
        heading_rad=h0 + rel_h,
        distance_m=np.concatenate((zero, rel.distance_m)),
        restarts=int(segment[-1]),
        exact_start=exact,
        counter_restarts=tuple(e0 + k for k in steps.reprimed),
        implausible_frames=steps.refused,
        placements=placed,
        ctrl_restarts=uptime_reprimed - frozenset(e0 + k for k in steps.ambiguous),
        unseen_restarts=frozenset(e0 + k for k in unseen),
        stall_reprimes=reprimes,
        ambiguous=frozenset(e0 + k for k in steps.ambiguous),
        stalled=windows,
    )


@dataclass
class Steps:
    """The count steps the firmware integrates between the accepted encoder frames of the log
    (element k: into frame ``e0 + k + 1``), with its refusals."""

    d_left: IntArray
    d_right: IntArray
    refused: int = 0  # frames beyond the plausibility bound, not integrated
    reprimed: list[int] = field(default_factory=list)  # frames (from e0) a counter restart primed
    by_uptime: list[int] = field(default_factory=list)  # of them, a controller restart's or
    ambiguous: list[int] = field(default_factory=list)  # an ambiguous step's (``ambiguity``)
    open_from: int | None = None  # the last accepted frame when the log ends in a refusal run
    taken_before: dict[int, int] = field(default_factory=dict)  # after refusals: the frame
    # taken before (``step_periods.doubt_origin_s``; elsewhere the frame before)


def firmware_steps(
    enc: Encoders, e0: int, geometry: Geometry, bits: int, max_wheel_speed_mm_s: SpeedBound,
    *, through: dict[int, int] | None = None, resets: Resets | None = None,
    stalled: tuple[Window, ...] = (), first_origin_s: float | None = None,
) -> Steps:
    """The steps as firmware/ecu.py takes them: a frame whose step from the last accepted one
    exceeds the robot's maximum wheel speed (``max_wheel_speed_mm_s``; ``PROFILE_SPEED``: the
    profile's) over its periods (``step_periods``: widened by the bus time, as the firmware
    widens them by its clock's; else from the frame before, ``doubted_bound_periods``) is
    refused (IMPLAUSIBLE_STEP, not integrated);
    ``RESYNC_FRAMES`` refused frames plausible among themselves are a counter restart
    (COUNTER_RESET): the odometry re-primes on the first of them and integrates one step from it to
    the last. A frame whose CTRL_UPTIME is below the last accepted frame's (both non-zero: the
    motor controller restarted), or below what it aged to over a silence (``aged_uptime``),
    re-primes it if its counts are young and the next frame confirms it (``confirmed_holds``;
    COUNTER_RESET, no step into it), else it is refused outright. A frame whose counts
    set wire bits above a 16-bit counter's width is refused outright. Vectorised; a short
    state machine runs only from each refused frame on. The bound is computed in float (the
    firmware's Q48 integer bound may differ by a count at the limit). ``through``: per gap (its
    encoder frame after) the firmware's longest step there, its pages' (``holetaken``): shorter
    than an ambiguous step, the gap is no ambiguous step (the firmware took frames in it).
    ``resets``: the firmware's COUNTER_RESET word, followed within a period of the threshold,
    and where a stall (``stalled``: ``stallrestart.stall_windows``) leaves a restart unproven.
    ``first_origin_s``: the doubt origin of frame ``e0`` (``step_periods.doubt_origin_s``)."""
    left, right = enc.left[e0:], enc.right[e0:]
    seq = enc.seq[e0:]
    steps = Steps(wrap_delta(np.diff(left), bits), wrap_delta(np.diff(right), bits))
    uptime = enc.uptime[e0:] if enc.uptime is not None else np.zeros(len(left), dtype=np.int64)
    stamps = enc.timestamp_s[e0:]
    counter = enc.counter[e0:]
    speed_mm_s = geometry.speed_bound_mm_s(max_wheel_speed_mm_s)
    if speed_mm_s is None:
        ones = np.ones(len(left), dtype=np.bool_)
        held = confirmed_holds((left, right, uptime, counter), ones, ~ones, bits, None)
        return _reprime_all(steps, told_otherwise(ctrl_restarts(
            uptime, ones, np.diff(stamps), enc.cycle_s, counter), uptime, stamps, e0, stalled,
            resets) & held[1:])
    bound = geometry.period_counts(speed_mm_s)
    foreign = beyond_width(left, right, bits)  # refused outright (IMPLAUSIBLE_STEP)
    young = young_counts(left, right, uptime, bits, bound) & ~foreign
    restart = told_otherwise(ctrl_restarts(uptime, young, np.diff(stamps), enc.cycle_s, counter),
                             uptime, stamps, e0, stalled, resets)  # stallrestart
    confirmed = confirmed_holds((left, right, uptime, counter), young, foreign, bits, bound)
    unconfirmed = restart & ~confirmed[1:]  # held, then refused: the state machine from it
    restart &= confirmed[1:]

    def delta(a: int, b: int) -> tuple[int, int]:
        return (int(wrap_delta(int(left[b]) - int(left[a]), bits)),
                int(wrap_delta(int(right[b]) - int(right[a]), bits)))

    def within(a: int, b: int, periods: int) -> bool:
        d = delta(a, b)
        return abs(d[0]) <= periods * bound[0] and abs(d[1]) <= periods * bound[1]

    def plausible(a: int, b: int) -> bool:  # from the last accepted frame: periods widened
        return within(a, b, pair_bound_periods(seq, stamps, enc.cycle_s, a, b)) or within(
            a, b, doubted_bound_periods(seq, stamps, enc.cycle_s, a, b, steps.taken_before,
                                        first_origin_s))

    def consistent(a: int, b: int) -> bool:  # among refused frames: the sequence's periods
        return within(a, b, max(1, int(seq[b] - seq[a])))

    def restarted(a: int, b: int) -> bool | None:  # None: held, not confirmed (refused)
        pair = [a, b]  # ``ctrl_restarts`` of the one step from a to b
        if not ctrl_restarts(uptime[pair], young[pair], stamps[b : b + 1] - stamps[a],
                             enc.cycle_s, counter[pair])[0]:
            return False
        return True if confirmed[b] else None

    least = least_ambiguous_periods(bound, bits)  # ``ambiguity``: the firmware re-primes
    ambiguous = ambiguity_rule(enc, e0, least, through or {}, resets,  # holetaken, nearthreshold
                               resets.holes if resets is not None else frozenset())

    periods = step_bound_periods(seq, stamps, enc.cycle_s)
    bad = (np.abs(steps.d_left) > periods * bound[0]) | (np.abs(steps.d_right) > periods * bound[1])
    bad |= foreign[1:] | unconfirmed | (periods >= least)
    bad |= near_candidates(seq, stamps, enc.cycle_s, least, resets)
    return _walk(steps, bad, restart,
                 ((plausible, consistent, foreign, ambiguous), delta, restarted))


def _walk(steps: Steps, bad: Any, restart: Any, rules: tuple[Any, Any, Any]) -> Steps:
    """From each refused step (``bad``) or controller restart on, the firmware's state machine
    (``rules``: the plausibility rules, the step between two frames, the restart test)."""
    plausibility, delta, restarted = rules
    n_frames = len(steps.d_left) + 1
    k = 0
    for first_bad in np.flatnonzero(bad | restart).tolist():
        if first_bad + 1 <= k:
            continue  # handled by the state machine of an earlier refusal
        if restart[first_bad]:  # frame first_bad accepted: the next one re-primes
            k = _reprime(steps, first_bad + 1)
            continue
        if plausibility[3](first_bad, first_bad + 1) and not plausibility[2][first_bad + 1]:
            k = _reprime(steps, first_bad + 1, ambiguous=True)  # ``ambiguity``
            continue
        k = _refusals(steps, first_bad, n_frames, plausibility, delta, restarted)
        steps.taken_before[k] = first_bad
        if k == n_frames:
            steps.open_from = first_bad
    return steps


def _reprime(steps: Steps, k: int, *, ambiguous: bool = False) -> int:
    """The firmware re-primes on frame ``k`` (a controller restart, or an ambiguous step):
    no step into it."""
    steps.d_left[k - 1] = steps.d_right[k - 1] = 0
    steps.reprimed.append(k)
    steps.by_uptime.append(k)  # re-primed on this frame alone, as a controller restart
    if ambiguous:
        steps.ambiguous.append(k)
    return k


def _reprime_all(steps: Steps, restart: npt.NDArray[np.bool_]) -> Steps:
    """Without a plausibility rule every frame is accepted: each restart re-primes."""
    for i in np.flatnonzero(restart).tolist():
        _reprime(steps, i + 1)
    return steps


def _refusals(
    steps: Steps,
    prev: int,
    n_frames: int,
    rules: tuple[Any, Any, Any, Any],
    delta: Any,
    restarted: Any,
) -> int:
    """Run the firmware's refusal logic from frame ``prev + 1`` (``prev`` accepted) until a frame
    is accepted again (``restarted(prev, k)``: it re-primes on frame k, a controller restart);
    return that frame (``n_frames`` at the end of the log). ``rules``: whether a step from the
    last accepted frame is plausible, whether one between refused frames is, and per frame
    whether its counts lie beyond the counters' width (``lossgate.beyond_width``), and whether
    a step from the last accepted frame is ambiguous (``ambiguity``: re-primed, no step);
    ``restarted``: None for a restart frame the next one did not confirm (refused outright)."""
    plausible, consistent, foreign, ambiguous = rules
    resync_first: int | None = None
    resync_last = 0
    resync_frames = 0
    for k in range(prev + 1, n_frames):
        told = False if foreign[k] else restarted(prev, k)
        if told is None or foreign[k]:  # counts beyond the counters' width, or a held restart
            steps.refused += 1  # frame the next did not confirm: refused, no part of the run
            steps.d_left[k - 1] = steps.d_right[k - 1] = 0
            continue
        if told:
            return _reprime(steps, k)
        if ambiguous(prev, k):
            return _reprime(steps, k, ambiguous=True)
        if plausible(prev, k):
            steps.d_left[k - 1], steps.d_right[k - 1] = delta(prev, k)
            return k
        steps.refused += 1
        steps.d_left[k - 1] = steps.d_right[k - 1] = 0
        if resync_first is not None and consistent(resync_last, k):
            resync_frames += 1
        else:
            resync_first, resync_frames = k, 1
        resync_last = k
        if resync_frames >= RESYNC_FRAMES:  # COUNTER_RESET: re-prime on the first, step to k
            steps.d_left[k - 1], steps.d_right[k - 1] = delta(resync_first, k)
            steps.reprimed.append(resync_first)
            return k
    return n_frames


def raw_segment_offsets(segment: IntArray, at: IntArray, error: FloatArray) -> FloatArray:
    """The position correction (m, one axis) each segment's samples ask for, per segment.

    Across a gap the firmware may have integrated frames the log does not hold (a logger that
    missed them): the heading stays exact (a function of the absolute counts) but the position's
    path over the gap is unknown. After a stall or hold the firmware took the frames it missed
    as one step or several. Each such segment asks to be placed like the start: the middle of
    the overlap of its on-board samples' rounding intervals (NaN for a segment without a
    sample); ``breaks.bound_offsets`` places it (a stall's within its allowance). Segment 0
    (the start) is not moved.
    """
    n_segments = int(segment[-1]) + 1
    offsets = np.full(n_segments, np.nan)
    offsets[0] = 0.0
    seg_of_sample = segment[at]
    bounds = np.searchsorted(seg_of_sample, np.arange(n_segments + 1))
    for k in np.flatnonzero(bounds[2:] > bounds[1:-1]) + 1:
        offsets[k] = _overlap_mid(error[bounds[k] : bounds[k + 1]], POSITION_LSB_M, base=True)
    return offsets


@dataclass(frozen=True)
class _Relative:
    """The reference's increments from the start to each on-board sample."""

    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray
    segment: IntArray  # gaps of the encoder sequence before the sample


def _start_pose(
    onboard: Poses, rel: _Relative, *, power_up: bool
) -> tuple[float, float, float, bool]:
    """The start pose (x m, y m, unwrapped heading rad) and whether it is the exact power-up pose
    (module docstring, step 4). The position uses only the samples before the first gap of the
    encoder sequence (the heading, exact across gaps, uses them all)."""
    n_first = max(1, int(np.searchsorted(rel.segment, 1)))
    h_first = onboard.heading_raw[0] * HEADING_LSB_RAD
    offsets = wrap_pi(onboard.heading_raw * HEADING_LSB_RAD - rel.heading_rad - h_first)
    lo = float(np.max(offsets)) - 0.5 * HEADING_LSB_RAD
    hi = float(np.min(offsets)) + 0.5 * HEADING_LSB_RAD
    if power_up:
        return 0.0, 0.0, 0.0, True
    if lo <= hi:  # consistent: the middle of the whole log's overlap, refined by the positions
        dh = 0.5 * (lo + hi)
        dh += _rotation_fit(onboard, rel, h_first + dh, (lo - dh, hi - dh))
    else:  # the samples disagree (a wrong firmware): place it on the first samples only
        dh = _overlap_mid(offsets[:START_FIT_SAMPLES], HEADING_LSB_RAD)
    n = min(START_FIT_SAMPLES, n_first)
    return placed_start(h_first, dh, onboard.x_m[:n], onboard.y_m[:n],
                        float(onboard.heading_rad[0]), rel.x_m[:n], rel.y_m[:n])


def placed_start(
    h_first: float, dh: float, x_m: FloatArray, y_m: FloatArray, heading0_rad: float,
    rel_x_m: FloatArray, rel_y_m: FloatArray,
) -> tuple[float, float, float, bool]:
    """The fitted start pose from its heading ``h_first + dh``: the position is the middle of
    the overlap of the first samples' rounding intervals (``x_m``, ``y_m``: their on-board
    positions, ``rel_*``: the reference's from the start), the heading in the first sample's
    turn. Shared by ``_start_pose`` and the streamed ``stream_place.start_pose``."""
    h0 = h_first + dh
    cos0, sin0 = math.cos(h0), math.sin(h0)
    px = cos0 * rel_x_m - sin0 * rel_y_m
    py = sin0 * rel_x_m + cos0 * rel_y_m
    x0 = x_m[0] + _overlap_mid(x_m - px - x_m[0], POSITION_LSB_M)
    y0 = y_m[0] + _overlap_mid(y_m - py - y_m[0], POSITION_LSB_M)
    turns = math.floor((heading0_rad - h_first) / (2 * math.pi) + 0.5)
    return float(x0), float(y0), float(h0 + turns * 2 * math.pi), False


def _rotation_fit(
    onboard: Poses, rel: _Relative, h0: float, bounds: tuple[float, float]
) -> float:
    """The small rotation (rad) of the reference about the start that best fits the on-board
    positions (least squares over every sample, each segment between gaps of the encoder
    sequence with a position offset of its own), kept within ``bounds``. Linearised:
    R(h0 + d) q = R(h0) q + d (-q_y, q_x)."""
    cos0, sin0 = math.cos(h0), math.sin(h0)
    qx = cos0 * rel.x_m - sin0 * rel.y_m
    qy = sin0 * rel.x_m + cos0 * rel.y_m
    bx = onboard.x_m - onboard.x_m[0] - qx
    by = onboard.y_m - onboard.y_m[0] - qy
    # normal equations of [1 0 -qy; 0 1 qx] (x_s, y_s, d) = (bx, by): offsets eliminated
    qx_c, qy_c, bx_c, by_c = (centred(v, rel.segment) for v in (qx, qy, bx, by))
    spread = block_dot(qx_c, qx_c) + block_dot(qy_c, qy_c)
    if spread <= (POSITION_LSB_M * POSITION_LSB_M) * len(qx):  # no lever arm: nothing to learn
        return 0.0
    d = (block_dot(qx_c, by_c) - block_dot(qy_c, bx_c)) / spread
    return min(max(d, bounds[0]), bounds[1])


def _overlap_mid(offsets: FloatArray, lsb: float, *, base: bool = False) -> float:
    """Middle of the overlap of [o - lsb/2, o + lsb/2] over ``offsets``, kept within the first
    interval (around 0, or around ``offsets[0]`` with ``base``)."""
    first = float(offsets[0]) if base else 0.0
    lo = float(np.max(offsets)) - 0.5 * lsb
    hi = float(np.min(offsets)) + 0.5 * lsb
    return min(max(0.5 * (lo + hi), first - 0.5 * lsb), first + 0.5 * lsb)



