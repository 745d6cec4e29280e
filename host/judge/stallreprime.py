"""A stall the firmware re-primed after, by its own word (issue #11, rule 5: a FAIL must never
blame a correct firmware; ``host.judge.stalls``, ``host.judge.ambiguity``).

A stalled MCU takes the frames it missed as one merged step when it runs again, and the judges
place the reference's position after the stall within the merge allowance, its heading exact
(``host.judge.breaks``). But its plausibility bound after an overrun is the step's periods plus
a COUNTER cycle plus its own periods since its last sample (firmware/encoders.py): about twice
the stall. Past ~3.7 s at pmir's 4 m/s that reaches half the counters' range (the ambiguous
step), and the firmware re-primes on the frame it takes after resuming (COUNTER_RESET): the
stall's motion is not in its pose, by design, and its heading is no longer the exact one.
Judged with the heading exact, the correct firmware FAILed every judge (1619 mm / 3000 mrad
after a 6 s stall).

Where the firmware says so itself (``nearthreshold.Resets.told``: its ERROR_MASK's sticky
COUNTER_RESET clear on the last summary before the stall, set on the first made after the frame
it re-primed on: the first after the stall, or the next one, ``said_reset``) and the stall
was long enough for its bound to reach the ambiguous step (``possible``), the reference
re-primes where the firmware did, as at a counter restart (``reference_path._reprime``:
no step into the frame re-primed on): its steps from the last frame the firmware took before
the stall (``f``) to the frame it re-primed on (``r``) are left out, so its heading and position
are re-placed there, and the stall's placement keeps the merge allowance of the frames up to
``f`` only. The log does not name ``f`` (the receive FIFO kept the first frames after the
halt: up to ``FIFO_SPAN`` after the last sample's) nor ``r`` exactly (the first sample after
a stall is left out: ``stalls.after_stalls``; ``r`` is at most ``R_SPAN`` frames before the
next one): of those pairs the one whose re-primed path best meets the first samples after the
stall is taken (``_chosen``), then judged as every step is. ``f`` may also be followed by a
late frame the host's E2E refused and the resumed firmware's wide-open window took from its FIFO
(``fifolate``: one step back in time, put in as the step into f + 1; kobuki halted 2 s under
``delay=0.3:55`` FAILed the correct firmware by 2.0 mm, 13.4 mrad without it). The event is
reported (``detail``) and the firmware's own DEGRADED state stands (``finalstate``). The
summaries around the stall are read by their gap, not by where a recorder's stamps put them
(``around``: ODOM_STATUS stamped up to ``LATE_S`` late).

A firmware whose word was latched before the stall (COUNTER_RESET set on both summaries around
it: sticky until a set-pose, it says nothing new) re-primes there all the same: its rule
(firmware/encoders.py) is the bound, not the bit. Its bound on the frame after the stall is the
step's periods plus a COUNTER cycle plus the periods since its last sample, measured over halts
of 3-8 s at least twice the halt; the summaries around a stall lie at most a summary period
either side of the halt, and a recorder's stamp ``LATE_S`` more (``SURE_SLACK_S``). So where
twice the stall less that slack reaches the ambiguous step (``certain``) the correct firmware
has re-primed and the reference re-primes with it, the pair chosen as for a declared one (issue
#11: on pmir's square halted 6 s then 8 s, the second stall was judged with the exact heading
and the correct firmware FAILed by 2733 mrad). Between ``possible`` and ``certain`` (pmir's
summaries 3.49 to 3.98 s apart) the latched word cannot tell: the firmware re-primed from a
3.7 s halt on, not at 3.6 s (its bound's periods since its last sample, which the log does not
show). Both hypotheses are tried on the samples after (``unsure``): the re-prime is taken when
its best pair fits within ``FIT_LSB`` or better than the exact heading does, else the exact rule
stays (before, the exact rule alone: pmir's square halted 6 s then 3.7 s or 3.8 s FAILed the
correct firmware by 919 mm). A correct firmware fits the hypothesis it followed; a wrong pose
fits neither and FAILs under the nearer (the robot at rest: both agree). A firmware that
re-primes without ever saying so keeps the exact rule: its heading FAILs. What a wrong firmware
can hide: a heading off by the turn of a few frames at the stall it declared (the pairs'
choice); a position off by more than those frames' merge allowance, or any wrong step after,
FAILs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from odocan.host.judge.fifolate import Judged, LateStep, after_frames, late_steps
from odocan.host.judge.nearthreshold import COUNTER_RESET_BIT, Resets
from odocan.host.judge.refusedenc import Refused
from odocan.host.judge.reprimecount import kept_pairs
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    SILENCE_CYCLES,
    Encoders,
    FloatArray,
    IntArray,
    Poses,
    wrap_pi,
)
from odocan.host.judge.step_periods import COUNTER_VALUES
from odocan.sim.mcu import HW_RX_FIFO_FRAMES

# The firmware's bound after an overrun: the step's periods (at most the stall's plus a COUNTER
# cycle of rounding) + a COUNTER cycle + its periods since its last sample (the stall's, plus
# a cycle of lateness): twice the stall plus these cycles at most.
SLACK_PERIODS = 3 * COUNTER_VALUES
FIFO_SPAN = HW_RX_FIFO_FRAMES + 1  # frames after the last sample's the firmware may have taken
R_SPAN = SILENCE_CYCLES  # frames before the first kept sample's the re-prime may lie on
COMPARED = 10  # samples after the stall the pairs are compared on
LATE_S = 0.05  # a recorder's stamps of ODOM_STATUS this late (half its period) still read
SUMMARY_S = 0.1  # ODOM_STATUS summary period (the DBC's cycle time of the page)
SURE_SLACK_S = 2 * SUMMARY_S + LATE_S  # a stall's summaries' gap beyond the halt, at most
FIT_LSB = 4.0  # a re-primed pair's score (position plus heading LSBs) that fits the samples


class Declared(NamedTuple):
    """A stall the firmware re-primed after by its word (``sure``), or may have (its word
    latched, the stall between ``possible`` and ``certain``: ``unsure``), and its length (s)."""

    stall_s: float
    sure: bool = True


@dataclass(frozen=True)
class Reprime:
    """A declared re-prime after a stall: frames from e0, ``f`` the last the firmware took
    before it, ``r`` the one it re-primed on, and the stall's length (s)."""

    f: int
    r: int
    stall_s: float
    sure: bool = True  # declared (or surely re-primed); False: the samples chose it (unsure)
    late: tuple[int, int] = (0, 0)  # a late frame's step taken after f (``fifolate``), counts


