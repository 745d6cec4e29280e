"""The power-up pose judged against its life's start (``host.judge.powerupjudged``; the drives:
``tests/test_live_held_tick_start.py``'s power-up poses)."""

from __future__ import annotations

import math

from odocan.host.judge.powerupjudged import names_the_prime, start_errors


def test_a_pose_naming_the_primes_counter_names_it_until_another_frame_has_it() -> None:
    """Kobuki 692: primed on the held COUNTER 1; its twin (the on-time 1) is refused, not a
    frame of the life; the frame of COUNTER 1 a lap on (0.970 s) makes the name ambiguous."""
    assert names_the_prime(1, 1, [2, 3, 4])
    assert not names_the_prime(1, 1, [2, 3, 1])
    assert not names_the_prime(2, 1, [2])


def test_the_errors_from_the_start_by_what_a_half_carries() -> None:
    """Both halves: the distance; an X half alone: X and HEADING; a Y half alone: Y."""
    start = (0.0, 0.0, 0.0)
    assert start_errors(0.003, 0.004, 0.0, start) == (0.005, 0.0)
    assert start_errors(0.01, None, 2 * math.pi - 0.001, start)[0] == 0.01
    assert math.isclose(start_errors(0.01, None, 2 * math.pi - 0.001, start)[1], 0.001)
    assert start_errors(None, -0.002, None, start) == (0.002, 0.0)
