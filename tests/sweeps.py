"""Sweeps sampled in a default run: ``sample(cases, every)`` keeps one case in ``every`` of a
grid (and every case it ``pins``); ``ODOCAN_SWEEPS=full`` keeps them all (``make sweeps``).

A sweep is a grid of drives run to find where a judge goes wrong (192 staged applies, every
stall of a grid, ten drives of one fault mix ...). Once the cases it found are pinned, the rest
of the grid guards the same rule again and again, each case a drive and several judges: the
whole suite outgrew CI's 90 minutes. Which cases a default run keeps is fixed by the cases
themselves (CRC-32 of their ``repr``, which mixes a grid's axes rather than keeping one axis's
values only), the same on every xdist worker and every run: a default run is as deterministic as
a full one, only smaller, and never empty.
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Iterable, Sequence
from typing import TypeVar

SWEEPS_ENV = "ODOCAN_SWEEPS"
Case = TypeVar("Case")


def full() -> bool:
    """Whether this run keeps every case of every sweep."""
    return os.environ.get(SWEEPS_ENV, "") == "full"


def sample(cases: Iterable[Case], every: int, pins: Sequence[Case] = ()) -> list[Case]:
    """``cases`` in their order, all of them under ``ODOCAN_SWEEPS=full``; else those whose
    ``repr``'s CRC-32 is 0 modulo ``every``, and every case in ``pins`` (the first case when
    that leaves none)."""
    cases = list(cases)
    if full():
        return cases
    kept = [c for c in cases if c in pins or zlib.crc32(repr(c).encode()) % every == 0]
    return kept or cases[:1]


def header() -> str:
    """The line the session starts with: which sweeps run."""
    return ("odocan: every case of every sweep" if full() else
            f"odocan: sweeps sampled (tests/sweeps.py); {SWEEPS_ENV}=full runs every case")
