"""A gap inside a run of the log's encoder frames over which the firmware received exactly the
log's frames, whichever of them it accepted (issue #11, rule 5: a PASS must never hide a wrong
pose; ``gapchecked.by_received``, ``gapseen.Seen.received``).

``gapbound`` allows a gap the worst split of its travel into its periods: the firmware may have
taken frames the log lacks (pmir straight seed 423, ``drop=0.05,busoff=6:0.4,delay=0.3:55``:
617 mm for an 18-period gap at 5.84 s, 238 mm for the bus-off's 12 periods, a pose raised 10 mm
from 6.0 s absorbed). The pages there (3.10 s, 6.70 s) prove its E2E check counted exactly the
log's encoder frames between them, nothing dropped (``gapchecked``: N, ENC_E2E_OK's growth plus
the refusals', equals the frames logged), though it accepted 149 where the host accepted 148
(it took a late frame the host refused): no proof that it took the host's frames, but one that
it received none the log lacks. So in the gap it can have taken only frames the log holds: the
ones the host refused there, each placed in the sender's sequence by ``gapfill``'s rule
(``LateFrames.known``: its COUNTER and bus time; two of one number must agree). Those are
frames of known counts, and whichever of them the firmware took, in sequence order, its steps
are runs of the path over them merged, as the reference's one step is: gapfill's bound

    |fw - ref| <= |fw - fine| + |ref - fine| <= 2 * breaks.merge_allowance_m(b-1, known, b)

with the frames the log lacks merged in the fine path too (no firmware took them apart), each
step from a frame of the gap within the plausibility bound over its periods (else a frame may
be a forgery: the gap keeps ``gapbound``'s allowance). The step out of the frame before the gap
is not judged: that frame is one the host and the firmware accepted (its counts the sender's),
and its COUNTER may number it a lap after its sample, which the firmware's bound allows for
(``sampledoubt``, ``step_periods.doubted_bound_periods``) and the gap's periods do not. kobuki
figure8 and circle 445, ``delay=0.3:55,busoff=5:0.2``: the bus-off's held frame (COUNTER 1,
sampled 4.97 s, heard 5.2028 s) is numbered 14 periods after the frame before it; the gap after
it, 17 periods by COUNTER to the frame at 5.30 s, holds the frames heard 5.21..5.29 s, 40
counts a period apart, but 954 counts from it in 8 periods (kobuki's bound: 85 a period). The
gap kept ``gapbound``'s 20.6 mm, and a pose raised 10 mm from the first pose after the bus-off
PASSed both analyses and both live judges (0.050 to 0.090 mm beyond); the frames the log holds
bound it to 0.033 mm (the two analyses and both live judges now FAIL that pose, 9.7 to 9.8 mm
beyond). The gap must lie ``MARGIN_FRAMES`` frames inside the run: a frame of the gap held back
(fewer than 15 periods, gapfill's premise) then reached the firmware between the run's pages,
where the count holds. No counter restart re-primed in the run (the sequence numbers hold).
Shared by the whole-log and the streamed judge (the same ``Seen``), the live judges
(``livegapskips``) and ``replay``'s jumps.
"""

from __future__ import annotations

import math

import numpy as np

from odocan.host.judge.breaks import merge_allowance_m
from odocan.host.judge.gapfill import MAX_LATE_PERIODS, Counts, plausible_steps
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.reference import Geometry, SpeedBound
from odocan.host.judge.samples import Encoders, IntArray

MARGIN_FRAMES = MAX_LATE_PERIODS + 1  # accepted frames between the gap and the run's ends


def received_fill(seen: Seen, frame: int, reprimed: frozenset[int] = frozenset()
                  ) -> list[tuple[int, Counts]] | None:
    """The frames the log holds in the gap into encoder ``frame`` (periods after the frame
    before it, counts) when a run of ``Seen.received`` holds it with ``MARGIN_FRAMES`` either
    side and no counter restart re-primed in it; else None."""
    known = seen.known.get(frame)
    if known is None:
        return None
    inside = any(lo + MARGIN_FRAMES <= frame - 1 and frame + MARGIN_FRAMES <= hi
                 and not any(lo < r <= hi for r in reprimed) for lo, hi in seen.received)
    return known if inside else None


def received_allowance_m(
    fill: list[tuple[int, Counts]] | None, before: Counts, after: Counts, periods: int,
    geometry: Geometry, bits: int, integrator: str, max_wheel_speed_mm_s: SpeedBound,
) -> float:
    """Twice the merge allowance (m) over the frame before the gap, the frames ``fill`` (from
    ``received_fill``) and the frame after it (``periods`` after the one before); inf where
    ``fill`` is None or a step from a frame of ``fill`` lies beyond the plausibility bound over
    its periods (the step out of the frame before is not judged: module docstring)."""
    if fill is None:
        return math.inf
    at = [0, *(k for k, _ in fill), periods]
    left = np.array([before[0], *(c[0] for _, c in fill), after[0]], dtype=np.int64)
    right = np.array([before[1], *(c[1] for _, c in fill), after[1]], dtype=np.int64)
    steps: IntArray = np.diff(np.array(at, dtype=np.int64)).astype(np.int64)
    if not plausible_steps(left[1:], right[1:], steps[1:], geometry, bits, max_wheel_speed_mm_s):
        return math.inf
    return 2.0 * merge_allowance_m(left, right, geometry, bits, integrator)


def received_at(enc: Encoders, b: int, seen: Seen, reprimed: frozenset[int], geometry: Geometry,
                bits: int, integrator: str, max_wheel_speed_mm_s: SpeedBound) -> float:
    """The whole-log judge's ``received_allowance_m`` of the gap into ``enc``'s frame ``b``."""
    return received_allowance_m(
        received_fill(seen, b, reprimed), (int(enc.left[b - 1]), int(enc.right[b - 1])),
        (int(enc.left[b]), int(enc.right[b])), int(enc.seq[b] - enc.seq[b - 1]), geometry,
        bits, integrator, max_wheel_speed_mm_s)
