"""The live judge's placement after a hold or stall, narrowed to what the firmware's own two
poses and the bus permit (issue #11, rule 3: a PASS never hides a wrong pose).

The live E2E model (``E2EMonitor``) decides each encoder frame as it comes, before the poses that
prove the firmware refused it are heard: on a jittered capture of a delayed drive it takes
lock-out frames the firmware refused, its sender numbering then sees gaps the firmware never
had, and the placement after the hold (``liveplace.StallPlacer.shift``) was bounded by those
gaps' allowances (9.9 mm on kobuki, seed 3, ``delay=0.1:15``, jitter seed 0), which hid a
firmware 1 mm off after one lock-out (``tests/test_live_jitter_lockout``).

What the evidence permits, whatever the E2E model took: the firmware's pose P (the last sample
compared) and its pose Q (the sample placed) name frames it took. Between them it took a
subset of the encoder frames the bus carried, in the order they came (its receiver drains its
mailbox in order; a frame refused, lost from its mailbox or refused as implausible is one it did
not take), and in sender order: Profile 2 takes a frame older than its last only with a window
of 14 or more, i.e. 13 periods or more after its last frame, and a frame held back that much
longer than the one after it is beyond the numbering's premise (frames held back less than half
a COUNTER cycle, as ``livefill`` numbers them). Where a frame of every sender number between
P's and Q's is heard (accepted or refused, CRC right: no hole) and none re-primed, its position
moved from P by the one-by-one steps of those frames in sender order (``d``, from P's heading)
within their worst merge error over any subset (``breaks.merge_allowance_m``: frames skipped
in runs), summed over the runs between the frames its poses in between name (each taken),
where only one frame fits a pose's ENC_COUNTER (``pose_named``; the tracker cannot resolve
them where its model refused the frame, and after a stall its names of backlog frames are not
sure: a correct firmware was 0.125 mm beyond with them). So Q lies within that of P + d,
plus P's and Q's rounding (half an LSB on each axis each) and P's heading's (half an LSB,
turning d). The error this leaves (``excess_m``, 0 for a firmware that did so) is kept in the
placed sample: the larger of the two is judged. On the kobuki drive the poses from 0.06 to
0.76 s named none of the frames the live model took: one run of 72 frames allowed 11 mm; cut
at the frames the poses name, the wrong firmware's step shows (0.82 mm beyond; pmir 0.67 mm).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from odocan.host.judge.breaks import merge_allowance_m
from odocan.host.judge.livepose import FramePose
from odocan.host.judge.losses import OneSteps
from odocan.host.judge.reference import Geometry, wrap_delta
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP

BUS_KEPT = 192  # the latest CRC-right encoder frames kept in bus order
MAX_SPAN_FRAMES = 128  # sender periods: longer spans are not checked (the DP is n^2)
LATE_CYCLES = 1.0  # a frame's typical lateness on the bus (periods): the numbering's centre
COUNTER_MODULO = ENC_COUNTER_LAP  # 16
ROUND_SLACK_M = 1e-7  # float64 against the firmware's integer arithmetic over a span (m)

Heard = tuple[int, int, int, int, float]  # accepted seq (-1: refused), COUNTER, left, right,
# bus time s
Counts = tuple[int, int]  # raw left, right
Named = tuple[int, float]  # a pose half's ENC_COUNTER, bus time s


class BusOrder:
    """The latest CRC-right WHEEL_ENCODERS frames in the order the bus carried them, accepted
    by the live E2E model or refused, and the firmware's pose at the last sample compared."""

    def __init__(self, cycle_s: float) -> None:
        self.cycle_s = cycle_s  # the encoder frames' cycle (s)
        self._heard: deque[Heard] = deque(maxlen=BUS_KEPT)
        self.last_pose: FramePose | None = None  # the firmware's, at the last sample compared

    def heard(self, seq: int, counter: int, left: int, right: int, t_s: float) -> None:
        """An encoder frame, accepted as ``seq`` or refused (-1); its COUNTER, raw counts, bus
        time s."""
        self._heard.append((seq, counter, left, right, t_s))

    def restart(self) -> None:
        """A new reference: no pose to measure from."""
        self.last_pose = None

    def chain(self, first: int, last: int, halves: list[Named] | None = None
              ) -> list[list[Counts]] | None:
        """The counts the firmware may have stepped through from accepted frame ``first`` to
        ``last`` (seq), in sender order (module docstring): both ends, and one frame of every
        sender number between them heard between them, cut into runs at the frames the pose
        ``halves`` (ENC_COUNTER, bus time s; ``pose_named``) name for sure (each run from one
        frame taken to the next); None when either is no longer kept, the span is too long,
        a sender number between them was never heard (a hole: the firmware may have taken a
        frame the host lacks) or two frames of one number differ."""
        rows = list(self._heard)
        ends = [i for i, row in enumerate(rows) if row[0] in (first, last)]
        if len(ends) != 2 or rows[ends[0]][0] != first:
            return None
        numbers = _numbers(rows, rows[ends[0]], self.cycle_s)
        n_first, n_last = numbers[ends[0]], numbers[ends[1]]
        if not 0 < n_last - n_first <= MAX_SPAN_FRAMES or not set(
                range(n_first, n_last + 1)) <= set(numbers):
            return None
        between: dict[int, Counts] = {}
        cuts = {n_first, n_last}
        for i in range(ends[0], ends[1] + 1):
            counts = (rows[i][2], rows[i][3])
            if between.setdefault(numbers[i], counts) != counts:
                return None  # two frames of one number differ: which one it took is unknown
        span = rows[ends[0]:ends[1] + 1]
        cuts |= {n for n in pose_named(span, numbers[ends[0]:ends[1] + 1], halves or [])
                 if n_first < n < n_last}
        kept = [n for n in sorted(between) if n_first <= n <= n_last]
        runs: list[list[Counts]] = [[]]
        for n in kept:
            runs[-1].append(between[n])
            if n in cuts and n != n_first and n != n_last:
                runs.append([between[n]])
        return runs


