"""A stretch of an overloaded robot's samples and the offsets they allow (``host.mqtt.haltstretch``,
``host.mqtt.haltcross``): a float64 reference re-started at a firmware pose, stepped with the
encoder frames the live tracker accepted, and per axis the interval of offsets (firmware -
reference) every sample so far allows.

The rule is the pose signals' rounding, not a tolerance: the firmware rounds X and Y to 0.1 mm
and HEADING to one LSB, to nearest. So a correct firmware's samples of one stretch differ from
the re-started reference by one common offset (the base's own rounding, unknown) plus each
sample's rounding (+-half an LSB), and the base's heading rounding turns the reference's
displacement by at most that offset (``narrow_offsets``). ``EPS_LSB`` and ``ARITH_*`` cover the
firmware's fixed point against float64 (issue #11: <= 0.08 mm over 10.8 km).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livewindow import window_counts
from odocan.host.judge.reference import ReferenceOdometry, wrap_delta
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.tracking import PoseTracker
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

EPS_LSB = 0.01  # the float noise of the decoders and the reference (~1e-8 LSB): the firmware
# rounds its Q40 pose to the signal to nearest, exactly (``mul_shr_round_i64``), its fixed point
# against float64 is ``ARITH_*``; 0.05 let a shift of 0.03 LSB at every halt hide (the
# carried boxes narrow to ~0.1 LSB, not ~0.02: ``host.mqtt.haltcarry``)
ARITH_M_PER_M = 1e-7  # fixed point vs float64 per metre of displacement (measured: 7.4e-9)
ARITH_RAD_PER_STEP = 2e-9  # the firmware's heading vs float64 per step (bam64: exact counts)
COUNTER_MASK = ENC_COUNTER_MASK  # 0xF: WHEEL_ENCODERS' E2E COUNTER (4 bits)
_TURN = 2.0 * math.pi
_QUARTER = 0.5 * math.pi


@dataclass
class Interval:
    """The offsets (m or rad) every sample of a stretch allows: ``lo`` <= offset <= ``hi``."""

    lo: float
    hi: float

    def narrow(self, error: float, half_width: float) -> None:
        """One sample ``error`` (firmware - reference) allows ``error +- half_width``."""
        self.lo = max(self.lo, error - half_width)
        self.hi = min(self.hi, error + half_width)


def interval(lsb: float) -> Interval:
    """A base's own offset: its rounding, +-half an LSB (and the float noise)."""
    half = (0.5 + EPS_LSB) * lsb
    return Interval(-half, half)


Offsets = tuple[Interval, Interval, Interval]  # x, y (m), heading (rad) offsets at the base
_NAMES = ("x", "y", "heading")
_LSBS = (POSITION_LSB_M, POSITION_LSB_M, HEADING_LSB_RAD)


def copy_box(box: Offsets) -> Offsets:
    """A copy of ``box`` with intervals of its own."""
    x, y, heading = box
    return Interval(x.lo, x.hi), Interval(y.lo, y.hi), Interval(heading.lo, heading.hi)


def emptied(box: Offsets) -> tuple[str, float] | None:
    """The first field of ``box`` whose interval is empty and by how many LSB (None: none)."""
    for name, allowed, lsb in zip(_NAMES, box, _LSBS, strict=True):
        if allowed.lo > allowed.hi:
            return name, (allowed.lo - allowed.hi) / lsb
    return None


@dataclass
class Stretch:
    """A stretch: its base's bus time, the reference re-started there, its last frame (seq,
    COUNTER), where it started, the steps, the offsets allowed."""

    base_t_s: float
    ref: ReferenceOdometry
    seq: int
    counter: int
    x0_m: float
    y0_m: float
    steps: int = 0
    x: Interval = field(default_factory=lambda: interval(POSITION_LSB_M))
    y: Interval = field(default_factory=lambda: interval(POSITION_LSB_M))
    heading: Interval = field(default_factory=lambda: interval(HEADING_LSB_RAD))
    wrong: bool = False
    boxes: list[Offsets] = field(default_factory=list)  # the offsets one of the ways taken at
    # the halts before allows (``host.mqtt.haltcarry``), each within x, y, heading; empty: none

    def fork(self) -> Stretch:
        """A copy with its own reference and offsets (a way the firmware may have gone on)."""
        return Stretch(self.base_t_s, copy.copy(self.ref), self.seq, self.counter, self.x0_m,
                       self.y0_m, self.steps, Interval(self.x.lo, self.x.hi),
                       Interval(self.y.lo, self.y.hi), Interval(self.heading.lo, self.heading.hi),
                       self.wrong, [copy_box(box) for box in self.boxes])


