"""The loss allowance's largest error takes back the samples a late-told reboot withdraws
(``livelosses.LiveAllowance.withdraw_from``, issue #11: the fleet's verdict read the new life's
first poses against the old reference, 1.78 m, and FAILed a correct firmware).

Independent of the marks: the test keeps every sample's (bus time, error) itself; with no lossy
span the allowance is 0, so the largest error beyond it of the samples kept is the largest of
their errors. Samples recorded in bus time order, settled by ``record`` and by pages
(``settle``) now and then, some still revisable when the withdrawal comes: exact while the
withdrawn samples are no more than ``MARKS_KEPT``; further back never below the samples kept."""

from __future__ import annotations

import random

import pytest

from odocan.host.judge.livelosses import LiveAllowance
from odocan.host.judge.livepose import MARKS_KEPT

CYCLE_S = 0.01


def _error(dpos_m: float) -> dict[str, float]:
    return {"dx_m": dpos_m, "dy_m": 0.0, "dpos_m": dpos_m, "dheading_rad": 0.0}


def _recorded(rng: random.Random, n: int) -> tuple[LiveAllowance, list[tuple[float, float]]]:
    """``n`` samples, one per cycle, errors mostly small and now and then a jump up; settled
    by a page every ~20 samples."""
    allowance, samples = LiveAllowance(), []
    for seq in range(n):
        t_s = seq * CYCLE_S
        dpos_m = rng.choice([rng.uniform(0, 1e-4), rng.uniform(0, 0.01 * seq / n + 1e-4)])
        allowance.record(seq, _error(dpos_m), True, t_s)
        samples.append((t_s, dpos_m))
        if rng.random() < 0.05:
            allowance.settle(seq, True)
    return allowance, samples


@pytest.mark.parametrize("seed", range(20))
def test_the_largest_error_is_the_kept_samples_after_a_withdrawal(seed: int) -> None:
    rng = random.Random(seed)
    allowance, samples = _recorded(rng, rng.randrange(300, 800))
    withdrawn = rng.randrange(1, MARKS_KEPT + 1)
    from_s = samples[-withdrawn][0] - CYCLE_S / 2
    if rng.random() < 0.5:  # as at a reboot: the old reference's samples all settled first
        allowance.restart(len(samples), True)
    allowance.withdraw_from(from_s)
    kept_m = max(e for t, e in samples if t < from_s)
    assert allowance.max_beyond_m() == kept_m


def test_the_new_life_one_metre_off_after_the_withdrawal_is_its_own() -> None:
    """After the withdrawal the next samples raise it again: a new life 1 m off shows."""
    allowance, samples = _recorded(random.Random(7), 400)
    allowance.record(400, _error(1.78), True, 4.0)  # the new firmware vs the old reference
    allowance.restart(400, True)
    allowance.withdraw_from(4.0)
    assert allowance.max_beyond_m() == max(e for _, e in samples)
    for seq in range(401, 500):
        allowance.record(seq, _error(1.0), True, seq * CYCLE_S)
    allowance.settle(499, True)
    assert allowance.max_beyond_m() == 1.0


@pytest.mark.parametrize("seed", range(10))
def test_further_back_than_the_marks_it_never_falls_below_the_kept_samples(seed: int) -> None:
    rng = random.Random(seed)
    allowance, samples = _recorded(rng, 600)
    allowance.restart(600, True)
    from_s = samples[rng.randrange(1, 600)][0] - CYCLE_S / 2
    allowance.withdraw_from(from_s)
    assert allowance.max_beyond_m() >= max(e for t, e in samples if t < from_s)
    assert allowance.max_beyond_m() <= max(e for _, e in samples)
