"""The bound on the reference's re-placement after a gap of the log (rule 5: a PASS must never
hide a wrong pose), shared by the whole-log, the streamed and the live judge through
``host.judge.breaks``' budget.

Across a gap of N encoder periods the log holds one merged step (its cumulative counts: the
total travel of each wheel is known, and so the heading after it, exactly); the firmware may
have integrated the N frames one by one, or some of them merged (frames the bus lost too), each
of its steps over k periods within k times the plausibility bound per period that it enforces
(the robot's ``max_wheel_speed_mm_s``, firmware/encoders.py ``step_bounds``; one count more here).
How far can its position after the gap lie from the merged step's? Write a step of left and
right wheel travel a, c (m) as ds = (a + c) / 2 and a heading change dtheta = (c - a) / b, taken
by the integrator as ds sigma(dtheta) u(dir) (``losses.step_vector``: u the unit vector, dir
the end heading (euler) or the middle (rk2, exact), sigma = sinc(dtheta / 2) for exact, else 1;
a step of more than half a turn taken whole, as the firmware and the reference take it). The
merged step is S r with S = sum ds_i and r = sigma_ref u(dir_ref) of the merged counts, so the
firmware's position differs from it by

    E = sum_i ds_i (sigma_i u(dir_i) - r),  |E| <= sum_i |ds_i| g_i,  g_i = |sigma_i u(dir_i) - r|.

``gap_allowance_m`` maximises the right-hand side over every sequence of steps (one per period or
merged over k periods) whose headings start at 0 and end at the merged step's, by dynamic
programming over the heading at each period boundary, kept in G bins of width delta over its
reachable range: a step from bin s to bin e over k periods is worth the largest |ds| any
dtheta within (c_e - c_s) +- delta allows over k periods (the travel is then free: dropping
sum ds_i = S only enlarges the set) times g at the bins' centres plus 0.75 delta (dir moves by
at most delta / 2 within the bins, sigma by at most 0.22 delta), at most 1 + |r| (|sigma| <= 1
always). Every real sequence of steps lies in some sequence of bins and earns no more there, so
the result bounds |E|: a true upper bound, proven against brute force and random splits in
tests/test_gap_bound.py.
It is also at most the path bound N (A + C) / 2 + |S r| (A, C: the wheels' travel bounds per
period), which it takes beyond ``DP_PERIODS`` periods. The firmware's own rounding is the
placement's tolerance (``breaks.bound_offsets``' slack)."""

from __future__ import annotations

import functools
import math

import numpy as np

from odocan.host.judge.reference import Geometry, SpeedBound, wrap_delta
from odocan.host.judge.samples import FloatArray
from odocan.host.protocol.busfacts import ENC_PERIOD_US as ENCODER_PERIOD_US

DP_PERIODS = 256  # gaps longer than this take the path bound (2.56 s at 100 Hz)
MAX_BINS = 160  # heading bins of a short gap (0.75 of their width per step: the slack)
DP_WORK = 1_000_000  # bins^2 * periods^2 / 2: the dynamic programme's size (a few ms)
SIGMA_SLOPE = 0.22  # max |d sinc(x / 2) / dx| (0.2174): sigma's change per rad of dtheta
BIN_SLACK = 0.5 + SIGMA_SLOPE  # g's change across the bins, per bin width (rad)
SINC_MIN = -0.2173  # the least value of sin(y) / y
# Distinct gaps kept by ``gap_allowance_m``'s cache: a judge asks the same gap again and again
# (each reference built, each live placement: 3190 calls of 99 gaps in test_run_delay_stall's
# figure8_671 drives, 53 s of its 120 s), a few ms of numpy each time.
ALLOWANCE_CACHE = 4096