def narrow_offsets(stretch: Stretch, pose: FramePose) -> tuple[str, float] | None:
    """Narrow the stretch's offsets (and each of its ``boxes``) by one sample's ``pose``; the
    first field whose interval emptied and by how many LSB beyond the rounding (None: every one
    still holds; with boxes: one of them at least, the nearest's when none does)."""
    ref = stretch.ref
    error = (pose.x_m - ref.x_m, pose.y_m - ref.y_m,
             math.remainder(pose.heading_rad - ref.heading_rad, _TURN))
    moved = (ref.x_m - stretch.x0_m, ref.y_m - stretch.y0_m, ARITH_RAD_PER_STEP * stretch.steps)
    half = ((0.5 + EPS_LSB) * POSITION_LSB_M + ARITH_M_PER_M * math.hypot(moved[0], moved[1]),
            (0.5 + EPS_LSB) * HEADING_LSB_RAD + moved[2])
    own = (stretch.x, stretch.y, stretch.heading)
    empty = _narrow_box(own, error, half, moved)
    if empty is not None or not stretch.boxes:
        return empty
    deaths = []
    kept = []
    for box in stretch.boxes:
        died = _narrow_box(box, error, half, moved)
        if died is None:
            kept.append(box)
        else:
            deaths.append(died)
    stretch.boxes = kept
    if not kept:
        return min(deaths, key=lambda died: died[1])
    hull_into(own, kept)
    return None


def _narrow_box(box: Offsets, error: tuple[float, float, float], half: tuple[float, float],
                moved: tuple[float, float, float]) -> tuple[str, float] | None:
    """Narrow ``box`` by one sample's ``error`` (x, y m; heading rad: firmware - reference)
    within ``half`` (m, rad) each side, its heading's turn of the displacement ``moved`` (x, y
    m since the base; the heading arithmetic, rad) taken out; what emptied (None)."""
    x, y, heading = box
    heading.narrow(error[2], half[1])
    x_lo, x_hi, y_lo, y_hi = _turn_bounds_m(moved, heading)  # the base's offset: the turn out
    x.lo, x.hi = max(x.lo, error[0] - x_hi - half[0]), min(x.hi, error[0] - x_lo + half[0])
    y.lo, y.hi = max(y.lo, error[1] - y_hi - half[0]), min(y.hi, error[1] - y_lo + half[0])
    return emptied(box)


def hull_into(own: Offsets, boxes: list[Offsets]) -> None:
    """Narrow ``own`` to the hull of ``boxes`` (each meets it: never empty)."""
    for axis, allowed in enumerate(own):
        lo, hi = math.inf, -math.inf
        for box in boxes:
            held = box[axis]
            lo, hi = min(lo, held.lo), max(hi, held.hi)
        allowed.lo, allowed.hi = max(allowed.lo, lo), min(allowed.hi, hi)


def turned_m(stretch: Stretch, heading: Interval | None = None) -> tuple[Interval, Interval]:
    """What the heading offset turns the reference's displacement since the base by (x, y; m):
    the firmware integrates the same steps at its heading, the reference's plus the offset d,
    so its displacement is the reference's (dx, dy) turned by d: x by -(1 - cos d) dx - sin d dy,
    y by sin d dx - (1 - cos d) dy, for every d the heading interval allows (widened by the
    firmware's heading arithmetic per step); the interval's own sign and width, not its largest
    magnitude on every side (a turn of 0.2 to 0.3 LSB moves x one way only). ``heading``: the
    interval of a box (``Stretch.boxes``), else the stretch's own."""
    ref = stretch.ref
    moved = (ref.x_m - stretch.x0_m, ref.y_m - stretch.y0_m, ARITH_RAD_PER_STEP * stretch.steps)
    x_lo, x_hi, y_lo, y_hi = _turn_bounds_m(moved, stretch.heading if heading is None
                                            else heading)
    return Interval(x_lo, x_hi), Interval(y_lo, y_hi)


