"""A gap inside a run the pages prove the firmware received exactly the log's frames over
(``host.judge.gapreceived``, issue #11 rule 5): it can have taken only frames the log holds, so
the gap is bounded by the merge errors over them, not by ``gapbound``'s worst split.

The bound is checked here against a float64 exact-arc odometry written for the test: every
subset of the frames the log holds in a turning gap (a firmware taking some, in sequence order)
ends within the allowance of the one merged step the reference takes. The whole-drive case
(pmir straight 423: 617 mm and 238 mm gaps to 0, a +10 mm tamper FAILed) is
``tests/test_gap_tamper_trial.py``'s.
"""

from __future__ import annotations

import itertools
import math

from odocan.host.judge.gapbound import gap_allowance_of_counts
from odocan.host.judge.gapreceived import MARGIN_FRAMES, received_allowance_m, received_fill
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.reference import PROFILE_SPEED, Geometry
from odocan.sim.robot import load

GEOMETRY = Geometry.of(load("pmir"))
BITS = 16
# a turning gap of 7 periods: the frames the log holds at periods 1, 2, 4 and 5 after the
# frame before it (3 and 6 lacked: the firmware received neither), counts (left, right)
BEFORE, AFTER, PERIODS = (0, 0), (40, 96), 7
FILL = [(1, (20, 2)), (2, (26, 30)), (4, (30, 70)), (5, (42, 74))]


def _arc_end(frames: list[tuple[int, int]], geometry: Geometry = GEOMETRY
             ) -> tuple[float, float]:
    """The position (m) after exact-arc steps between consecutive wire counts ``frames``."""
    x = y = heading = 0.0
    for (l0, r0), (l1, r1) in itertools.pairwise(frames):
        dl = (l1 - l0) * geometry.m_per_count_left
        dr = (r1 - r0) * geometry.m_per_count_right
        ds, turn = 0.5 * (dl + dr), (dr - dl) / geometry.wheelbase_m
        chord = ds if turn == 0.0 else ds * math.sin(0.5 * turn) / (0.5 * turn)
        x += chord * math.cos(heading + 0.5 * turn)
        y += chord * math.sin(heading + 0.5 * turn)
        heading += turn
    return x, y


def _allowance(fill: list[tuple[int, tuple[int, int]]]) -> float:
    return received_allowance_m(fill, BEFORE, AFTER, PERIODS, GEOMETRY, BITS, "exact",
                                PROFILE_SPEED)


def test_every_firmware_taking_frames_the_log_holds_ends_within_the_allowance() -> None:
    allowance = _allowance(FILL)
    ref = _arc_end([BEFORE, AFTER])
    worst = 0.0
    for n in range(len(FILL) + 1):
        for taken in itertools.combinations([c for _, c in FILL], n):
            fw = _arc_end([BEFORE, *taken, AFTER])
            worst = max(worst, math.hypot(fw[0] - ref[0], fw[1] - ref[1]))
    assert 0.5 * allowance < worst <= allowance + 1e-12, (worst, allowance)  # 3.6, 5.4 mm
    gapbound = gap_allowance_of_counts(BEFORE, AFTER, PERIODS, GEOMETRY, BITS, "exact",
                                       PROFILE_SPEED)
    assert allowance < gapbound / 10, (allowance, gapbound)  # 5.4 mm against 76 mm


def test_nothing_held_is_one_merged_step_and_an_implausible_one_keeps_gapbound() -> None:
    assert _allowance([]) == 0.0  # the firmware took the gap as the reference's one step
    assert received_allowance_m(None, BEFORE, AFTER, PERIODS, GEOMETRY, BITS, "exact",
                                PROFILE_SPEED) == math.inf
    far = [(1, (400, 10))]  # 400 counts in one period: beyond pmir's 4 m/s (a forgery)
    assert _allowance(far) == math.inf


def test_only_a_run_with_margin_and_no_reprime_proves_the_fill() -> None:
    lo, hi = 100, 200
    seen = Seen([], [], received=[(lo, hi)], known={150: FILL, lo + MARGIN_FRAMES: FILL,
                                                    lo + MARGIN_FRAMES + 1: FILL})
    assert received_fill(seen, 150) == FILL
    assert received_fill(seen, lo + MARGIN_FRAMES) is None  # a held frame may predate the run
    assert received_fill(seen, lo + MARGIN_FRAMES + 1) == FILL
    assert received_fill(seen, 150, frozenset({120})) is None  # a counter restart re-primed
    assert received_fill(Seen([], [], known={150: FILL}), 150) is None  # no run proven


# kobuki figure8 445, ``delay=0.3:55,busoff=5:0.2``: the frame before the gap is the bus-off's
# held frame (COUNTER 1, heard at 5.2028 s, sampled 4.97 s: numbered a COUNTER lap after its
# sample), the frame after it COUNTER 2 at 5.30 s, 17 periods on by COUNTER; the log holds the
# frames at 8..16 periods (heard 5.21..5.29 s, refused by the host's E2E check).
KOBUKI = Geometry.of(load("kobuki"))
HELD_BEFORE, HELD_AFTER, HELD_PERIODS = (19384, 26207), (20696, 27990), 17
HELD_FILL = [(8, (20338, 27504)), (9, (20378, 27558)), (10, (20418, 27612)),
             (11, (20457, 27666)), (12, (20497, 27720)), (13, (20537, 27774)),
             (14, (20577, 27828)), (15, (20616, 27882)), (16, (20656, 27936))]


def test_a_held_frame_before_the_gap_bounds_it_by_the_frames_the_log_holds() -> None:
    """The step out of the frame before the gap (954 counts in 8 periods by COUNTER: beyond
    kobuki's 85 a period) is the held frame's numbering, not a forgery among the gap's frames,
    which step 40 counts a period into the frame after it. Before: inf, and ``gapbound``'s
    20.6 mm absorbed a pose raised 10 mm from the first pose after the bus-off (both analyses
    and both live judges PASSed it, 0.050 to 0.090 mm beyond)."""
    bits = min(load("kobuki").counter_bits, 24)
    allowance = received_allowance_m(HELD_FILL, HELD_BEFORE, HELD_AFTER, HELD_PERIODS, KOBUKI,
                                     bits, "exact", PROFILE_SPEED)
    ref = _arc_end([HELD_BEFORE, HELD_AFTER], KOBUKI)
    worst = 0.0
    for n in range(len(HELD_FILL) + 1):
        for taken in itertools.combinations([c for _, c in HELD_FILL], n):
            fw = _arc_end([HELD_BEFORE, *taken, HELD_AFTER], KOBUKI)
            worst = max(worst, math.hypot(fw[0] - ref[0], fw[1] - ref[1]))
    assert 0.5 * allowance < worst <= allowance + 1e-12, (worst, allowance)
    assert allowance < 1e-4, allowance  # 0.033 mm
    forged = [*HELD_FILL[:4], (12, (21497, 27720)), *HELD_FILL[5:]]  # 1000 counts off
    assert received_allowance_m(forged, HELD_BEFORE, HELD_AFTER, HELD_PERIODS, KOBUKI, bits,
                                "exact", PROFILE_SPEED) == math.inf
