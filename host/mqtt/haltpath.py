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

EPS_LSB = 0.05  # the decoders' float noise and the firmware's rounding of its Q formats
ARITH_M_PER_M = 1e-7  # fixed point vs float64 per metre of displacement (measured: 7.4e-9)
ARITH_RAD_PER_STEP = 2e-9  # the firmware's heading vs float64 per step (bam64: exact counts)
COUNTER_MASK = 0xF  # WHEEL_ENCODERS' E2E COUNTER (4 bits)
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

    def narrow_turned(self, error: float, half_width: float, turn: Interval) -> None:
        """One sample ``error`` (firmware - reference) allows ``error - turn +- half_width``:
        the base's offset, the heading offset's turn of the displacement (``turn``) taken out."""
        self.lo = max(self.lo, error - turn.hi - half_width)
        self.hi = min(self.hi, error - turn.lo + half_width)


def interval(lsb: float) -> Interval:
    """A base's own offset: its rounding, +-half an LSB (and the float noise)."""
    half = (0.5 + EPS_LSB) * lsb
    return Interval(-half, half)


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

    def fork(self) -> Stretch:
        """A copy with its own reference and offsets (a way the firmware may have gone on)."""
        return Stretch(self.base_t_s, copy.copy(self.ref), self.seq, self.counter, self.x0_m,
                       self.y0_m, self.steps, Interval(self.x.lo, self.x.hi),
                       Interval(self.y.lo, self.y.hi), Interval(self.heading.lo, self.heading.hi),
                       self.wrong)


def narrow_offsets(stretch: Stretch, pose: FramePose) -> tuple[str, float] | None:
    """Narrow the stretch's offsets by one sample's ``pose``; the first field whose interval
    emptied and by how many LSB beyond the rounding (None: every one still holds)."""
    ref = stretch.ref
    heading_error = math.remainder(pose.heading_rad - ref.heading_rad, _TURN)
    stretch.heading.narrow(heading_error, (0.5 + EPS_LSB) * HEADING_LSB_RAD
                           + ARITH_RAD_PER_STEP * stretch.steps)
    moved_m = math.hypot(ref.x_m - stretch.x0_m, ref.y_m - stretch.y0_m)
    half_m = (0.5 + EPS_LSB) * POSITION_LSB_M + ARITH_M_PER_M * moved_m
    turn_x, turn_y = turned_m(stretch)
    stretch.x.narrow_turned(pose.x_m - ref.x_m, half_m, turn_x)
    stretch.y.narrow_turned(pose.y_m - ref.y_m, half_m, turn_y)
    for name, allowed, lsb in (("x", stretch.x, POSITION_LSB_M),
                               ("y", stretch.y, POSITION_LSB_M),
                               ("heading", stretch.heading, HEADING_LSB_RAD)):
        if allowed.lo > allowed.hi:
            return name, (allowed.lo - allowed.hi) / lsb
    return None


def turned_m(stretch: Stretch) -> tuple[Interval, Interval]:
    """What the heading offset turns the reference's displacement since the base by (x, y; m):
    the firmware integrates the same steps at its heading, the reference's plus the offset d,
    so its displacement is the reference's (dx, dy) turned by d: x by -(1 - cos d) dx - sin d dy,
    y by sin d dx - (1 - cos d) dy, for every d the heading interval allows (widened by the
    firmware's heading arithmetic per step); the interval's own sign and width, not its largest
    magnitude on every side (a turn of 0.2 to 0.3 LSB moves x one way only)."""
    ref, arith_rad = stretch.ref, ARITH_RAD_PER_STEP * stretch.steps
    dx_m, dy_m = ref.x_m - stretch.x0_m, ref.y_m - stretch.y0_m
    lo_rad, hi_rad = stretch.heading.lo - arith_rad, stretch.heading.hi + arith_rad
    most_rad = max(abs(lo_rad), abs(hi_rad))
    if most_rad >= _QUARTER:  # sin not monotonic there: every turn of the displacement
        moved_m = math.hypot(dx_m, dy_m) * min(2.0, most_rad)
        return Interval(-moved_m, moved_m), Interval(-moved_m, moved_m)
    sines = (math.sin(lo_rad), math.sin(hi_rad))
    sag = 1.0 - math.cos(most_rad)  # 1 - cos d is in [0, sag]
    return (_plus(_times(sines, -dy_m), _times((0.0, sag), -dx_m)),
            _plus(_times(sines, dx_m), _times((0.0, sag), -dy_m)))


def _times(factor: tuple[float, float], by: float) -> Interval:
    """The interval of ``f * by`` for ``f`` in ``factor`` (lo, hi)."""
    ends = (factor[0] * by, factor[1] * by)
    return Interval(min(ends), max(ends))


def _plus(a: Interval, b: Interval) -> Interval:
    """The interval of sums."""
    return Interval(a.lo + b.lo, a.hi + b.hi)


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
