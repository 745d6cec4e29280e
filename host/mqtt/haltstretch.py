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
empties it; the offsets and their arithmetic: ``host.mqtt.haltpath``). ``EPS_LSB`` and
``ARITH_*`` cover the firmware's fixed point against float64
(issue #11: <= 0.08 mm over 10.8 km).

A stretch is also ended (its samples since left unjudged) when the tracker's reference
restarted (a reboot, a set-pose applied) or a frame between base and sample is missing or
beyond the robot's per-period count bound (the firmware may have refused it): the next base
waits for the next halt, never a moment a wrong firmware could choose.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from odocan.firmware.encoders import RESYNC_FRAMES
from odocan.host.judge.livepose import Sample
from odocan.host.judge.reference import ReferenceOdometry
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.haltpath import (
    Stretch,
    frames_from,
    narrow_offsets,
    step_frames,
)
from odocan.sim.board import TICK_S


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
        self._stretch: Stretch | None = None
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
        rows = frames_from(self.tracker, sample.pose.seq)
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
        self._stretch = Stretch(sample.t_s, ref, seq, counter, pose.x_m, pose.y_m)
        self.stretches += 1

    def _step_to(self, stretch: Stretch, seq: int) -> bool:
        """Step the stretch's reference up to encoder frame ``seq``; False when a frame is
        missing (seq or COUNTER not the next) or beyond the per-period count bound, or the
        sample names a frame before the reference's (module docstring)."""
        if seq < stretch.seq:
            return False
        if seq == stretch.seq:
            return True
        rows = frames_from(self.tracker, stretch.seq + 1)
        return step_frames(stretch, rows, seq, self._bound, self.tracker.counter_bits)

    def _compare(self, stretch: Stretch, sample: Sample) -> None:
        """Narrow the stretch's offsets by one sample; note the stretch wrong once one empties."""
        self.judged += 1
        emptied = narrow_offsets(stretch, sample.pose)
        if stretch.wrong or emptied is None:
            return
        stretch.wrong = True
        self.wrong_stretches += 1
        if self.first_wrong is None:
            self.first_wrong = Wrong(sample.t_s, sample.pose.seq, *emptied, stretch.base_t_s)

    def as_dict(self) -> dict[str, Any]:
        """The report's ``halt_stretches`` (``overload`` adds the loop's ``halts``): samples
        after the first halt, judged, stretches, wrong stretches, the first wrong one (None)."""
        first = self.first_wrong
        return {"samples_after_first_halt": self.after, "samples_judged": self.judged,
                "stretches": self.stretches, "wrong_stretches": self.wrong_stretches,
                "first_wrong": None if first is None else first.text()}

