"""A hold needs evidence (issue #11, ``stalls.hold_evidence``): the bus quiet over all but
``SILENCE_CYCLES`` cycles of the span between two samples, checked against a plain loop; and
``frozen_breaks`` makes no break for a pair without evidence (sparse samples under ``delay``)."""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from odocan.host.judge.samples import SILENCE_CYCLES
from odocan.host.judge.stalls import frozen_breaks, quiet_between

CYCLE_S = 0.01


def _plain(t0: float, t1: float, sent: list[float]) -> bool:
    inside = [t for t in sent if t0 <= t <= t1]
    quiet = sum(b - a for a, b in pairwise(inside)
                if b - a >= (SILENCE_CYCLES - 0.5) * CYCLE_S)
    return quiet > 0 and quiet >= (t1 - t0) - SILENCE_CYCLES * CYCLE_S


def test_quiet_between_is_the_plain_count() -> None:
    rng = np.random.default_rng(11)
    for _ in range(200):
        steps = rng.choice([0.02, 0.02, 0.02, 0.1, 0.2], size=40) + rng.uniform(0, 0.003, 40)
        sent = np.cumsum(steps)  # off the grid: no sum ties the bound to the last bit
        pick = np.sort(rng.choice(len(sent), size=2, replace=False))
        t0, t1 = sent[pick[0]], sent[pick[1]]
        got = quiet_between(np.array([t0]), np.array([t1]), sent, CYCLE_S)
        assert bool(got[0]) == _plain(float(t0), float(t1), sent.tolist()), (t0, t1)


def test_a_jump_without_evidence_is_no_hold() -> None:
    enc = np.array([10, 60], dtype=np.int64)
    seq = np.array([10, 60], dtype=np.int64)
    assert frozen_breaks(enc, seq).tolist() == [11]  # no evidence asked: the old rule
    assert frozen_breaks(enc, seq, evidence=np.array([True])).tolist() == [11]
    assert frozen_breaks(enc, seq, evidence=np.array([False])).tolist() == []
