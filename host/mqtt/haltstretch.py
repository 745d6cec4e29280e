"""An overloaded fleet's robots judged between the loop's halts (``host.mqtt.overload``).

When the fleet's loop runs a tick ``sim.board.HALT_AFTER_S`` (9.5 periods) or more late, every
board runs it as a halted MCU's: its receive FIFO kept 3 frames and overran the rest, so the
firmware lost frames the bus carried and took them as one step (or refused it and re-primed,
COUNTER_RESET). No judge can tell from the bus how far that moved the firmware's pose: the halt
is the rig's fault. Between two halts, though, the firmware hears every frame again, and its pose
must move exactly as a float64 reference stepped with those frames moves.

``HaltStretches`` judges each *stretch* so, like a set-pose: the reference re-starts at the
firmware's pose (its *base* sample) once the firmware has taken the frames after the halt
(the base names a frame ``RESYNC_FRAMES`` releases after the halted tick or later: by then a
refused step has been re-primed, ``firmware.encoders``), and steps with every encoder frame the
tracker accepted; the stretch ends at the next halt (a sample made at or after it belongs to
the next). The re-start jump itself is never judged; a pose step inside a stretch that the
reference does not make is.

The rule is the pose signals' rounding, not a tolerance: the firmware rounds X and Y to 0.1 mm
and HEADING to one LSB, to nearest. So a correct firmware's samples of one stretch differ from
the re-started reference by one common offset (the base's own rounding, unknown) plus each
sample's rounding (+-half an LSB), and the base's heading rounding turns the reference's
displacement by at most that offset. The judge keeps, per axis, the interval of offsets every
sample so far allows (``Interval``); the heading's interval bounds the turn. A stretch whose
interval empties is wrong: no start the firmware could have been at explains its samples, by
``excess_lsb`` LSB beyond their rounding (a step of more than one LSB inside a stretch always
empties it). ``EPS_LSB`` and ``ARITH_*`` cover the firmware's fixed point against float64
(issue #11: <= 0.08 mm over 10.8 km).

A stretch is also ended (its samples since left unjudged) when the tracker's reference
restarted (a reboot, a set-pose applied) or a frame between base and sample is missing or
beyond the robot's per-period count bound (the firmware may have refused it): the next base
waits for the next halt, never a moment a wrong firmware could choose.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from odocan.firmware.encoders import RESYNC_FRAMES
from odocan.host.judge.livepose import Sample
from odocan.host.judge.livewindow import window_counts
from odocan.host.judge.reference import ReferenceOdometry, wrap_delta
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.tracking import PoseTracker
from odocan.sim.board import TICK_S

EPS_LSB = 0.05  # the decoders' float noise and the firmware's rounding of its Q formats
ARITH_M_PER_M = 1e-7  # fixed point vs float64 per metre of displacement (measured: 7.4e-9)
ARITH_RAD_PER_STEP = 2e-9  # the firmware's heading vs float64 per step (bam64: exact counts)
COUNTER_MASK = 0xF  # WHEEL_ENCODERS' E2E COUNTER (4 bits)
_TURN = 2.0 * math.pi


@dataclass
class Interval:
    """The offsets (m or rad) every sample of a stretch allows: ``lo`` <= offset <= ``hi``."""

    lo: float
    hi: float

    def narrow(self, error: float, half_width: float) -> None:
        """One sample ``error`` (firmware - reference) allows ``error +- half_width``."""
        self.lo = max(self.lo, error - half_width)
        self.hi = min(self.hi, error + half_width)

    @property
    def magnitude(self) -> float:
        """The largest offset still allowed (abs)."""
        return max(abs(self.lo), abs(self.hi))


@dataclass
class Wrong:
    """The first wrong stretch: bus time (s) of its sample whose interval emptied, its encoder
    frame (seq), which pose field, by how much beyond the rounding (LSB), the stretch's base
    time (s)."""

    t_s: float
    seq: int
    field: str
    excess_lsb: float
    base_t_s: float

    def text(self) -> str:
        """``x 2.04 LSB beyond the rounding at 4.81 s (enc 480), in the stretch from 4.62 s``."""
        return (f"{self.field} {self.excess_lsb:.2f} LSB beyond the pose signals' rounding at "
                f"{self.t_s:.2f} s (enc {self.seq}), inside the stretch re-started at "
                f"{self.base_t_s:.2f} s: a pose step the reference does not make")


@dataclass
class _Stretch:
    """The current stretch: its base's bus time, the reference re-started there, its last
    frame (seq, COUNTER), where it started, the steps, the offsets allowed."""

    base_t_s: float
    ref: ReferenceOdometry
    seq: int
    counter: int
    x0_m: float
    y0_m: float
    steps: int = 0
    x: Interval = field(default_factory=lambda: _interval(POSITION_LSB_M))
    y: Interval = field(default_factory=lambda: _interval(POSITION_LSB_M))
    heading: Interval = field(default_factory=lambda: _interval(HEADING_LSB_RAD))
    wrong: bool = False


def _interval(lsb: float) -> Interval:
    """A base's own offset: its rounding, +-half an LSB (and the float noise)."""
    half = (0.5 + EPS_LSB) * lsb
    return Interval(-half, half)


