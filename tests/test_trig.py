"""odocan.firmware.trig against float64 ``math``, exact identities and closed forms.

The error bounds asserted here are the ones documented in ``firmware/trig.py``: the requirement
(``*_SPEC``) and the tighter design bound (``*_DESIGN``: the final rounding plus the internal error
budget), so a regression of the internal precision fails even while the requirement still holds.
Run with ``pytest -s`` to see the measured maxima.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterable, Iterator
from decimal import localcontext

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.firmware import trig_tables
from odocan.firmware.fixmath import I64_MAX, I64_MIN, U32_MAX
from odocan.firmware.trig import atan2_bam32, cos_q30, sin_q30, sincos_q30
from tools import gen_trig_tables

LSB_Q30 = 2.0**-30
RAD_PER_BAM32 = math.tau / 2**32
SINCOS_SPEC = 2.0**-30
SINCOS_DESIGN = 2.0**-31 + 2.0**-41
ATAN2_SPEC = 2.0**-24
ATAN2_DESIGN = math.pi * 2.0**-32 + 2.0**-36  # half a BAM32 LSB plus the internal budget
QUARTER = 1 << 30
HALF = 1 << 31
KNOT = 1 << 22  # spacing of the quarter-wave table, in BAM32 LSB


# --- sin / cos -------------------------------------------------------------------------------


def _sincos_error(angle: int) -> float:
    """Larger of the sin and cos absolute errors at ``angle`` (u32 BAM32), vs float64 math."""
    s, c = sincos_q30(angle)
    theta = angle * RAD_PER_BAM32
    return max(abs(s * LSB_Q30 - math.sin(theta)), abs(c * LSB_Q30 - math.cos(theta)))


def _max_sincos_error(angles: Iterable[int]) -> tuple[float, int]:
    """The largest error over ``angles`` and the angle where it occurs."""
    worst, worst_angle = -1.0, -1
    for angle in angles:
        err = _sincos_error(angle)
        if err > worst:
            worst, worst_angle = err, angle
    return worst, worst_angle


def _knot_angles() -> Iterator[int]:
    """Every table knot and tie (half-knot) of every quadrant, with neighbours +-1..3 LSB."""
    for quadrant in range(4):
        for knot in range(257):
            for centre in (knot * KNOT, knot * KNOT + KNOT // 2):
                for offset in range(-3, 4):
                    yield (quadrant * QUARTER + centre + offset) & U32_MAX


def _report_sincos(label: str, worst: float, angle: int) -> None:
    print(f"\nsincos_q30 {label}: max error {worst / LSB_Q30:.6f} x 2^-30 at angle {angle:#010x}")
    assert worst <= SINCOS_SPEC
    assert worst <= SINCOS_DESIGN


def test_sincos_knots_ties_and_quadrant_boundaries() -> None:
    worst, angle = _max_sincos_error(_knot_angles())
    _report_sincos("knots/ties/boundaries", worst, angle)


def test_sincos_random_angles() -> None:
    rng = random.Random(20240601)
    worst, angle = _max_sincos_error(rng.getrandbits(32) for _ in range(1 << 20))
    _report_sincos("2^20 random angles", worst, angle)


@settings(max_examples=2000)
@given(st.integers(min_value=0, max_value=U32_MAX))
def test_sincos_bound_property(angle: int) -> None:
    assert _sincos_error(angle) <= SINCOS_DESIGN
    s, c = sincos_q30(angle)
    assert -(1 << 30) <= s <= 1 << 30
    assert -(1 << 30) <= c <= 1 << 30


@given(st.integers(min_value=-(1 << 31), max_value=(1 << 31) - 1))
def test_sincos_accepts_i32_angles(angle: int) -> None:
    assert sincos_q30(angle) == sincos_q30(angle & U32_MAX)


def test_sincos_exact_values() -> None:
    one = 1 << 30
    assert sincos_q30(0) == (0, one)
    assert sincos_q30(QUARTER) == (one, 0)
    assert sincos_q30(HALF) == (0, -one)
    assert sincos_q30(3 * QUARTER) == (-one, 0)
    s45, c45 = sincos_q30(QUARTER // 2)
    assert s45 == c45 == round(2**29.5)


def _symmetry_angles() -> Iterator[int]:
    yield from _knot_angles()
    rng = random.Random(7)
    yield from (rng.getrandbits(32) for _ in range(20000))


def test_sincos_symmetries_exact() -> None:
    for a in _symmetry_angles():
        s, c = sincos_q30(a)
        assert sincos_q30(-a & U32_MAX) == (-s, c), a  # odd / even
        assert sincos_q30((a + QUARTER) & U32_MAX) == (c, -s), a
        assert sincos_q30((a + HALF) & U32_MAX) == (-s, -c), a
        assert sincos_q30((HALF - a) & U32_MAX) == (s, -c), a  # supplementary angle
        assert sincos_q30((QUARTER - a) & U32_MAX) == (c, s), a  # complementary angle


def test_sin_and_cos_match_sincos() -> None:
    rng = random.Random(3)
    for a in [rng.getrandbits(32) for _ in range(2000)]:
        assert (sin_q30(a), cos_q30(a)) == sincos_q30(a)


def test_pythagorean_identity() -> None:
    # each component is within 1/2 + 2^-11 LSB of the truth, so
    # |s^2 + c^2 - 2^60| <= 2^30 * (|sin| + |cos|) * (1 + 2^-10) + 1 <= 2^30 * sqrt(2) * 1.001 + 1
    bound = (1 << 30) * math.sqrt(2) * 1.001 + 1
    rng = random.Random(11)
    worst = 0
    for a in [rng.getrandbits(32) for _ in range(1 << 16)]:
        s, c = sincos_q30(a)
        worst = max(worst, abs(s * s + c * c - (1 << 60)))
    print(f"\nsin^2 + cos^2: max |s^2 + c^2 - 2^60| = {worst / (1 << 30):.4f} x 2^30")
    assert worst <= bound


# --- atan2 -----------------------------------------------------------------------------------


def _atan2_error(y: int, x: int) -> float:
    """|atan2_bam32(y, x) - math.atan2(y, x)| in radians, wrapped into [0, pi]."""
    got = atan2_bam32(y, x)
    assert -HALF <= got < HALF
    return abs(math.remainder(got * RAD_PER_BAM32 - math.atan2(y, x), math.tau))


def _max_atan2_error(points: Iterable[tuple[int, int]]) -> tuple[float, tuple[int, int], int]:
    """Largest error over ``points``, where it occurs, and how many points were checked."""
    worst, where, count = -1.0, (0, 0), 0
    for y, x in points:
        count += 1
        err = _atan2_error(y, x)
        if err > worst:
            worst, where = err, (y, x)
    return worst, where, count


def _report_atan2(label: str, worst: float, where: tuple[int, int], count: int) -> None:
    print(
        f"\natan2_bam32 {label} ({count} points): max error {worst:.3e} rad"
        f" = 2^{math.log2(max(worst, 2.0**-99)):.2f} rad = {worst / RAD_PER_BAM32:.4f} LSB"
        f" at (y, x) = {where}"
    )
    assert worst <= ATAN2_SPEC
    assert worst <= ATAN2_DESIGN


RADII = [1, 2, 3, 5, 7, 10, 50, 100, 1000, 4095, 65537, 10**6, 2**24 - 1, 2**31, 2**32 + 1]
RADII += [10**12, 2**46 - 3, 2**47, 2**47 + 5, 2**50, 10**17, 2**60, 2**62, 2**62 + 2**61]


def _circle_points(n_per_radius: int) -> Iterator[tuple[int, int]]:
    """Points rounded to integers around circles of every radius in ``RADII`` (seeded)."""
    rng = random.Random(42)
    for radius in RADII:
        for _ in range(n_per_radius):
            t = rng.random() * math.tau
            yield round(radius * math.sin(t)), round(radius * math.cos(t))


def test_atan2_circles() -> None:
    points = _circle_points(-(-(1 << 18) // len(RADII)))
    worst, where, count = _max_atan2_error(points)
    assert count >= 1 << 18
    _report_atan2("circles r = 1 .. 1.5 * 2^62", worst, where, count)


def test_atan2_small_integer_grid() -> None:
    grid = ((y, x) for y in range(-64, 65) for x in range(-64, 65) if (y, x) != (0, 0))
    _report_atan2("grid |y|, |x| <= 64", *_max_atan2_error(grid))


def test_atan2_full_range_and_near_diagonal() -> None:
    rng = random.Random(5)
    pts = [(rng.randint(I64_MIN, I64_MAX), rng.randint(I64_MIN, I64_MAX)) for _ in range(1 << 14)]
    for m in (2**20, 2**46 - 1, 2**47, 2**47 + 1, 2**62, I64_MAX):
        for dn in (0, 1, 2, 2**10):
            pts += [(m - dn, m), (m, m - dn), (-(m - dn), m), (m - dn, -m), (1, m), (-1, -m)]
    _report_atan2("full i64 range + near diagonal/axes", *_max_atan2_error(pts))


@pytest.mark.parametrize(
    ("y", "x", "expected"),
    [
        (0, 0, 0),
        (0, 5, 0),
        (5, 0, QUARTER),
        (0, -5, -HALF),  # +pi is represented as -2^31
        (-5, 0, -QUARTER),
        (7, 7, QUARTER // 2),
        (7, -7, 3 * QUARTER // 2),
        (-7, -7, -3 * QUARTER // 2),
        (-7, 7, -QUARTER // 2),
        (0, I64_MIN, -HALF),
        (I64_MIN, 0, -QUARTER),
        (I64_MAX, 0, QUARTER),
        (0, I64_MAX, 0),
        (I64_MIN, I64_MIN, -3 * QUARTER // 2),
        (I64_MAX, I64_MAX, QUARTER // 2),
        (I64_MIN, I64_MAX, -QUARTER // 2),  # off the diagonal by 2^-63: rounds onto it
    ],
)
def test_atan2_exact_cases(y: int, x: int, expected: int) -> None:
    assert atan2_bam32(y, x) == expected


def test_atan2_extreme_inputs_within_bound() -> None:
    extremes = [I64_MIN, I64_MIN + 1, -1, 0, 1, I64_MAX - 1, I64_MAX]
    pts = [(y, x) for y in extremes for x in extremes if (y, x) != (0, 0)]
    _report_atan2("extreme i64 pairs", *_max_atan2_error(pts))


i64s = st.integers(min_value=I64_MIN, max_value=I64_MAX)


@settings(max_examples=1000)
@given(i64s, i64s)
def test_atan2_bound_property(y: int, x: int) -> None:
    assert _atan2_error(y, x) <= ATAN2_DESIGN


@given(i64s, i64s)
def test_atan2_symmetries_exact(y: int, x: int) -> None:
    phi = atan2_bam32(y, x)
    if y != I64_MIN:
        mirrored = atan2_bam32(-y, x)
        assert mirrored == (phi if phi == -HALF else -phi)
    if y >= 0 and x >= 0 and (y, x) != (0, 0):
        assert atan2_bam32(x, y) == QUARTER - phi


@given(
    st.integers(min_value=-(2**40), max_value=2**40),
    st.integers(min_value=-(2**40), max_value=2**40),
    st.integers(min_value=0, max_value=22),
)
def test_atan2_power_of_two_scale_invariance(y: int, x: int, k: int) -> None:
    assert atan2_bam32(y << k, x << k) == atan2_bam32(y, x)


@settings(max_examples=2000)
@given(st.integers(min_value=0, max_value=U32_MAX))
def test_atan2_inverts_sincos(angle: int) -> None:
    # sin, cos are each within ~1/2 LSB of Q30 (angle error <= 2^-30.5 rad = 0.7 BAM32 LSB),
    # plus half an LSB of rounding in atan2: at most 2 LSB apart
    s, c = sincos_q30(angle)
    back = atan2_bam32(s, c)
    assert abs(((back - angle + HALF) & U32_MAX) - HALF) <= 2


# --- the generated tables --------------------------------------------------------------------


def test_generator_reproduces_tables() -> None:
    with open(trig_tables.__file__, encoding="utf-8") as f:
        assert gen_trig_tables.render() == f.read()


def test_generator_pi() -> None:
    with localcontext() as ctx:
        ctx.prec = 60
        pi = gen_trig_tables._pi()
    assert float(pi) == math.pi
    assert str(pi).startswith("3.14159265358979323846264338327950288419716939937510582097")


def _is_nearest_sqrt(root: int, square: int) -> bool:
    """``root`` is the nearest integer to sqrt(``square``) (an exact integer test)."""
    return (2 * root - 1) ** 2 <= 4 * square < (2 * root + 1) ** 2


def _exceeds(sign: int, rhs: int) -> bool:
    """``sign * sqrt(2^249) > rhs``, exactly (sqrt(2^249) is irrational, never equal)."""
    if sign > 0:
        return rhs < 0 or rhs * rhs < 1 << 249
    return rhs < 0 and rhs * rhs > 1 << 249


def test_sin_table_closed_forms_are_correctly_rounded() -> None:
    table = trig_tables.SIN_Q62
    assert table[0] == 0
    assert table[256] == 1 << 62
    assert _is_nearest_sqrt(table[128], 1 << 123)  # sin(pi/4) * 2^62 = sqrt(2^123)
    # sin(pi/8) * 2^62 = sqrt(v) with v = 2^123 - 2^122 sqrt(2), and sin(3pi/8) with + instead.
    # R is the nearest integer iff (2R - 1)^2 < 4v < (2R + 1)^2, where
    # 4v = 2^125 + sign * sqrt(2^249).
    for k, sign in ((64, -1), (192, 1)):
        r = table[k]
        assert _exceeds(sign, (2 * r - 1) ** 2 - (1 << 125)), k
        assert not _exceeds(sign, (2 * r + 1) ** 2 - (1 << 125)), k


def test_tables_against_float64() -> None:
    for k, v in enumerate(trig_tables.SIN_Q62):
        assert abs(v / 2**62 - math.sin(math.pi * k / 512)) <= 2.0**-53
    for k, v in enumerate(trig_tables.ATAN_BAM48):
        assert abs(v - math.atan(k / 256) * 2**48 / math.tau) <= 0.5 + 2.0**-6
    assert trig_tables.ATAN_BAM48[256] == 1 << 45
    assert round(math.tau * 2**32) == trig_tables.SIN_STEP_Q64