def detail(stall_s: float, sure: bool = True) -> str:
    """The report's words for a re-prime declared after a stall of ``stall_s`` seconds (not
    ``sure``: the word latched, the samples after fit it, not the exact heading)."""
    if not sure:
        return (f"re-primed after a {stall_s:.1f} s stall: motion left out; COUNTER_RESET "
                "latched before (it cannot say it again) and the stall's bound may or may not "
                "have reached half the counters' range: the samples after fit the re-prime, "
                "not the exact heading, so the reference re-primes with it")
    return (f"re-primed after a {stall_s:.1f} s stall: motion left out, declared by the "
            "firmware (COUNTER_RESET; its step's bound reached half the counters' range): the "
            "reference re-primes with it (heading and position re-placed there)")


def possible(stall_s: float, cycle_s: float, least: int | None) -> bool:
    """Whether a stall of ``stall_s`` (bus time) can bring the firmware's step bound to the
    ambiguous step (``least`` periods; None: no plausibility bound, no re-prime)."""
    return least is not None and 2.0 * stall_s / cycle_s + SLACK_PERIODS >= least


def certain(stall_s: float, cycle_s: float, least: int | None) -> bool:
    """Whether a stall whose summaries lie ``stall_s`` apart (bus time) surely brought the
    firmware's step bound to the ambiguous step (``least`` periods): its halt at least
    ``stall_s - SURE_SLACK_S``, its bound at least twice the halt (module docstring)."""
    return least is not None and 2.0 * (stall_s - SURE_SLACK_S) / cycle_s >= least


def latched(mask: IntArray, i: int) -> bool:
    """COUNTER_RESET set on both summaries ``i`` and ``i + 1``: the firmware's word was said
    before the stall and cannot be said again (sticky until a set-pose)."""
    return bool(mask[i] & COUNTER_RESET_BIT) and bool(mask[i + 1] & COUNTER_RESET_BIT)


