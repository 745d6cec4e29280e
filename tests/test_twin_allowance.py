"""``host.judge.twins.twin_detour_m`` against the reference's own integrator
(``reference.integrate``, vectorised, from any start heading): the position after the next frame
along prev -> accepted -> next, prev -> twin -> next and prev -> next, for each integrator (the
heading after the next frame is the same on every path: a function of the counts)."""

from __future__ import annotations

import itertools
import math
import random

import pytest

from odocan.host.judge.reference import Geometry, integrate
from odocan.host.judge.twins import counts_bound, twin_detour_m
from odocan.sim.robot import load

GEOMETRY = Geometry.of(load("pmir"))
ONE_CM = Geometry(500, 0.075, 0.075, 0.01)  # pmir's wheels on 1 cm: 0.094 rad a count
BITS = 24


def _end(steps: list[tuple[int, int]], heading0_rad: float, integrator: str,
         g: Geometry = GEOMETRY) -> tuple[float, float, float]:
    """Position (m) and heading (rad) after ``steps`` (count deltas) from (0, 0, heading0)."""
    pose = integrate([s[0] for s in steps], [s[1] for s in steps], g, integrator,
                     heading0_rad=heading0_rad)
    return float(pose.x_m[-1]), float(pose.y_m[-1]), float(pose.heading_rad[-1])


@pytest.mark.parametrize("integrator", ["exact", "rk2", "euler"])
def test_the_detour_is_the_reference_integrators_own(integrator: str) -> None:
    rng = random.Random(11)
    bound = counts_bound(GEOMETRY)
    detours = []
    for _ in range(200):
        prev = (rng.randrange(1 << 20), rng.randrange(1 << 20))
        step = [rng.randrange(-bound[w] // 3, bound[w] // 3) for w in (0, 1)]
        acc = (prev[0] + step[0], prev[1] + step[1])
        nxt = (acc[0] + step[0] + rng.randrange(-3, 4), acc[1] + step[1] + rng.randrange(-3, 4))
        off = [rng.randrange(-bound[w] // 3, bound[w] // 3 + 1) for w in (0, 1)]
        twin = (acc[0] + off[0], acc[1] + off[1])  # plausible: within the bound both ways
        h0 = rng.uniform(-math.pi, math.pi)
        ax, ay, ah = _end([(acc[0] - prev[0], acc[1] - prev[1]),
                           (nxt[0] - acc[0], nxt[1] - acc[1])], h0, integrator)
        tx, ty, th = _end([(twin[0] - prev[0], twin[1] - prev[1]),
                           (nxt[0] - twin[0], nxt[1] - twin[1])], h0, integrator)
        mx, my, _ = _end([(nxt[0] - prev[0], nxt[1] - prev[1])], h0, integrator)
        assert abs(th - ah) < 1e-12  # the heading agrees after the next frame
        want = max(math.hypot(tx - ax, ty - ay), math.hypot(mx - ax, my - ay))
        got = twin_detour_m([prev], acc, [twin], nxt, (1, 1), GEOMETRY, BITS, integrator)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-15)
        detours.append(got)
    assert sum(d > 1e-6 for d in detours) > 150  # mostly a real detour, not 0 = 0


@pytest.mark.parametrize("integrator", ["exact", "rk2", "euler"])
def test_the_detour_of_a_1_cm_robot_at_4_m_s_is_the_reference_integrators_own(
    integrator: str
) -> None:
    """Steps up to the firmware's bound (4 m/s: 8 rad a period), and the merged step of both
    frames lost (up to 16 rad): each taken whole, as the reference and the firmware take it."""
    rng = random.Random(13)
    bound = counts_bound(ONE_CM)
    big = 0
    for _ in range(300):
        prev = (rng.randrange(1 << 20), rng.randrange(1 << 20))
        step = [rng.randint(-bound[w], bound[w]) for w in (0, 1)]
        acc = (prev[0] + step[0], prev[1] + step[1])
        step = [rng.randint(-bound[w], bound[w]) for w in (0, 1)]
        nxt = (acc[0] + step[0], acc[1] + step[1])
        off = [rng.randint(max(-bound[w], nxt[w] - prev[w] - bound[w]),
                           min(bound[w], nxt[w] - prev[w] + bound[w])) for w in (0, 1)]
        twin = (prev[0] + off[0], prev[1] + off[1])  # plausible from prev and to nxt
        h0 = rng.uniform(-math.pi, math.pi)
        paths = [_end([(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(counts)], h0,
                      integrator, ONE_CM) for counts in ([prev, acc, nxt], [prev, twin, nxt],
                                                        [prev, nxt])]
        (ax, ay, _), (tx, ty, _), (mx, my, mh) = paths
        big += abs(mh - h0) > math.pi
        want = max(math.hypot(tx - ax, ty - ay), math.hypot(mx - ax, my - ay))
        got = twin_detour_m([prev], acc, [twin], nxt, (1, 1), ONE_CM, BITS, integrator)
        assert got == pytest.approx(want, rel=1e-9, abs=1e-15)
    assert big > 100  # mostly merged steps of more than half a turn


def test_an_implausible_twin_is_no_option() -> None:
    """A twin whose step the firmware refuses (beyond the per-period bound) counts as the frame
    lost (prev -> next in one step), never as a step of metres."""
    bound = counts_bound(GEOMETRY)
    prev, acc, nxt = (1000, 1000), (1010, 1020), (1020, 1040)
    far = (acc[0] + 40 * bound[0], acc[1] - 40 * bound[1])
    mx, my, _ = _end([(20, 40)], 0.3, "exact")
    ax, ay, _ = _end([(10, 20), (10, 20)], 0.3, "exact")
    got = twin_detour_m([prev], acc, [far], nxt, (1, 1), GEOMETRY, BITS, "exact")
    assert got == pytest.approx(math.hypot(mx - ax, my - ay), rel=1e-9, abs=1e-15)