def _turn_bounds_m(moved: tuple[float, float, float], heading: Interval
                   ) -> tuple[float, float, float, float]:
    """``turned_m`` as plain floats (x lo, x hi, y lo, y hi; m) of the displacement ``moved``
    (x, y m; the heading arithmetic, rad): each sample asks it once a box."""
    dx_m, dy_m, arith_rad = moved
    lo_rad, hi_rad = heading.lo - arith_rad, heading.hi + arith_rad
    most_rad = max(abs(lo_rad), abs(hi_rad))
    if most_rad >= _QUARTER:  # sin not monotonic there: every turn of the displacement
        moved_m = math.hypot(dx_m, dy_m) * min(2.0, most_rad)
        return -moved_m, moved_m, -moved_m, moved_m
    sin_lo, sin_hi = math.sin(lo_rad), math.sin(hi_rad)
    sag = 1.0 - math.cos(most_rad)  # 1 - cos d is in [0, sag]
    a, b, c = -sin_lo * dy_m, -sin_hi * dy_m, -sag * dx_m  # x: -sin d dy - (1 - cos d) dx
    x_lo, x_hi = min(a, b) + min(c, 0.0), max(a, b) + max(c, 0.0)
    a, b, c = sin_lo * dx_m, sin_hi * dx_m, -sag * dy_m  # y: sin d dx - (1 - cos d) dy
    return x_lo, x_hi, min(a, b) + min(c, 0.0), max(a, b) + max(c, 0.0)


Frame = tuple[int, int, float, int, int]  # seq, COUNTER, bus time s, left, right


def step_frames(stretch: Stretch, rows: list[Frame], seq: int, bound: tuple[int, int],
                bits: int) -> bool:
    """Step the stretch's reference with ``rows`` (frames from ``stretch.seq + 1`` on) one by
    one up to frame ``seq``; False when a frame is missing (seq or COUNTER not the next) or
    beyond the per-period count ``bound`` (the firmware may have refused it)."""
    ref, (bound_left, bound_right) = stretch.ref, bound
    for row_seq, counter, _, left, right in rows:
        if row_seq <= stretch.seq:
            continue
        if row_seq > seq:
            break
        prev = ref._prev
        if row_seq != stretch.seq + 1 or counter != (stretch.counter + 1) & COUNTER_MASK \
                or prev is None or abs(wrap_delta(left - prev[0], bits)) > bound_left \
                or abs(wrap_delta(right - prev[1], bits)) > bound_right:
            return False
        ref.step_counts(left, right)
        stretch.seq, stretch.counter, stretch.steps = row_seq, counter, stretch.steps + 1
    return stretch.seq == seq


def frames_from(tracker: PoseTracker, first: int) -> list[Frame]:
    """The encoder frames of the tracker's window from seq ``first`` on: from its latest rows
    as plain tuples (``Columns.rows``: a sample names one of the latest frames) when they reach
    back that far, else from the numpy window (``window_counts``: 20 times the CPU)."""
    window = tracker.window  # the tracker's window of the latest encoder frames
    rows = window.rows
    if rows and (rows[0][0] <= first or window.whole):
        frames = []
        for r in reversed(rows):  # the latest first: a sample names one of the last few
            if r[0] < first:
                break
            frames.append((int(r[0]), int(r[2]), float(r[3]), int(r[4]), int(r[5])))
        frames.reverse()
        return frames
    return [(seq, counter, t_s, left, right)
            for seq, counter, left, right, _, _, t_s in window_counts(window, first)]
