"""``lsbround.rounded``: ``round(value, decimals)``'s very float (its ``repr``, which the JSON
carries), without ``round``'s decimal conversion where the scaled value is near an integer:
every LSB field of every publication goes through it (``bench/bridge_frames.py``'s digest of
a fleet's publications holds the bytes; here the edges: zeros and their signs, ties, values
too large for the shortcut, non-decimal LSBs such as HEADING's 2 pi / 65536 rad)."""

from __future__ import annotations

import math
import random

import pytest

from odocan.host.mqtt.lsbround import rounded

HEADING_LSB = 2 * math.pi / 65536


def _same(value: float, decimals: int) -> bool:
    return repr(rounded(value, decimals, 10**decimals)) == repr(round(value, decimals))


@pytest.mark.parametrize("decimals", range(12))
def test_decoded_values_round_as_round_does(decimals: int) -> None:
    rng = random.Random(decimals)
    raws = [rng.randint(-10**7, 10**7) for _ in range(3000)]
    values = [raw * 10.0**-decimals for raw in raws] + [raw * HEADING_LSB for raw in raws]
    values += [rng.uniform(-1e4, 1e4) for _ in range(3000)]
    assert [v for v in values if not _same(v, decimals)] == []


@pytest.mark.parametrize("value", [0.0, -0.0, 5e-324, -5e-324, 1e-300, 0.5, 1.5, 2.5, -2.5,
                                   0.00015, 0.00025, 1e12, -1e15, 2.0**40, 2.0**60, 1e300])
def test_zeros_ties_and_large_values_round_as_round_does(value: float) -> None:
    assert [d for d in range(12) if not _same(value, d)] == []


def test_ties_at_the_decimals_asked_round_as_round_does() -> None:
    rng = random.Random(7)
    ties = [(rng.randint(-10**6, 10**6) + 0.5) / 10**d for d in range(8) for _ in range(500)]
    assert [v for v in ties for d in range(8) if not _same(v, d)] == []
