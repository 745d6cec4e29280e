"""The firmware's ambiguous step, as the judges mirror it (firmware/encoders.py
``_least_ambiguous_periods``): a step whose plausibility bound (its periods times a period's most
counts) reaches half the range the counts are read in (the counters' width, at most the wire's 24
bits) could be any wire delta; the firmware re-primes on its frame (COUNTER_RESET) and integrates
nothing across it. The judges take no step into that frame either; the truth is expected off
there by the silence's motion, which no one on board can know."""

from __future__ import annotations

from odocan.firmware.config import READABLE_PERIODS
from odocan.firmware.encoders import STEP_PERIODS_MAX, WIRE_COUNTER_BITS


def least_ambiguous_periods(bound: tuple[int, int], bits: int) -> int:
    """The fewest periods whose bound (``bound``: counts per period, left and right) reaches half
    the range of ``bits``-bit counters read through the wire: ceil(half / the larger bound),
    at most ``STEP_PERIODS_MAX`` (the firmware's saturated bound); never (above it) for a
    configuration the firmware refuses."""
    half = 1 << (min(bits, WIRE_COUNTER_BITS) - 1)
    most = max(1, bound[0], bound[1])
    least = min(-(-half // most), STEP_PERIODS_MAX)
    # READABLE_PERIODS or fewer: the firmware refuses the configuration (WIRE_RANGE), so no
    # firmware takes such steps to mirror; a synthesized log of one is judged as before
    return least if least > READABLE_PERIODS else STEP_PERIODS_MAX + 1