def reprimed_across(resets: Resets, i: int, stall_s: float, cycle_s: float,
                    least: int | None) -> bool | None:
    """Whether the firmware re-primed across its summaries ``i``, ``i + 1`` (``stall_s``
    apart): said after a stall that could bring it (``possible``, ``said_reset``), or its
    word latched before a stall that surely brought it (``certain``, ``latched``): True; None
    (unsure) when latched before a stall that could bring it only (module docstring)."""
    mask = resets.mask
    if not possible(stall_s, cycle_s, least):
        return False
    if said_reset(mask, i, resets.sent_s):
        return True
    if not latched(mask, i):
        return False
    return True if certain(stall_s, cycle_s, least) else None


def any_declared(resets: Resets, cycle_s: float, least: int | None) -> bool:
    """Whether two consecutive summaries of ``resets`` are a silence the firmware re-primed
    across (``reprimed_across``): the streamed judge then takes one more pass over the life
    (``stream_reprime``)."""
    gaps = np.diff(resets.sent_s)
    return any(reprimed_across(resets, k, float(g), cycle_s, least) is not False
               for k, g in enumerate(gaps.tolist()))


def declared_stalls(breaks: IntArray | None, enc: Encoders, e0: int, resets: Resets,
                    least: int | None) -> dict[int, Declared]:
    """The stalls' ``breaks`` (encoder frames the reference's position restarts at after a
    stall, ``stalls.after_stalls``) after which the firmware declared a re-prime (module
    docstring): each frame, from ``e0``, with the stall's length (s: between the firmware's
    summaries around it), and whether it was ``sure``."""
    if breaks is None or enc.cycle_s is None:
        return {}
    return declared_at({b: float(enc.timestamp_s[b]) for b in breaks.tolist()
                        if e0 < b < len(enc.timestamp_s)}, enc.cycle_s, e0, resets, least)


def declared_at(break_s: dict[int, float], cycle_s: float, e0: int, resets: Resets,
                least: int | None) -> dict[int, Declared]:
    """``declared_stalls`` of the breaks after ``e0`` given with their encoder frames' bus
    times (``break_s``; the streamed judge's, ``stream_reprime``, read in a pass)."""
    out: dict[int, Declared] = {}
    if len(resets.sent_s) == 0:
        return out
    for b, b_s in sorted(break_s.items()):
        i = around(resets.sent_s, b_s)
        if i is None:
            continue
        stall_s = float(resets.sent_s[i + 1] - resets.sent_s[i])
        word = reprimed_across(resets, i, stall_s, cycle_s, least)
        if word is not False:
            out[b - e0] = Declared(stall_s, word is True)
    return out


def around(sent_s: FloatArray, b_s: float) -> int | None:
    """The summaries around the stall the reference restarts after at bus time ``b_s``: ``i``
    and ``i + 1``, consecutive, the widest gap of those whose first is stamped before
    ``b_s + LATE_S`` and whose second after ``b_s`` (None: no such pair). A stalled firmware
    sends nothing, so a summary stamped in that window is its last tick's, stamped late by a
    recorder (issue #11: the summary sent 0.1 ms after the last pose, stamped 10 ms late, fell
    after ``b_s``, and the stall read as its 0.1 s gap: the re-prime went unseen and a correct
    firmware FAILed by 3.1 m); a firmware that talked on has no gap to offer."""
    lo = max(int(np.searchsorted(sent_s, b_s, side="left")) - 1, 0)
    hi = min(int(np.searchsorted(sent_s, b_s + LATE_S, side="left")), len(sent_s) - 1)
    if hi <= lo or sent_s[hi] <= b_s:
        return None
    return lo + int(np.argmax(np.diff(sent_s[lo : hi + 1])))


