"""The twin allowance (issue #11): how far a correct firmware's position may leave the reference
because of an encoder frame with a *twin* (``samples.twinned_encoder_frames``), shared by the
whole-log and the live judge (``host.judge.livetwins``).

The host integrates the frame it accepted; the firmware may have taken the twin instead (its
mailbox keeps whichever it was given), or lost both. The heading is exact for every integrator
(a function of the cumulative counts), so after the next accepted frame only the position differs,
and by a constant vector from then on: the difference between the steps prev -> accepted -> next
and prev -> twin -> next (or prev -> next, both lost), as ``losses.step_vector`` takes them.
Its length does not depend on the heading at prev (a rotation of both paths), so it is computed
from heading 0. With twins on consecutive frames the firmware's prev may itself be a twin: the
path's difference telescopes into one term per twinned frame, each with the prev the firmware
took, so the worst over the prev's choices (the accepted one and its twins) bounds it, and the
terms' lengths, summed over the twins before a frame, bound the position there (rule 5: a FAIL
must never blame a correct firmware; a real error beyond the sum still fails)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from odocan.host.judge.losses import heading_steps, step_vector
from odocan.host.judge.reference import Geometry, wrap_delta
from odocan.host.judge.reference_path import Reference
from odocan.host.judge.samples import WIRE_COUNTER_BITS, Encoders, FloatArray, IntArray
from odocan.host.protocol.busfacts import ENC_PERIOD_US as ENCODER_PERIOD_US
from odocan.sim.robot import RobotProfile

Counts = tuple[int, int]  # wire LEFT_COUNT, RIGHT_COUNT


def _step(a: Counts, b: Counts, h_m: float, g: Geometry, bits: int, integrator: str
          ) -> tuple[float, float, float]:
    """One step from counts ``a`` at heading ``h_m`` (rad) to counts ``b``: (dx m, dy m, the
    heading after it rad)."""
    dl = np.array([int(wrap_delta(b[0] - a[0], bits))], dtype=np.int64)
    dr = np.array([int(wrap_delta(b[1] - a[1], bits))], dtype=np.int64)
    h_new = h_m + float(heading_steps(dl, dr, g)[0])
    dx, dy = step_vector(dl, dr, np.array([h_m]), np.array([h_new]), g, integrator)
    return float(dx[0]), float(dy[0]), h_new


def _two_steps(a: Counts, mid: Counts | None, b: Counts, g: Geometry, bits: int,
               integrator: str) -> tuple[float, float]:
    """The displacement (m) from counts ``a`` (heading 0) through ``mid`` (None: one step) to
    ``b``."""
    if mid is None:
        dx, dy, _ = _step(a, b, 0.0, g, bits, integrator)
        return dx, dy
    dx1, dy1, h1 = _step(a, mid, 0.0, g, bits, integrator)
    dx2, dy2, _ = _step(mid, b, h1, g, bits, integrator)
    return dx1 + dx2, dy1 + dy2


def counts_bound(g: Geometry) -> Counts:
    """The most counts per period each wheel may step for the firmware to take it: the
    reference's plausibility bound (``reference_path.firmware_steps``)."""
    travel_m = g.max_wheel_speed_mm_s * 1e-3 * ENCODER_PERIOD_US * 1e-6
    return (math.ceil(travel_m / g.m_per_count_left) + 1,
            math.ceil(travel_m / g.m_per_count_right) + 1)


def _plausible(a: Counts, b: Counts, periods: int, g: Geometry, bits: int) -> bool:
    """Whether the firmware takes a step from counts ``a`` to ``b`` over ``periods``."""
    left, right = counts_bound(g)
    return (abs(int(wrap_delta(b[0] - a[0], bits))) <= periods * left
            and abs(int(wrap_delta(b[1] - a[1], bits))) <= periods * right)


def twin_detour_m(prevs: Sequence[Counts], accepted: Counts, twins: Sequence[Counts],
                  nxt: Counts, periods: tuple[int, int], g: Geometry, bits: int,
                  integrator: str) -> float:
    """The worst position difference (m) after ``nxt`` between taking ``accepted`` and taking
    one of its ``twins`` (or neither), from any of ``prevs`` (the frame before and its twins).
    A twin the firmware would refuse as implausible (a step from prev or to ``nxt`` beyond the
    reference's bound over ``periods``: the COUNTER steps before and after the frame) counts
    as neither taken (a random forgery's counts: its detour would be meters); so does a twin
    of the frame before that the firmware could not have gone on from to ``accepted``. An
    implausible ``accepted`` is refused by the reference too (``firmware_steps``): one step."""
    worst = 0.0
    for prev in [prevs[0], *(p for p in prevs[1:] if _plausible(p, accepted, periods[0], g, bits))]:
        taken = accepted if _plausible(prev, accepted, periods[0], g, bits) else None
        ax, ay = _two_steps(prev, taken, nxt, g, bits, integrator)  # the reference refuses it
        for mid in (*twins, None):
            if mid is not None and not (_plausible(prev, mid, periods[0], g, bits)
                                        and _plausible(mid, nxt, periods[1], g, bits)):
                continue
            tx, ty = _two_steps(prev, mid, nxt, g, bits, integrator)
            worst = max(worst, float(np.hypot(tx - ax, ty - ay)))
    return worst


def twin_spans(enc: Encoders, g: Geometry, bits: int, integrator: str, after: int
               ) -> list[tuple[int, float]]:
    """(accepted encoder frame k, its ``twin_detour_m``) for every twinned frame k > ``after``
    with a frame before and after it (``enc.twins``: per twin, k and its counts)."""
    if enc.twins is None:
        return []
    of: dict[int, list[Counts]] = {}
    for k, left, right in zip(*(a.tolist() for a in enc.twins), strict=True):
        twins = of.setdefault(k, [])
        if (left, right) not in twins:  # a twin repeated is one option
            twins.append((left, right))
    counts = list(zip(enc.left.tolist(), enc.right.tolist(), strict=True))
    spans = []
    for k in sorted(of):
        if k <= max(after, 0) or k + 1 >= len(counts):
            continue
        prevs = [counts[k - 1], *of.get(k - 1, [])]
        periods = (max(1, int(enc.seq[k] - enc.seq[k - 1])),
                   max(1, int(enc.seq[k + 1] - enc.seq[k])))
        spans.append((k, twin_detour_m(prevs, counts[k], of[k], counts[k + 1], periods, g, bits,
                                       integrator)))
    return spans


def twin_allowance(spans: list[tuple[int, float]], at: IntArray) -> FloatArray:
    """The twin allowance (m) at encoder frames ``at``: the spans' detours before each, summed
    in order (as ``livelosses.LiveAllowance.at_m`` sums them)."""
    allowance = np.zeros(len(at))
    for k, detour_m in spans:
        allowance += np.where(at > k, detour_m, 0.0)
    return allowance


def twin_allowance_of(enc: Encoders, robot: RobotProfile, integrator: str, ref: Reference,
                      at: IntArray, *, record: bool = True) -> FloatArray:
    """``twin_allowance`` at encoder frames ``at`` for the twins after ``ref``'s start (the
    whole-log judge's), their count and largest sum noted in ``ref.placements`` (the report's
    ``reference_breaks``; ``record`` False: not noted, the lone halves' frames)."""
    spans = twin_spans(enc, Geometry.of(robot), min(robot.counter_bits, WIRE_COUNTER_BITS),
                       integrator, ref.start)
    allowance = twin_allowance(spans, at)
    if not record:
        return allowance
    ref.placements.twins = len(spans)
    ref.placements.twin_allowance_m = float(np.max(allowance, initial=0.0))
    return allowance
