"""A gap of the log that ends in a controller restart (issue #11, rule 5: a FAIL must never blame
a correct firmware).

The firmware re-primes on the restarted controller's first frame (COUNTER_RESET, no step into
it: ``reference_path.firmware_steps``), so when it took exactly the log's frames up to the
restart, nothing it integrated is missing from the log and the reference goes on exactly across
the gap (no allowance: a firmware that integrated the restart's jump, or is off, FAILs). That is
so when ENC_E2E_OK proves it (``gapseen.Seen.took_across``: the firmware accepted no frame the
log lacks from the frame before the gap to the restart's first).

Otherwise, where the log went dark before the restart (no frame of any message for
``gapseen.DARK_CYCLES`` encoder cycles since the encoder frame before: the recorder lost frames,
``Seen.holes``), the firmware may have integrated frames the log does not hold (with or without
pages to tell: the pages of the dark span are lost too), and across the restarted counters
their counts are unknowable: neither its position nor its heading after the restart follow
from the log. The reference then restarts there as a new life with a placed start: its heading
the middle of the overlap of the heading rounding intervals of the on-board samples from the
restart to the next such restart (``heading_offsets``), its path from the restart on rotated by
that, and its position placed freely (``gapbound`` allowance inf: ``breaks.bound_offsets``).
A gap of the encoder frames alone, the firmware's frames logged across it, is the controller's
silence (or frames E2E refused, held in the log): the exact rule stays there, as before (a
recorder that drops encoder frames only is not modelled: a known limit).

What a wrong firmware can hide there: one wrong pose jump at the restart (position and heading
at once), as a log that starts mid-drive hides a wrong start pose. What it cannot: any wrong
step before or after it (the reference integrates every step of the log on both sides, the
placed start uses every sample of the new life, which must agree within their rounding), nor
a restart the pages prove it took exactly (the exact rule). Each such restart is an event of the
report (``DETAIL``) and counted (``samples.unseen_restarts``). The streamed judge does not fit
the new start: it refuses such a life (``whole_only``) and ``odocan analyze`` judges it whole.
The live judge (``host.judge.tracking``) restarts its reference there from the next on-board
pose when its input went dark before the restart (``host.judge.livedark``), with this event, and
judges the new life's first second of samples by the start fitted over all of them
(``host.judge.livenewstart``), the samples after by that fit as it goes on.
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.judge.evidenceless import evidenceless
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.samples import Encoders, FloatArray, IntArray, wrap_pi

if TYPE_CHECKING:
    from odocan.host.judge.stream_life import LifeInfo

AMBIGUOUS = ("re-primed: the counts could not span the silence (its bound reached half the "
             "counters' range); the reference re-primed where the firmware must (COUNTER_RESET): "
             "the motion across is unknowable")
EVIDENCELESS = ("an ambiguous gap the log gives no evidence for (host.judge.evidenceless): the "
                "whole log's judge chooses re-prime or gap by the next pose")
NEAR = ("the firmware's COUNTER_RESET at a long gap differs from the stream's re-prime (a "
        "silence near the ambiguity threshold): judged on the whole log")
THROUGH = ("a long gap of the log's encoder frames the firmware's pages prove it took frames "
           "in: judged on the whole log")
DETAIL = ("a controller restart (CTRL_UPTIME went back) behind a silence of the log (frames the "
          "recorder lost, or a controller that stopped sending): the firmware may have taken "
          "frames the log lacks and their counts are unknowable across the restarted counters; "
          "the reference restarts from the on-board pose after it (heading included)")


def unseen_restarts(enc: Encoders, e0: int, by_uptime: list[int], seen: Seen) -> list[int]:
    """The controller restarts (frames from ``e0`` the firmware re-primed on, ``by_uptime``)
    that end a gap of the log where it went dark (``Seen.holes``) and that the pages do not
    prove the firmware took exactly (module docstring), ascending."""
    return sorted(k for k in by_uptime
                  if k > 0 and int(enc.seq[e0 + k] - enc.seq[e0 + k - 1]) > 1
                  and e0 + k in seen.holes and not seen.took_across(e0 + k))


def whole_only(seen: Seen, info: LifeInfo, refusal: type[Exception]
               ) -> tuple[Seen, frozenset[int]]:
    """The streamed judge's ``seen`` and re-primed frames of a life (``info``: its first
    placement pass's); ``refusal`` (``stream_analysis.NotStreamable``: the whole log's judge
    then) when a controller restart there is a new start (``unseen_restarts``): the stream
    does not fit the new start's heading; nor when the stream's reference re-primed at a gap
    the firmware's pages prove it took frames in (``Seen.through``: the stream steps before
    the pages are read; the whole log's reference takes such a gap as a gap, ``holetaken``),
    nor where the firmware's word differs from its re-primes (``nearthreshold``)."""
    if any(b in info.gap_steps and b in seen.holes and not seen.took_across(b)
           for b in info.by_uptime):
        raise refusal(DETAIL)
    if any(b in seen.through for b in info.by_uptime):
        raise refusal(THROUGH)
    if seen.resets.disagrees(frozenset(info.reprimed), info.least, seen.holes):  # nearthreshold
        raise refusal(NEAR)
    if any(b in info.gap_steps and evidenceless(seen, b) for b in info.by_uptime):
        raise refusal(EVIDENCELESS)  # the whole log's judge chooses by the next pose
    return seen, frozenset(info.reprimed)