def said_reset(mask: IntArray, i: int, sent_s: FloatArray | None = None) -> bool:
    """The firmware's word across summaries ``i`` and ``i + 1``: COUNTER_RESET clear on the
    first, set on the first made after the frame it re-primed on (``nearthreshold.Resets.told``'s
    reading for a stall): ``i + 1``, or ``i + 2`` (``sent_s``: the summaries' bus times) when
    ``i + 1`` said nothing yet and ``i + 2`` followed it without a silence. The resumed firmware
    takes the frames its FIFO kept on its first tick and the frame it re-primes on the tick
    after; its first summary is made on that first tick when the stall ends on a summary tick
    (issue #11: every ``--faults stall=T:DUR``, whole tenths of a second, on kobuki 2 s, on pmir
    6 s): read there alone, the correct firmware FAILed by 825 mm / 2288 mrad."""
    if mask[i] & COUNTER_RESET_BIT:
        return False
    if mask[i + 1] & COUNTER_RESET_BIT:
        return True
    return (sent_s is not None and i + 2 < len(mask) and bool(mask[i + 2] & COUNTER_RESET_BIT)
            and float(sent_s[i + 2] - sent_s[i + 1]) <= SUMMARY_S + 2 * LATE_S)


def stall_reprimes(declared: dict[int, Declared], onboard: Poses, e0: int,
                   rel: tuple[FloatArray, FloatArray, FloatArray],
                   start: tuple[float, float, float] | None,
                   lost: dict[int, int] | None = None,
                   fifo: tuple[Encoders, Refused | None, Judged] | None = None,
                   ) -> dict[int, Reprime]:
    """Per declared stall (``declared_stalls``, frames from ``e0``) the pair (f, r) chosen
    (module docstring), from the reference's path from the start (``rel``: x, y m, heading rad
    per frame from e0, the fine steps) and the on-board samples; ``start``: the exact start
    pose at e0 (power-up, set-pose), None when fitted; ``lost``: per stall's break (absolute
    frame) the first count page's ENC_E2E_LOST that pins its pairs (``reprimecount``);
    ``fifo``: the accepted frames, the log's refused CRC-right ones and how a step is
    integrated, for the late frames f may be followed by (``fifolate``). A stall
    without samples after it, or without a sample or an exact start before it, is left to the
    exact rule, and so is an unsure one whose samples do not choose the re-prime (``_chosen``)."""
    at = onboard.enc - e0
    out: dict[int, Reprime] = {}
    after_k = after_frames(fifo[1] if fifo else None, fifo[0].timestamp_s if fifo else rel[0])
    for b, (stall_s, sure) in sorted(declared.items()):
        before = np.flatnonzero(at < b)
        if len(before):
            s0 = int(before[-1])
            anchor = (int(at[s0]), float(onboard.x_m[s0]), float(onboard.y_m[s0]),
                      float(onboard.heading_rad[s0]))
        elif start is not None:
            anchor = (0, *start)
        else:
            continue
        after = np.flatnonzero(at >= b)[:COMPARED]
        if len(after) == 0:
            continue
        first = int(at[after[0]])
        late = [] if fifo is None or (lost or {}).get(b + e0) is not None else late_steps(
            fifo[1], after_k, (b - 1, min(b - 1 + FIFO_SPAN, first - 1)),
            (fifo[0].left, fifo[0].right), e0, fifo[2])
        pair = _chosen(b, first, anchor, rel, (
            at[after], onboard.x_m[after], onboard.y_m[after], onboard.heading_rad[after]),
            (lost or {}).get(b + e0), unsure=not sure, late=late)
        if pair is not None:
            out[b] = Reprime(pair[0], pair[1], stall_s, sure, pair[2])
    return out


Pair = tuple[int, int, tuple[int, int]]  # f, r, the late step after f (``Reprime.late``)


