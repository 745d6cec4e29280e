"""An overloaded fleet's robots judged between the loop's halts (``host.mqtt.overload``).

When the fleet's loop runs a tick ``sim.board.HALT_AFTER_S`` (9.5 periods) or more late, every
board runs it as a halted MCU's: its receive FIFO kept 3 frames and overran the rest, so the
firmware lost frames the bus carried and took them as one step (or refused it and re-primed,
COUNTER_RESET): the halt is the rig's fault. Between two halts the firmware hears every frame
again, and its pose must move exactly as a float64 reference stepped with those frames moves.

``HaltStretches`` judges each *stretch* so, like a set-pose: the reference re-starts at the
firmware's pose (its *base* sample) once the firmware has taken the frames after the halt
(the base names a frame ``RESYNC_FRAMES`` releases after the halted tick or later: by then a
refused step has been re-primed, ``firmware.encoders``), and steps with every encoder frame the
tracker accepted; the stretch ends at the next halt (a sample made at or after it belongs to
the next). A pose step inside a stretch that the reference does not make is wrong.

The re-start itself, the samples from the halt up to the new base, is judged across the halt
(``host.mqtt.haltcross``): the stretch before it (before the first halt: one based
``BEFORE_SAMPLES`` samples before it and narrowed by them) is stepped with the frames sent
during the halt in each way the halted MCU could have taken them (its FIFO's frames, then the
first after the halt merged or re-primed on), and a sample no way explains is wrong. That
needs the loop's gap before each halt (``halt_gaps``, ``sim.fleet.Fleet.halt_gaps``), one halt
since the latest sample and the frames in the tracker's window; else the re-start is not
judged (counted apart: ``restarts_judged``). A judged re-start's new stretch keeps the offsets
the surviving paths allow at its base, one triple a path, as long as its samples meet one of
them (``host.mqtt.haltcarry``, counted: ``restarts_carried``), not only its base's rounding,
so a shift under one LSB at every halt adds up halt after halt until it shows.

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

import itertools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from odocan.firmware.encoders import RESYNC_FRAMES
from odocan.host.judge.livepose import Sample
from odocan.host.judge.reference import ReferenceOdometry
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.haltcarry import carry_offsets, keep_offsets
from odocan.host.mqtt.haltcross import ENC, Crossing
from odocan.host.mqtt.haltpath import (
    Frame,
    Stretch,
    frames_from,
    narrow_offsets,
    step_frames,
)
from odocan.sim.board import TICK_S

BEFORE_SAMPLES = 50  # samples before the first halt its stretch is narrowed by (2 s of poses)


@dataclass
class Wrong:
    """The first wrong stretch or re-start: bus time (s) of its sample whose interval emptied,
    its encoder frame (seq), which pose field (``haltcross.ENC``: the frame it names), by how
    much beyond the rounding (LSB), the stretch's base time (s) or (``across``) the halt's."""

    t_s: float
    seq: int
    field: str
    excess_lsb: float
    base_t_s: float
    across: bool = False

    def text(self) -> str:
        """``x 2.04 LSB beyond the rounding at 4.81 s (enc 480), in the stretch from 4.62 s``."""
        if self.across:
            what = (f"ENC_COUNTER names no frame the halted firmware could have taken last at "
                    f"{self.t_s:.2f} s" if self.field == ENC else
                    f"{self.field} {self.excess_lsb:.2f} LSB beyond the pose signals' rounding "
                    f"at {self.t_s:.2f} s (enc {self.seq})")
            return (f"{what}, across the halt at {self.base_t_s:.2f} s: no way the halted "
                    "firmware could have taken the frames sent meanwhile (its FIFO's, then the "
                    "first after the halt merged or re-primed) brings the stretch before it there")
        return (f"{self.field} {self.excess_lsb:.2f} LSB beyond the pose signals' rounding at "
                f"{self.t_s:.2f} s (enc {self.seq}), inside the stretch re-started at "
                f"{self.base_t_s:.2f} s: a pose step the reference does not make")


class HaltStretches:
    """One robot's samples after the loop's first halt, judged stretch by stretch (module
    docstring). ``halt_ticks``: the fleet's halted ticks as the loop appends them
    (``sim.fleet.Fleet.halt_ticks``, ascending, read as it grows); ``offset_ticks``: how many
    fleet ticks this robot's clock starts late (its bus time = (k - offset) * TICK_S)."""

    def __init__(self, tracker: PoseTracker, halt_ticks: Sequence[int], offset_ticks: int,
                 halt_gaps: Sequence[int] | None = None) -> None:
        self.tracker = tracker
        self._halt_ticks, self._offset = halt_ticks, offset_ticks
        self._halt_gaps = halt_gaps  # each halt's periods since the tick run before it
        self._crossing: Crossing | None = None  # the latest halt's, until its new base
        self._before: deque[Sample] = deque(maxlen=BEFORE_SAMPLES)  # the latest before the
        # first halt (``_stretch_before``)
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
        self.restarts_seen = 0  # halts taken (each a re-start of the firmware's pose)
        self.restarts_judged = 0  # ... whose samples up to the new base were judged across it
        self.wrong_restarts = 0
        self.judged_across = 0  # samples judged across a halt (``haltcross``)
        self.restarts_carried = 0  # ... whose paths' offsets the next stretch kept

    def on_samples(self, samples: list[Sample]) -> None:
        """The tracker's samples settled (``PoseTracker.take_samples``), in order."""
        for sample in samples:
            self._on_sample(sample)

    def _on_sample(self, sample: Sample) -> None:
        taken = self._consume_halts(sample.t_s)
        if taken:
            self._cross(taken)
            self._stretch = None
        starts, restarted = self.tracker.reference_starts, False
        if starts != self._starts:  # a reboot, a set-pose: a stretch based before it ends
            self._starts, restarted = starts, self._stretch is not None
            self._crossing = None
            self._before.clear()  # samples of a reference before it
        if self.halt_s is None:
            self._before.append(sample)  # before the first halt: the tracker judges them
            return
        self.after += 1
        if restarted:
            self._stretch, self.halt_s, self._crossing = None, math.inf, None  # no new base
            return  # before the next halt
        if self._stretch is None:
            self._judge_crossing(sample)
            self._start(sample)
            if self._stretch is not None and self._crossing is not None:
                self._carry(self._crossing, self._stretch, sample)
                self._crossing = None  # the halt's re-start judged up to the new base
                self.restarts_judged += 1
        elif self._step_to(self._stretch, sample.pose.seq):
            self._compare(self._stretch, sample)
        else:
            self._stretch, self.halt_s = None, math.inf

    def _consume_halts(self, t_s: float) -> int:
        """Take the halts at or before bus time ``t_s`` (a sample made at a halted tick, sent
        1 ms after it, is the next stretch's); how many were taken."""
        ticks, taken = self._halt_ticks, 0
        while self._next < len(ticks):
            halt_s = max(ticks[self._next] - self._offset, 0) * TICK_S
            if halt_s > t_s:
                break
            self.halt_s, taken = halt_s, taken + 1
            self._next += 1
        return taken

    def _cross(self, taken: int) -> None:
        """The samples from the halt just taken on are judged across it (``haltcross``) from
        the stretch judged before it (before the first halt: ``_stretch_before``), when
        that is the only halt since the latest sample and the loop told its gap; an open
        crossing of an earlier halt ends unsettled (its re-start not judged)."""
        self._crossing = None
        self.restarts_seen += taken
        gaps, index = self._halt_gaps, self._next - 1
        if taken != 1 or gaps is None or index >= len(gaps) or self.halt_s is None:
            return
        before = self._stretch
        if index == 0 and before is None and self._before:
            before = self._stretch_before()
        if before is None or before.wrong:
            return
        last_run_s = max(self._halt_ticks[index] - gaps[index] - self._offset, 0) * TICK_S
        self._crossing = Crossing(before, self.tracker, self._bound, self.halt_s, last_run_s)

    def _judge_crossing(self, sample: Sample) -> None:
        """``sample`` judged across the latest halt (``haltcross``), while its crossing is open."""
        crossing = self._crossing
        if crossing is None:
            return
        if not crossing.judge(sample):
            self._crossing = None  # lost: this halt's re-start not judged
            return
        self.judged += 1
        self.judged_across += 1
        if crossing.wrong is None:
            return
        self._crossing = None
        self.wrong_restarts += 1
        self.restarts_judged += 1
        if self.first_wrong is None:
            self.first_wrong = Wrong(sample.t_s, sample.pose.seq, *crossing.wrong,
                                     crossing.halt_s, across=True)

    def _carry(self, crossing: Crossing, stretch: Stretch, sample: Sample) -> None:
        """The new stretch keeps the offsets the crossing's surviving paths allow at its base
        (``host.mqtt.haltcarry``); wrong when none of them is within the base's rounding."""
        paths = crossing.survivors()
        carried = None if paths is None else carry_offsets(paths, stretch)
        if carried is None:
            return
        _, emptied = keep_offsets(stretch, carried)
        if emptied is None:
            self.restarts_carried += 1
            return
        stretch.wrong = True
        self.wrong_stretches += 1
        if self.first_wrong is None:
            self.first_wrong = Wrong(sample.t_s, sample.pose.seq, *emptied, stretch.base_t_s)

    def _start(self, sample: Sample) -> None:
        """``sample`` is the stretch's base when its frame came ``RESYNC_FRAMES`` releases after
        the halt or later (module docstring) and the reference's integrator is known."""
        assert self.halt_s is not None
        rows = frames_from(self.tracker, sample.pose.seq)
        if rows and rows[0][2] < self.halt_s + (RESYNC_FRAMES - 0.5) * TICK_S:
            return
        self._stretch = self._stretch_at(sample, rows)
        if self._stretch is not None:
            self.stretches += 1

    def _stretch_before(self) -> Stretch | None:
        """The stretch the first halt is judged from: based at the earliest sample kept before
        it (``BEFORE_SAMPLES``) and narrowed by every later one, so it carries their offsets
        (based at the latest alone it allowed its rounding, +-half an LSB, and a shift at each
        halt hid in it: ``host.mqtt.haltcarry``); based at the latest when a frame between them
        is missing or beyond the per-period bound, or a sample does not fit."""
        samples, latest = self._before, self._before[-1]
        stretch = self._stretch_at(samples[0])
        if stretch is None:
            return self._stretch_at(latest)
        for sample in itertools.islice(samples, 1, None):
            if not self._step_to(stretch, sample.pose.seq) \
                    or narrow_offsets(stretch, sample.pose) is not None:
                return self._stretch_at(latest)
        return stretch

    def _stretch_at(self, sample: Sample, rows: list[Frame] | None = None) -> Stretch | None:
        """A stretch based at ``sample`` (its reference primed at the frame it names; None
        when that frame is not in the window or the integrator is not known)."""
        if rows is None:
            rows = frames_from(self.tracker, sample.pose.seq)
        integrator = self.tracker.integrator
        if not rows or rows[0][0] != sample.pose.seq or integrator is None:
            return None
        seq, counter, _, left, right = rows[0]
        pose = sample.pose
        ref = ReferenceOdometry(self.tracker.geometry, integrator, self.tracker.counter_bits,
                                x_m=pose.x_m, y_m=pose.y_m, heading_rad=pose.heading_rad)
        ref.step_counts(left, right)  # primes
        return Stretch(sample.t_s, ref, seq, counter, pose.x_m, pose.y_m)

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
        emptied = narrow_offsets(stretch, sample.pose)  # and the boxes carried (haltcarry)
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
                "samples_judged_across_halts": self.judged_across,
                "stretches": self.stretches, "wrong_stretches": self.wrong_stretches,
                "restarts": self.restarts_seen, "restarts_judged": self.restarts_judged,
                "wrong_restarts": self.wrong_restarts, "restarts_carried": self.restarts_carried,
                "first_wrong": None if first is None else first.text()}

    def tally(self) -> str:
        """``1 of 12 stretches between halts wrong, 0 of 13 re-starts at them`` (a FAIL's)."""
        return (f"{self.wrong_stretches} of {self.stretches} stretches between halts wrong, "
                f"{self.wrong_restarts} of {self.restarts_judged} re-starts at them judged")

