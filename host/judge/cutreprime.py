"""A staged APPLY a few ticks after a stall the firmware re-primes after, its re-prime in the
APPLY's life (issue #11: "a FAIL must never blame a correct firmware"; ``host.judge.acrosscut``,
``host.judge.stallreprime``).

The firmware drains its FIFO's backlog after a stall, takes an APPLY that staged X, Y and
HEADING, then re-primes on the first fresh encoder frame it takes after it (its step bound
reached half the counters' range: COUNTER_RESET): it holds the staged pose to that frame and
steps plainly from it. The judge's reference starts exactly at the staged pose on the frame the
APPLY took effect after (the latest on the bus before its ACK, ``setposes``), and stepped into
the re-prime frame: the correct firmware FAILed by one frame's turn (6.3 mrad, 12.6 on the spin)
and DISTANCE by its step (2.9-5.6 mm) in 24 of 192 drives (``tests/test_staged_apply_sweep.py``;
where its re-prime came before the APPLY, on the APPLY's frame, it PASSed).

So the re-prime rule of the life after the APPLY applies: when its first sample is the
firmware's first after the stall (``acrosscut.backlog_first``: nothing but backlog frames named
before the APPLY), the start exact (all three staged), and the firmware says it re-primed at
that stall (its last summary before the stall, read before the cut: ``acrosscut.earlier_word``, with
COUNTER_RESET clear, the first one made after it set: ``Resets.told``, a stall long enough:
``stallreprime.possible``; or, latched by an earlier re-prime, set on both, read as
``stallreprime.reprimed_across`` reads a stall: ``_word``; before, a latched word was never
read and the correct firmware FAILed by the step into the re-prime frame, DISTANCE 2.38 mm
beyond on pmir's square: ``tests/test_cut_reprime_latched.py``), the reference holds the
staged pose to frame ``r`` (the steps into frames 1 .. ``r`` of the life left out, in the
pose and in DISTANCE), ``r`` one of 0 (it re-primed before the APPLY, or not at all: nothing
left out, the exact rule's hypothesis when the latched word cannot tell) and the frames up to
the first sample kept
(``stallreprime.R_SPAN`` at most), whichever path best meets the first samples
(``stallreprime.COMPARED``): the stall re-prime's own choice. What a wrong firmware can hide
there: a heading off by the turn of those few frames (as at a declared stall); its position is
still held to the exact staged start (1 m, 10 mm off FAIL).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from odocan.host.judge.nearthreshold import Resets
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    Encoders,
    FloatArray,
    IntArray,
    Poses,
    wrap_pi,
)
from odocan.host.judge.stallreprime import (
    COMPARED,
    R_SPAN,
    Reprime,
    latched,
    possible,
    reprimed_across,
)

Word = tuple[FloatArray, IntArray]  # summaries' bus times and ERROR_MASKs (``acrosscut``)
CUT_KEY = 0  # the cut's re-prime in ``Reference.stall_reprimes`` (a stall's keys are breaks > 0)


@dataclass(frozen=True)
class Backlog:
    """A cut's life whose first sample names a backlog frame (``acrosscut.backlog_first``), with
    the same firmware's summaries before the cut (``acrosscut.earlier_word``; None: none)."""

    earlier: Word | None


def cut_reprime(backlog: Backlog | None, start_pose: tuple[float, float, float] | None,
                enc: Encoders, onboard: Poses, resets: Resets, least: int | None,
                rel: tuple[FloatArray, FloatArray, FloatArray]) -> dict[int, Reprime]:
    """The cut's re-prime (module docstring), keyed ``CUT_KEY``, frames from the life's first
    (its exact start's); none when the rule does not hold or it re-primed before the APPLY.
    ``resets``: the life's summaries; ``rel``: the reference's path from frame 0 (x, y m,
    heading rad per frame, the fine steps)."""
    if backlog is None or backlog.earlier is None or start_pose is None or len(onboard.enc) == 0:
        return {}
    heard = Resets(np.concatenate((backlog.earlier[0], resets.sent_s)),
                   np.concatenate((backlog.earlier[1], resets.mask)), cycle_s=resets.cycle_s)
    b_s = float(enc.timestamp_s[0])
    i = int(np.searchsorted(heard.sent_s, b_s, side="left")) - 1
    j = int(np.searchsorted(heard.sent_s, b_s, side="right"))
    if i < 0 or j >= len(heard.sent_s) or enc.cycle_s is None:
        return {}
    stall_s = float(heard.sent_s[j] - heard.sent_s[i])
    word = _word(heard, i, b_s, stall_s, enc.cycle_s, least)
    if word is False:
        return {}
    r = _chosen(start_pose, rel, onboard)
    return {CUT_KEY: Reprime(0, r, stall_s, word is True)} if r > 0 else {}


def _word(heard: Resets, i: int, b_s: float, stall_s: float, cycle_s: float,
          least: int | None) -> bool | None:
    """The firmware's word at the stall before the cut (summaries ``i`` and on, ``stall_s``
    apart across it; ``b_s``: the life's first frame's bus time): True when said (clear before,
    set after: ``Resets.told``) or latched before a stall that surely re-primed it; None when
    latched before one that only may have (``stallreprime.reprimed_across``'s unsure: both
    hypotheses tried, ``_chosen``'s r = 0 is the not-re-primed one); False otherwise."""
    if not possible(stall_s, cycle_s, least):
        return False
    said = heard.told(b_s)
    if said is None and latched(heard.mask, i):
        return reprimed_across(heard, i, stall_s, cycle_s, least)
    return bool(said)


def _chosen(start: tuple[float, float, float], rel: tuple[FloatArray, FloatArray, FloatArray],
            onboard: Poses) -> int:
    """The frame ``r`` (0: none) whose held path (the staged ``start`` at frame 0 to ``r``, the
    fine steps after) ends nearest the first ``COMPARED`` samples, in LSBs (the worst sample's
    position plus heading), as ``stallreprime._chosen`` scores its pairs."""
    rx, ry, rh = rel
    at = onboard.enc[:COMPARED]
    first = int(at[0])
    x0, y0, h0 = start
    best: tuple[float, int] | None = None
    for r in [0, *range(max(1, first - R_SPAN), first + 1)]:
        turn = h0 - float(rh[r])  # the path from r, turned onto the held staged heading
        c, s = math.cos(turn), math.sin(turn)
        dx, dy = rx[at] - rx[r], ry[at] - ry[r]
        ex = x0 + c * dx - s * dy - onboard.x_m[:COMPARED]
        ey = y0 + s * dx + c * dy - onboard.y_m[:COMPARED]
        eh = wrap_pi(turn + rh[at] - onboard.heading_rad[:COMPARED])
        score = float(np.max(np.hypot(ex, ey) / POSITION_LSB_M + np.abs(eh) / HEADING_LSB_RAD))
        if best is None or score < best[0]:
            best = (score, r)
    assert best is not None
    return best[1]


def cut_left_out(d_left: np.ndarray, d_right: np.ndarray, reprimes: dict[int, Reprime]) -> None:
    """The steps the cut's re-prime left out zeroed (DISTANCE's steps from the life's first
    frame: the firmware's odometer took none of them either)."""
    rep = reprimes.get(CUT_KEY)
    if rep is not None:
        d_left[rep.f : rep.r] = 0
        d_right[rep.f : rep.r] = 0