def _chosen(b: int, first: int, anchor: tuple[int, float, float, float],
            rel: tuple[FloatArray, FloatArray, FloatArray],
            samples: tuple[IntArray, FloatArray, FloatArray, FloatArray],
            lost: int | None = None, *, unsure: bool = False,
            late: list[LateStep] | None = None) -> Pair | None:
    """The pair (f, r) whose re-primed path, placed on the ``anchor`` (frame from e0, its
    on-board x, y, heading), ends nearest the ``samples`` after (frames from e0, x, y,
    heading), in LSBs (the worst sample's position plus heading); ``first``: the first of
    them; ``lost``: ENC_E2E_LOST, the pairs it allows only (``reprimecount.kept_pairs``);
    ``late``: late frames f may be followed by (``fifolate``: f is then their ``k``).
    ``unsure``: None unless that pair fits (``FIT_LSB``) or beats the exact heading's worst
    sample (LSBs; position left to the stall's placement: module docstring)."""
    rx, ry, rh = rel
    k0, ax, ay, ah = anchor
    turn0 = ah - float(rh[k0])
    cos0, sin0 = math.cos(turn0), math.sin(turn0)
    at, on_x, on_y, on_h = samples
    best: tuple[float, int, int, tuple[int, int]] | None = None
    pairs = [(f, r) for f in range(b - 1, min(b - 1 + FIFO_SPAN, first - 1) + 1)
             for r in range(max(f + 1, first - R_SPAN), first + 1)]
    ends = [(f, r, _end(rel, f)) for f, r in kept_pairs(pairs, lost)]
    ends += [(s.k, r, _end(rel, s.k, s)) for s in late or []
             for r in range(max(s.k + 1, first - R_SPAN), first + 1)]
    for f, r, (fx, fy, fh, step) in ends:
        left = float(rh[r]) - fh  # the turn the re-prime left out
        c, s = math.cos(-left), math.sin(-left)
        dx, dy = rx[at] - rx[r], ry[at] - ry[r]
        px = fx - rx[k0] + c * dx - s * dy
        py = fy - ry[k0] + s * dx + c * dy
        ex = ax + cos0 * px - sin0 * py - on_x
        ey = ay + sin0 * px + cos0 * py - on_y
        eh = wrap_pi(turn0 + rh[at] - left - on_h)
        score = float(np.max(np.hypot(ex, ey) / POSITION_LSB_M
                             + np.abs(eh) / HEADING_LSB_RAD))
        if best is None or score < best[0]:
            best = (score, f, r, step)
    if best is None or (unsure and best[0] > FIT_LSB
                        and best[0] >= _exact_lsb(turn0 + rh[at] - on_h)):
        return None
    return best[1], best[2], best[3]


def _end(rel: tuple[FloatArray, FloatArray, FloatArray], f: int,
         late: LateStep | None = None) -> tuple[float, float, float, tuple[int, int]]:
    """The reference's pose (x, y m, heading rad) where the firmware's last step before the
    re-prime ended: at frame ``f``, or one ``late`` step after it; and that step's counts."""
    x, y, h = float(rel[0][f]), float(rel[1][f]), float(rel[2][f])
    if late is None:
        return x, y, h, (0, 0)
    c, s = math.cos(h), math.sin(h)
    return (x + c * late.x_m - s * late.y_m, y + s * late.x_m + c * late.y_m,
            h + late.turn_rad, (late.d_left, late.d_right))


def _exact_lsb(heading_off_rad: FloatArray) -> float:
    """The exact rule's fit to the samples after a stall (``heading_off_rad``: each one's
    heading less the reference's, nothing left out): the worst, in heading LSBs."""
    return float(np.max(np.abs(wrap_pi(heading_off_rad)))) / HEADING_LSB_RAD


def left_out(d_left: IntArray, d_right: IntArray, reprimes: dict[int, Reprime]) -> None:
    """The steps the firmware left out at each re-prime (into frames f + 1 .. r) zeroed, as
    ``reference_path._reprime`` zeroes the step into a counter restart's frame."""
    for rep in reprimes.values():
        d_left[rep.f : rep.r] = 0
        d_right[rep.f : rep.r] = 0
        d_left[rep.f], d_right[rep.f] = rep.late  # the late frame's step into f + 1 (fifolate)


def left_out_at(k: int, reprimes: dict[int, Reprime]) -> bool:
    """Whether frame ``k`` (from e0) lies in a re-prime's left-out span (f + 1 .. r): the
    firmware integrated nothing into it, so a gap of the log that ends there carries no motion
    on board and its placement no allowance (issue #11: the log's gaps inside a 6 s halt the
    firmware re-primed across summed to 1257 mm allowed, absorbing a pose 10 mm off)."""
    return any(rep.f < k <= rep.r for rep in reprimes.values())


def reprime_events(timestamp_s: Any, enc: Encoders, start: int,
                   reprimes: dict[int, Reprime]) -> list[dict[str, Any]]:
    """``analyze``'s events of the declared re-primes (frames from ``start``), at the frame
    the firmware re-primed on."""
    return [{"kind": "stall_reprime", "t_s": float(timestamp_s[enc.index[start + rep.r]]),
             "encoder_frame": int(start + rep.r), "detail": detail(rep.stall_s, rep.sure)}
            for _, rep in sorted(reprimes.items())]