def heading_offsets(unseen: list[int], rel_h: FloatArray, heading_rad: FloatArray,
                    at: IntArray, unwrapped_rad: FloatArray) -> FloatArray:
    """Per frame of the reference (from ``e0``: ``rel_h`` its heading from the start), the
    heading (rad) each restart of ``unseen`` adds from it on: the middle of the overlap of the
    heading intervals of the on-board samples (``heading_rad`` at frames ``at``) after it, less
    that of the samples of the life before it (0 for a life without samples: nothing to
    compare there), plus the whole turns the on-board unwrapped heading (``unwrapped_rad``:
    TURNS * 2 pi + HEADING) took across it (``_turns_across``)."""
    cuts = [0, *unseen, len(rel_h)]
    mids, firsts = [], []
    for a, b in itertools.pairwise(cuts):
        inside = (at >= a) & (at < b)
        offsets = wrap_pi(heading_rad[inside] - rel_h[at[inside]])
        mids.append(_middle(offsets) if len(offsets) else math.nan)
        first = np.flatnonzero(inside)[:1]  # the life's first sample's unwrapped offset
        firsts.append(float(unwrapped_rad[first[0]] - rel_h[at[first[0]]]) if len(first) else 0.0)
    add = np.zeros(len(rel_h))
    known = mids[0] if not math.isnan(mids[0]) else 0.0
    known_first = firsts[0]
    for k, mid, first_rad in zip(unseen, mids[1:], firsts[1:], strict=True):
        if not math.isnan(mid):
            turn = float(wrap_pi(np.array([mid - known]))[0])
            add[k:] += turn + _turns_across(first_rad - known_first, turn)
            known, known_first = mid, first_rad
    return add


def _turns_across(unwrapped_rad: float, wrapped_rad: float) -> float:
    """The whole turns (rad, a multiple of 2 pi) by which the on-board unwrapped heading's
    change across a restart (``unwrapped_rad``: its first samples' offsets from the reference,
    before and after) exceeds the wrapped one (``wrapped_rad``, in (-pi, pi]). Its heading
    across the restart is unknowable (module docstring), its whole turns as much as its
    fraction: the new start takes both, as a fitted start takes its first sample's turn
    (``host.judge.turns``), so a drive that turned past half a turn inside the gap is not
    judged 2 pi off; TURNS after the new start is judged from it."""
    return 2.0 * math.pi * round((unwrapped_rad - wrapped_rad) / (2.0 * math.pi))


def restarted_path(unseen: list[int], rel_x: FloatArray, rel_y: FloatArray, rel_h: FloatArray,
                   add_h: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The reference's path from the start (``rel_*``, m and rad) with each restart of
    ``unseen`` a new start: the path after it rotated about its frame by the heading it adds
    (``add_h``: ``heading_offsets``); its position is placed later (allowance inf)."""
    x, y = rel_x.copy(), rel_y.copy()
    for k in unseen:
        turn = float(add_h[k] - (add_h[k - 1] if k > 0 else 0.0))
        cos_t, sin_t = math.cos(turn), math.sin(turn)
        dx, dy = x[k:] - x[k], y[k:] - y[k]
        x[k:], y[k:] = x[k] + cos_t * dx - sin_t * dy, y[k] + sin_t * dx + cos_t * dy
    return x, y, rel_h + add_h


def _middle(offsets: FloatArray) -> float:
    """The middle of the overlap of [o - lsb/2, o + lsb/2] over ``offsets`` (unwrapped about
    the first); the middle of the extremes when they do not overlap (a wrong firmware)."""
    around = offsets[0] + wrap_pi(offsets - offsets[0])
    return 0.5 * (float(np.max(around)) + float(np.min(around)))


def restart_detail(by_uptime: bool, unseen: bool = False, *, ambiguous: bool = False) -> str:
    """The report's words for an encoder frame the firmware re-primes on (COUNTER_RESET):
    ``by_uptime``, the motor controller said it restarted (CTRL_UPTIME went back); ``unseen``:
    after frames the recorder lost (``unseenrestart.DETAIL``); ``ambiguous``: a step too
    long to read (``AMBIGUOUS``), whatever CTRL_UPTIME says. The same words in ``analyze``'s
    events, the monitor's (screen and ``--json``) and the bridge's status events."""
    if unseen:
        return DETAIL
    if ambiguous:
        return AMBIGUOUS
    cause = ("the motor controller restarted (CTRL_UPTIME went back): " if by_uptime
             else "")
    return (f"{cause}the firmware re-primes here (COUNTER_RESET): the reference restarts with "
            "it; the motion across the restart is unknowable")
