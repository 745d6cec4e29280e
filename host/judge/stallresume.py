"""A stall is no set-pose (issue #11, H2): the firmware resumes from its own pose.

After a stall the reference's position is placed again at the first sample compared, within
the merge allowance of the frames across it (``breaks``): the worst of every grouping of those
frames into merged steps, the log not saying which the firmware took. On a curve that allowance
is large (pmir, figure8, a 3 s stall: 454.5 mm, a correct firmware's own merge error 446 mm),
and since it bounds the offset's length only, an edit of +10 mm (even +400 mm) on every pose
after the stall was absorbed as a placement: analyze and the monitor PASSed.

But a stalled MCU groups its frames one way: its receive FIFO kept the first few frames after it
halted (taken one by one, or drained at once) and overran the rest, so when it runs again it
steps from the last frame it kept to the first it takes after, once, then on frame by frame. Its
pose at the first sample after the stall (``after``) is the pose it sent before (``before``)
carried over the log's counts that way: fine steps to a frame ``p`` within
``FIFO_FRAMES`` of ``before`` (the FIFO's), one merged step from ``p`` to some ``q``,
fine steps from ``q`` on, each by the firmware's integrator (``losses.step_vector``), from the
exact heading, turned by ``before``'s sent heading (half a heading LSB of rounding over the
candidate's way: 0.26 mm over the 5.33 m a 12-count wheel of 0.27 m radius rolled across a
33-period stall). The sample must lie within the two samples' tolerance, plus the merge allowance
of the FIFO's frames and of the frames just after the resume (a mailbox that dropped some, an
E2E window catching up), of one such candidate. A pose that jumped elsewhere is no placement.
Spans over ``breaks.MAX_MERGE_FRAMES`` frames are not judged by this rule (the placement's
allowance alone, as before).

Nor is a firmware that re-primed across the span by its own plausibility rules one grouping:
under ``delay`` the frames held back 150 ms arrive among the on-time ones, E2E takes both, and
the firmware refused the on-time ones as implausible until three late ones made a counter
restart (re-primed on the first late one), stepped along the late ones, and re-primed back on
the on-time ones once those ran out: two steps left out, not one (kobuki seed 2,
``delay=0.5:150``, the sample at 5.14 s: 0.097 mm beyond every one-grouping candidate, the
firmware's every step within 1/1000 LSB, ``tests.fw_watch``). Those steps are the reference's
own (``reference_path.firmware_steps``, the same rules on the same frames): the position they
reach (``taken``) is one more candidate, exact, within the two samples' tolerance and the
before's heading rounding alone (``taken_excess``)."""

from __future__ import annotations

import math

import numpy as np

from odocan.host.judge.breaks import MAX_MERGE_FRAMES, merge_allowance_m
from odocan.host.judge.losses import OneSteps, step_vector
from odocan.host.judge.reference import Geometry, integrate, wrap_delta
from odocan.host.judge.samples import HEADING_LSB_RAD

FIFO_FRAMES = 16  # frames after the sample before a stall the firmware may have kept (a counter
# cycle of ENC_COUNTER, ``stallfirst.FIFO_FRAMES``: longer than any receive FIFO)


def resume_excess(before: tuple[float, float, float], after: tuple[float, float],
                  counts: tuple[np.ndarray, np.ndarray], robot: tuple[Geometry, str, int],
                  tolerance_m: float, taken: tuple[np.ndarray, np.ndarray] | None = None
                  ) -> float | None:
    """How far (m) the position ``after`` (x, y) lies beyond every one the firmware can reach
    from the pose ``before`` (x, y, heading) over the count steps of the frames from
    ``before``'s to ``after``'s (``counts``: their wire counts, left and right, in order;
    ``robot``: geometry, integrator, wire counter bits), beyond the allowance (module
    docstring); None when the span is not judged here. ``taken``: the ``n`` count steps as the
    firmware's plausibility and restart rules take them (a re-prime's step 0), one more
    candidate."""
    geometry, integrator, bits = robot
    left, right = (np.asarray(v, dtype=np.int64) for v in counts)
    n = len(left) - 1
    if n < 1 or n > MAX_MERGE_FRAMES:
        return None
    steps = OneSteps.of_deltas(wrap_delta(np.diff(left), bits), wrap_delta(np.diff(right), bits),
                               geometry, integrator)
    p = np.arange(min(FIFO_FRAMES, n) + 1)
    pp, qq = np.meshgrid(p, np.arange(n + 1), indexing="ij")
    pp, qq = pp[qq >= pp], qq[qq >= pp]
    mx, my = step_vector(steps.cum_left[qq] - steps.cum_left[pp],
                         steps.cum_right[qq] - steps.cum_right[pp],
                         steps.heading[pp], steps.heading[qq], geometry, integrator)
    tail_x, tail_y = steps.cum_x[n] - steps.cum_x[qq], steps.cum_y[n] - steps.cum_y[qq]
    # or the merged step refused as too long, the firmware re-primed on q (``stallreprime``):
    # its pose kept there, the counts from p to q not integrated, its heading short of them
    skip = steps.heading[pp] - steps.heading[qq]
    x = np.tile(steps.cum_x[pp], 2) + np.concatenate(
        (mx + tail_x, tail_x * np.cos(skip) - tail_y * np.sin(skip)))
    y = np.tile(steps.cum_y[pp], 2) + np.concatenate(
        (my + tail_y, tail_x * np.sin(skip) + tail_y * np.cos(skip)))
    turn = before[2] - float(steps.heading[0])
    want_x, want_y = after[0] - before[0], after[1] - before[1]
    rx = x * math.cos(turn) - y * math.sin(turn)
    ry = x * math.sin(turn) + y * math.cos(turn)
    # each candidate turned by ``before``'s sent heading, within half its LSB of the exact one
    nearest = float(np.min(np.hypot(rx - want_x, ry - want_y)
                           - 0.5 * HEADING_LSB_RAD * np.hypot(rx, ry)))
    edge = min(FIFO_FRAMES, n) + 1
    slack = (2.0 * tolerance_m
             + merge_allowance_m(left[:edge], right[:edge], geometry, bits, integrator)
             + merge_allowance_m(left[-edge:], right[-edge:], geometry, bits, integrator))
    if taken is None or len(taken[0]) != n:
        return nearest - slack
    return min(nearest - slack, taken_excess(before, (want_x, want_y), taken, robot, tolerance_m))


def taken_excess(before: tuple[float, float, float], want: tuple[float, float],
                 taken: tuple[np.ndarray, np.ndarray], robot: tuple[Geometry, str, int],
                 tolerance_m: float) -> float:
    """How far (m) the offset ``want`` (x, y: the sample after less the one before) lies from
    the firmware's own way over the ``taken`` count steps from the pose ``before``, beyond the
    two samples' tolerance and the rounding of ``before``'s heading (half its LSB) over the
    way's length. No merge allowance: the steps are the firmware's, none grouped otherwise;
    each sample is within the tolerance of the firmware's exact pose (its integer arithmetic
    and the wire's LSBs), so their difference is within twice it of the exact way, whose
    direction ``before``'s sent heading gives within half a heading LSB."""
    geometry, integrator, _ = robot
    path = integrate(taken[0], taken[1], geometry, integrator, heading0_rad=before[2])
    way_x, way_y = float(path.x_m[-1]), float(path.y_m[-1])
    rounding_m = 0.5 * HEADING_LSB_RAD * math.hypot(way_x, way_y)
    return math.hypot(way_x - want[0], way_y - want[1]) - 2.0 * tolerance_m - rounding_m
