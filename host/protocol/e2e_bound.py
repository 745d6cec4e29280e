"""The firmware's plausibility bound, for the E2E check's reading of a skip proof (issue #11,
rule 5: a FAIL must never blame a correct firmware).

A pose proves an encoder frame skipped (``e2e_evidence``): the firmware's E2E check refused it,
*or* took it and its plausibility bound refused the step (``firmware.encoders``: beyond the
robot's maximum wheel speed over its periods; the check's COUNTER then moves on to that frame and
the frames on time after it are out of sequence). ``e2e_evidence._bound_skip`` reads it as the
bound's where the readings' windows are one and take it (``exact``). The rule here
(``by_counts``): where every reading's window takes it (the narrowest too) and its step from the
frame the firmware's check took last is beyond the bound even over the widest window plus its
COUNTER step, it is the bound's: the stamps
say the check took it, and the counts say the firmware could not integrate it (a frame of another
chain: a counter restart's, or a late sender's). A starved recorder's lying stamps (the reason
the windows must otherwise be one) never turn a step of the robot's own chain into one that far.

Kobuki figure8, seed 7, ``delay=0.5:150,drop=0.1``: the late COUNTER 2 (LEFT_COUNT 29598,
heard 7.69 s) taken, then the on-time 4 of 7.72 s (30313: 715 counts, where 3 periods allow
252) that every reading's window (3, 3, 2) took; the poses named 2 on, so the host read the skip
as the E2E check's and took the late 6, 8 and 9 the firmware refused (out of sequence from 4).
The firmware re-primed its counter restart on that 4, the reference on the 10 after: 5.9 mrad of
heading and 0.150 mm of position beyond the allowance off a correct firmware.

The bound comes from the judge (``host.judge.e2estepbound``: the robot it judges with), for the
duration of an analysis (a context variable: every E2E check of its frames reads it alike); none
set, no skip proof is read this way.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.decode import BulkDecoder

Beyond = Callable[[int, int, int], bool]  # (frame a, frame b, periods): the step beyond the bound


@dataclass(frozen=True)
class StepBound:
    """The firmware's per-period step bound in counts (left, right), the counters' width on
    the wire (bits, for the wrap-safe delta), and the decoder of the DBC the analysis reads
    (WHEEL_ENCODERS' LEFT_COUNT and RIGHT_COUNT where that DBC puts them)."""

    left_counts: int
    right_counts: int
    bits: int
    decoder: BulkDecoder


_BOUND: ContextVar[StepBound | None] = ContextVar("e2e_step_bound", default=None)


@contextmanager
def step_bound(bound: StepBound | None) -> Iterator[None]:
    """``bound`` in force for the E2E checks run inside the block."""
    token = _BOUND.set(bound)
    try:
        yield
    finally:
        _BOUND.reset(token)


def beyond_bound(frames: FrameArrays, index: npt.NDArray[np.intp]) -> Beyond | None:
    """For the encoder frames ``index``: whether the step from frame ``a`` to frame ``b``
    (positions in ``index``) is beyond the bound in force over ``periods``; None without one
    (or when ``index`` is not the DBC's WHEEL_ENCODERS frames)."""
    bound = _BOUND.get()
    if bound is None:
        return None
    rows = bound.decoder.decode(frames, "WHEEL_ENCODERS")
    if not np.array_equal(rows["index"], index):
        return None
    left, right = rows["LEFT_COUNT"].astype(np.int64), rows["RIGHT_COUNT"].astype(np.int64)
    half = 1 << (bound.bits - 1)

    def wrapped(d: int) -> int:
        return ((d + half) & (2 * half - 1)) - half

    def beyond(a: int, b: int, periods: int) -> bool:
        return (abs(wrapped(int(left[b] - left[a]))) > periods * bound.left_counts
                or abs(wrapped(int(right[b] - right[a]))) > periods * bound.right_counts)

    return beyond


def exact(delta: int, windows: list[int]) -> bool:
    """Whether the three readings' ``windows`` are one (the stamps since the last frame taken
    are the bus's: a starved recorder's would read otherwise) and take a frame ``delta``
    COUNTERs on (issue #11: on a starved capture of kobuki, seed 3, ``delay=0.1:15,seed=7``,
    the COUNTER 12 of 3.35 s, 2 after the proven 10, every reading took and the firmware's
    check refused: the robot standing, no bound refuses a step; its windows read 4, 4 and 2).
    Moved here from ``e2e_evidence`` (its ``_exact``)."""
    return windows[0] == windows[1] == windows[2] >= delta


def by_counts(beyond: Beyond | None, delta: int, windows: list[int], last: int, j: int) -> bool:
    """Whether frame ``j``, ``delta`` COUNTERs after ``last`` (the firmware's check's last),
    proven skipped, was the bound's by its counts (module docstring): every reading's
    ``windows`` takes it, and its step from ``last`` is ``beyond`` the bound over the widest
    window plus ``delta`` periods. False without a bound."""
    return beyond is not None and min(windows) >= delta and beyond(last, j, max(windows) + delta)