def pose_named(span: list[Heard], numbers: list[int], halves: list[Named]) -> set[int]:
    """The sender numbers of the frames pose ``halves`` (ENC_COUNTER, bus time s, in the order
    heard) name within ``span`` (the frames heard from P's to Q's, ``numbers`` theirs), where
    that is sure. The firmware's last frame only moves on in sender order, so a half heard
    after P's frame names a frame from the last sure one (first P's) to Q's, heard before the
    half: where exactly one frame of its COUNTER is such, it is that one (after a stall the
    firmware names frames of its backlog, heard long before: several fit, none is taken). The
    halves from the first naming Q's COUNTER after Q's frame was heard on are Q's or later."""
    arrival: dict[int, float] = {}
    for row, number in zip(span, numbers, strict=True):
        arrival.setdefault(number, row[4])
    floor, last, first_s = numbers[0], numbers[-1], span[0][4]
    sure: set[int] = set()
    for counter, t_s in halves:
        if t_s <= first_s:
            continue
        if counter == span[-1][1] and t_s >= span[-1][4]:
            break
        fits = [n for n in range(floor, last + 1)
                if n % COUNTER_MODULO == counter and arrival.get(n, math.inf) < t_s]
        if len(fits) == 1:
            floor = fits[0]
            sure.add(floor)
    return sure


def _numbers(rows: list[Heard], anchor: Heard, cycle_s: float) -> list[int]:
    """Each frame's sender number, counted from ``anchor``'s COUNTER: the one of its COUNTER
    nearest its bus time's (frames held back less than half a COUNTER cycle more than the
    anchor are numbered right; ``livefill`` numbers refused frames so too)."""
    counter0, t0_s, half = anchor[1], anchor[4], COUNTER_MODULO // 2
    numbers = []
    for row in rows:
        near = round(counter0 + (row[4] - t0_s) / cycle_s - LATE_CYCLES)
        numbers.append(near + ((row[1] - near + half) % COUNTER_MODULO) - half)
    return numbers


def excess_m(before: FramePose, after: FramePose, runs: list[list[Counts]],
             reference: tuple[Geometry, int, str]) -> float:
    """How far (m) the firmware's pose ``after`` lies beyond where its steps over ``runs``
    (``BusOrder.chain`` from the frame ``before`` names to the one ``after`` names) can take it
    from ``before`` (module docstring); 0 within."""
    geometry, bits, integrator = reference
    chain = [runs[0][0], *(counts for run in runs for counts in run[1:])]
    left = np.array([counts[0] for counts in chain], dtype=np.int64)
    right = np.array([counts[1] for counts in chain], dtype=np.int64)
    dl, dr = wrap_delta(np.diff(left), bits), wrap_delta(np.diff(right), bits)
    steps = OneSteps.of_deltas(dl, dr, geometry, integrator)
    cos_h, sin_h = math.cos(before.heading_rad), math.sin(before.heading_rad)
    dx, dy = float(steps.cum_x[-1]), float(steps.cum_y[-1])
    moved_x, moved_y = cos_h * dx - sin_h * dy, sin_h * dx + cos_h * dy
    merge_m = sum(merge_allowance_m(np.array([c[0] for c in run], dtype=np.int64),
                                    np.array([c[1] for c in run], dtype=np.int64),
                                    geometry, bits, integrator) for run in runs)
    bound = (merge_m
             + POSITION_LSB_M * math.sqrt(2.0) + 0.5 * HEADING_LSB_RAD * math.hypot(dx, dy)
             + ROUND_SLACK_M)
    off = math.hypot(after.x_m - before.x_m - moved_x, after.y_m - before.y_m - moved_y)
    return max(0.0, off - bound)