def period_bounds(geometry: Geometry, max_wheel_speed_mm_s: int | None = None
                  ) -> tuple[int, int]:
    """Per wheel, the most counts the firmware accepts in one encoder period: its
    ``step_bounds`` (ceil(v_max T / travel per count) + 1) computed in float, plus one count
    (its Q48 bound may differ by one at the limit). ``max_wheel_speed_mm_s`` None: the robot's
    (``geometry.max_wheel_speed_mm_s``, its profile's)."""
    if max_wheel_speed_mm_s is None:
        max_wheel_speed_mm_s = geometry.max_wheel_speed_mm_s
    travel_m = max_wheel_speed_mm_s * 1e-3 * ENCODER_PERIOD_US * 1e-6
    return (math.ceil(travel_m / geometry.m_per_count_left) + 2,
            math.ceil(travel_m / geometry.m_per_count_right) + 2)


def step_response(turn_rad: FloatArray, h_old_rad: FloatArray, integrator: str
                  ) -> tuple[FloatArray, FloatArray]:
    """(sigma, dir rad) of steps turning ``turn_rad`` from heading ``h_old_rad``: the
    displacement is ds sigma u(dir) (``losses.step_vector``'s rule: the whole turn, even one of
    more than half a turn)."""
    if integrator == "euler":
        return np.ones_like(turn_rad), h_old_rad + turn_rad
    sigma = np.sinc(turn_rad / (2.0 * np.pi)) if integrator == "exact" else np.ones_like(turn_rad)
    return sigma, h_old_rad + 0.5 * turn_rad


@functools.lru_cache(maxsize=ALLOWANCE_CACHE)
def gap_allowance_m(d_left: int, d_right: int, periods: int, geometry: Geometry,
                    integrator: str, bounds: tuple[int, int]) -> float:
    """The most (m) the firmware's position after a gap of ``periods`` encoder periods can lie
    from the reference's merged step of ``d_left``, ``d_right`` counts (module docstring;
    ``bounds``: the counts per period per wheel, ``period_bounds``). 0 for one period.
    Cached (``ALLOWANCE_CACHE`` gaps): a pure function of its arguments (``Geometry`` is a
    frozen dataclass, hashed by its fields), so a gap asked again gets the same float."""
    if periods <= 1:
        return 0.0
    a_m = bounds[0] * geometry.m_per_count_left
    c_m = bounds[1] * geometry.m_per_count_right
    b_m = geometry.wheelbase_m
    turn = (d_right * geometry.m_per_count_right - d_left * geometry.m_per_count_left) / b_m
    ds_total = 0.5 * (d_left * geometry.m_per_count_left + d_right * geometry.m_per_count_right)
    sigma, direction = step_response(np.array([turn]), np.zeros(1), integrator)
    r = (float(sigma[0]) * math.cos(float(direction[0])),
         float(sigma[0]) * math.sin(float(direction[0])))
    path = periods * 0.5 * (a_m + c_m) + abs(ds_total) * math.hypot(*r)
    if periods > DP_PERIODS:
        return path
    return min(path, _programme(periods, (a_m, c_m, b_m), turn, r, integrator))