class HaltStretches:
    """One robot's samples after the loop's first halt, judged stretch by stretch (module
    docstring). ``halt_ticks``: the fleet's halted ticks as the loop appends them
    (``sim.fleet.Fleet.halt_ticks``, ascending, read as it grows); ``offset_ticks``: how many
    fleet ticks this robot's clock starts late (its bus time = (k - offset) * TICK_S)."""

    def __init__(self, tracker: PoseTracker, halt_ticks: Sequence[int], offset_ticks: int) -> None:
        self.tracker = tracker
        self._halt_ticks, self._offset = halt_ticks, offset_ticks
        self._next = 0  # the next halt not consumed
        self.halt_s: float | None = None  # bus time of the latest halt before the samples
        self._stretch: _Stretch | None = None
        self._starts = tracker.reference_starts
        bound = tracker.geometry.period_counts(tracker.geometry.max_wheel_speed_mm_s)
        self._bound = bound
        self.after = 0  # samples settled after the first halt
        self.judged = 0  # ... compared inside a stretch (bases not counted)
        self.stretches = 0  # stretches with a base
        self.wrong_stretches = 0
        self.first_wrong: Wrong | None = None

    def on_samples(self, samples: list[Sample]) -> None:
        """The tracker's samples settled (``PoseTracker.take_samples``), in order."""
        for sample in samples:
            self._on_sample(sample)

    def _on_sample(self, sample: Sample) -> None:
        if self._consume_halts(sample.t_s):
            self._stretch = None
        starts, restarted = self.tracker.reference_starts, False
        if starts != self._starts:  # a reboot, a set-pose: a stretch based before it ends
            self._starts, restarted = starts, self._stretch is not None
        if self.halt_s is None:
            return  # before the first halt: the tracker judges (``overload``)
        self.after += 1
        if restarted:
            self._stretch, self.halt_s = None, math.inf  # no new base before the next halt
            return
        if self._stretch is None:
            self._start(sample)
        elif self._step_to(self._stretch, sample.pose.seq):
            self._compare(self._stretch, sample)
        else:
            self._stretch, self.halt_s = None, math.inf

    def _consume_halts(self, t_s: float) -> bool:
        """Take the halts at or before bus time ``t_s`` (a sample made at a halted tick, sent
        1 ms after it, is the next stretch's); True when one was taken."""
        ticks, taken = self._halt_ticks, False
        while self._next < len(ticks):
            halt_s = max(ticks[self._next] - self._offset, 0) * TICK_S
            if halt_s > t_s:
                break
            self.halt_s, taken = halt_s, True
            self._next += 1
        return taken

    def _start(self, sample: Sample) -> None:
        """``sample`` is the stretch's base when its frame came ``RESYNC_FRAMES`` releases after
        the halt or later (module docstring) and the reference's integrator is known."""
        assert self.halt_s is not None
        rows = _frames_from(self.tracker, sample.pose.seq)
        integrator = self.tracker.integrator
        if not rows or rows[0][0] != sample.pose.seq or integrator is None:
            return
        seq, counter, frame_t_s, left, right = rows[0]
        if frame_t_s < self.halt_s + (RESYNC_FRAMES - 0.5) * TICK_S:
            return
        pose = sample.pose
        ref = ReferenceOdometry(self.tracker.geometry, integrator, self.tracker.counter_bits,
                                x_m=pose.x_m, y_m=pose.y_m, heading_rad=pose.heading_rad)
        ref.step_counts(left, right)  # primes
        self._stretch = _Stretch(sample.t_s, ref, seq, counter, pose.x_m, pose.y_m)
        self.stretches += 1

    def _step_to(self, stretch: _Stretch, seq: int) -> bool:
        """Step the stretch's reference up to encoder frame ``seq``; False when a frame is
        missing (seq or COUNTER not the next) or beyond the per-period count bound, or the
        sample names a frame before the reference's (module docstring)."""
        if seq < stretch.seq:
            return False
        if seq == stretch.seq:
            return True
        rows = _frames_from(self.tracker, stretch.seq + 1)
        ref, (bound_left, bound_right) = stretch.ref, self._bound
        bits = self.tracker.counter_bits
        for row_seq, counter, _, left, right in rows:
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

    def _compare(self, stretch: _Stretch, sample: Sample) -> None:
        """Narrow the stretch's offsets by one sample; note the stretch wrong once one empties."""
        ref, pose = stretch.ref, sample.pose
        self.judged += 1
        heading_error = math.remainder(pose.heading_rad - ref.heading_rad, _TURN)
        stretch.heading.narrow(heading_error, (0.5 + EPS_LSB) * HEADING_LSB_RAD
                               + ARITH_RAD_PER_STEP * stretch.steps)
        moved_m = math.hypot(ref.x_m - stretch.x0_m, ref.y_m - stretch.y0_m)
        turn_m = moved_m * (stretch.heading.magnitude + ARITH_RAD_PER_STEP * stretch.steps)
        half_m = (0.5 + EPS_LSB) * POSITION_LSB_M + turn_m + ARITH_M_PER_M * moved_m
        stretch.x.narrow(pose.x_m - ref.x_m, half_m)
        stretch.y.narrow(pose.y_m - ref.y_m, half_m)
        if stretch.wrong:
            return
        for name, interval, lsb in (("x", stretch.x, POSITION_LSB_M),
                                    ("y", stretch.y, POSITION_LSB_M),
                                    ("heading", stretch.heading, HEADING_LSB_RAD)):
            if interval.lo > interval.hi:
                stretch.wrong = True
                self.wrong_stretches += 1
                if self.first_wrong is None:
                    self.first_wrong = Wrong(sample.t_s, pose.seq, name,
                                             (interval.lo - interval.hi) / lsb, stretch.base_t_s)
                return

    def as_dict(self) -> dict[str, Any]:
        """The report's ``halt_stretches`` (``overload`` adds the loop's ``halts``): samples
        after the first halt, judged, stretches, wrong stretches, the first wrong one (None)."""
        first = self.first_wrong
        return {"samples_after_first_halt": self.after, "samples_judged": self.judged,
                "stretches": self.stretches, "wrong_stretches": self.wrong_stretches,
                "first_wrong": None if first is None else first.text()}


Frame = tuple[int, int, float, int, int]  # seq, COUNTER, bus time s, left, right


def _frames_from(tracker: PoseTracker, first: int) -> list[Frame]:
    """The encoder frames of the tracker's window from seq ``first`` on: from its latest rows
    as plain tuples (``Columns.rows``: a sample names one of the latest frames) when they reach
    back that far, else from the numpy window (``window_counts``: 20 times the CPU)."""
    window = tracker._window  # the tracker's own window (tracking.py is at its size limit)
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

