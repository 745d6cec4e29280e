"""When a WHEEL_ENCODERS step is too long to read: its counts ambiguous mod the counters' range.

A step whose plausibility bound (its periods times a period's most counts) reaches half the
range the counts are read in is ambiguous: after a silence that long any wire delta is as
plausible as one a whole range away (kobuki's 16-bit counters after 3.9 s of silence at full
speed). The firmware never integrates such a guess: it re-primes on the frame (COUNTER_RESET,
latched as a restart's; the pose keeps its value, the silence's motion is lost). Taken mod 2^16
(``odocan run --robot kobuki --faults busoff=5:30``) the pose went 788 mm off and back to OK.

C: ``least_ambiguous_periods`` in firmware/c/ecu.c.
"""

from __future__ import annotations


def least_ambiguous_periods(bits: int, bounds: tuple[int, int], periods_max: int) -> int:
    """The fewest step periods whose plausibility bound reaches half the range the counts
    are read in (the counters' width, at most the wire's 24 bits) on either wheel: from
    there every wire delta is plausible, the one read (mod the range) as much as the ones a
    whole range away, so the step is ambiguous and never integrated (``on_frame``: the
    odometry re-primes on the frame, COUNTER_RESET; kobuki: 16-bit counters, 84 counts a
    period, 391 periods). ceil(half / counts per period) of the larger wheel bound (u64
    at configuration time; at least 1), at most ``periods_max``: a bound saturated
    there no longer knows the elapsed time. C: the end of ``step_bounds``.

    ``bits``: the width the counts are read in (the counters', at most the wire's 24);
    ``bounds``: each wheel's most counts a period; ``periods_max``: STEP_PERIODS_MAX.
    """
    half = 1 << (bits - 1)
    left_max, right_max = bounds
    most = left_max if left_max > right_max else right_max  # >= 1
    least = (half + most - 1) // most
    return least if least < periods_max else periods_max  # saturated: unknown