def _programme(n: int, wheels: tuple[float, float, float], turn: float, r: tuple[float, float],
               integrator: str) -> float:
    """The dynamic programme of ``gap_allowance_m`` over the heading bins (module docstring)."""
    a_m, c_m, b_m = wheels
    turn_1 = (a_m + c_m) / b_m  # the most one period can turn (rad)
    lo = 0.5 * (turn - n * turn_1)
    bins = int(min(MAX_BINS, max(16, math.sqrt(2.0 * DP_WORK) / n)))
    width = n * turn_1 / bins
    if width <= 0.0:
        return 0.0
    centre: FloatArray = lo + width * (np.arange(bins, dtype=np.float64) + 0.5)
    first, last = (min(bins - 1, max(0, int((h - lo) // width))) for h in (0.0, turn))
    turns, g = _bin_steps(centre, width, r, integrator)
    worth = np.stack([_worth(k, turns, g, (a_m, c_m, b_m))
                      for k in range(1, n + 1)])  # (k - 1, s, e)
    best = np.full((n + 1, bins), -np.inf)
    best[0, first] = 0.0
    for j in range(1, n + 1):
        before = best[j - 1 :: -1][:j]  # best[j - k] for k = 1 .. j
        best[j] = np.max(before[:, :, None] + worth[:j], axis=(0, 1))
    return max(0.0, float(best[n, last]))


def _bin_steps(centre: FloatArray, width: float, r: tuple[float, float], integrator: str
               ) -> tuple[tuple[FloatArray, FloatArray], FloatArray]:
    """Per pair of bins (s, e): the turns (c_e - c_s -+ ``width``) and g of a step from bin s
    to bin e at the bins' centres plus the slack, capped at 1 + |r| (module docstring). The
    same for every step length k: computed once per programme, not once per k (the sinc, cos,
    sin and hypot were most of its time), with the same operations, so the same floats."""
    turn_c = centre[None, :] - centre[:, None]
    sigma, direction = step_response(turn_c, np.broadcast_to(centre[:, None], turn_c.shape),
                                     integrator)
    g = np.hypot(sigma * np.cos(direction) - r[0], sigma * np.sin(direction) - r[1])
    g = np.minimum(g + BIN_SLACK * width, 1.0 + math.hypot(*r))
    return (turn_c - width, turn_c + width), g


def _worth(k: int, turns: tuple[FloatArray, FloatArray], g: FloatArray,
           wheels: tuple[float, float, float]) -> FloatArray:
    """Per pair of bins (s, e): the most a step over ``k`` periods from bin s to bin e adds to
    sum |ds| g (-inf where no such step is possible; ``turns``, ``g``: ``_bin_steps``')."""
    a_m, c_m, b_m = wheels
    t_lo = np.maximum(turns[0], -k * (a_m + c_m) / b_m)
    t_hi = np.minimum(turns[1], k * (a_m + c_m) / b_m)
    ds = _ds_max(k * a_m, k * c_m, b_m * t_lo, b_m * t_hi)
    worth: FloatArray = np.where(t_lo <= t_hi, ds * g, -np.inf)
    return worth


def _ds_max(a_m: float, c_m: float, x_lo: FloatArray, x_hi: FloatArray) -> FloatArray:
    """The largest |ds| (m) of a step with |a| <= ``a_m``, |c| <= ``c_m`` and c - a = x in
    [x_lo, x_hi]: max(min(a_m + x/2, c_m - x/2), min(a_m - x/2, c_m + x/2)), each term concave
    in x, so its largest value is at an end of the interval or at the term's kink."""
    def forward(x: FloatArray) -> FloatArray:
        out: FloatArray = np.minimum(a_m + 0.5 * x, c_m - 0.5 * x)
        return out

    def backward(x: FloatArray) -> FloatArray:
        out: FloatArray = np.minimum(a_m - 0.5 * x, c_m + 0.5 * x)
        return out

    best = np.maximum(np.maximum(forward(x_lo), forward(x_hi)),
                      np.maximum(backward(x_lo), backward(x_hi)))
    kink_f, kink_b = c_m - a_m, a_m - c_m
    best = np.where((x_lo <= kink_f) & (kink_f <= x_hi), np.maximum(best, 0.5 * (a_m + c_m)), best)
    best = np.where((x_lo <= kink_b) & (kink_b <= x_hi), np.maximum(best, 0.5 * (a_m + c_m)), best)
    return np.maximum(best, 0.0)


def gap_allowance_of_counts(
    before: tuple[int, int], after: tuple[int, int], periods: int, geometry: Geometry,
    bits: int, integrator: str, max_wheel_speed_mm_s: SpeedBound,
) -> float:
    """``gap_allowance_m`` of a gap from the wire counts ``before`` (left, right) to ``after``
    over ``periods`` encoder periods (``bits``: the wire counter width); inf without a
    plausibility bound (``max_wheel_speed_mm_s`` None: the firmware's steps are not bounded;
    ``PROFILE_SPEED``: the robot's)."""
    speed_mm_s = geometry.speed_bound_mm_s(max_wheel_speed_mm_s)
    if speed_mm_s is None:
        return math.inf
    d_left = int(wrap_delta(after[0] - before[0], bits))
    d_right = int(wrap_delta(after[1] - before[1], bits))
    return gap_allowance_m(d_left, d_right, periods, geometry, integrator,
                           period_bounds(geometry, speed_mm_s))
