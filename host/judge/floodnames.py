"""Which frame of a flood a pose names (issue #11): a sender paused and then sent its backlog
back to back; the firmware's mailbox kept the flood's first frames, it integrated them and made
a pose naming the last by its 4-bit ENC_COUNTER. The plain rule pairs that name with the latest
frame of that COUNTER on the bus, laps after the one the firmware had (a 1 s pause: 397 mm off
a correct firmware). Leaving such names out makes the judges take the flood for a stall and
place the reference again (which hid 10 mm after a babbler's burst), so the pose's own HEADING
tells the frame instead.

The heading is the exact linear function of the cumulative counts (``host.judge.reference``):
from the last pose named without doubt before the flood (its frame's counts, its HEADING) the
heading at each candidate frame (the named frame and those a COUNTER lap, two, ... before it,
each less than ``HALF_LAP`` cycles after the one a lap before: the flood) is known to the
rounding of two wire headings. A candidate is taken when it alone lies within ``MATCH_LSB`` of
the pose's HEADING, and only then; else the plain rule's name stands (as before).

Why a wrong firmware gains nothing: the candidate is chosen by the heading alone, and its
position is then judged against the reference there. A position error moves no heading, so a
pose 10 mm off is paired with its own frame and FAILs as before. A wrong heading that lands
within ``MATCH_LSB`` of another candidate's (5 values of 65536 per candidate) gets that frame's
reference, laps of travel away from the position it shows: a PASS needs the pose to be right,
heading and position, for a frame of that COUNTER the flood did carry, which is what a correct
firmware that kept that frame says. A flood with no heading change between its laps (a straight
line, standing still) ties the candidates: the plain rule's name stands."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.judge.reference import Geometry
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_WIRE_COUNTER_BITS
from odocan.sim.robot import RobotProfile

HALF_LAP = ENC_COUNTER_LAP // 2
MATCH_LSB = 2  # wire headings truncate (<1 LSB each, the anchor's and the pose's) + margin
FOLLOW_CYCLES = 4  # cycles after a renamed X half its tick's Y half and twist may come (``follow``)
BAM16 = 1 << 16

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


def of_robot(robot: RobotProfile) -> tuple[Geometry, int]:
    """What ``resolve_x`` takes of a robot: its geometry and the counts' wrap (bits)."""
    return Geometry.of(robot), min(robot.counter_bits, ENC_WIRE_COUNTER_BITS)


def cumulative_counts(left: IntArray, right: IntArray, bits: int) -> tuple[IntArray, IntArray]:
    """The counts unwrapped frame to frame (mod ``2**bits``, each step the nearest): the
    travel between any two frames as one difference."""
    def unwrapped(counts: IntArray) -> IntArray:
        wide = counts.astype(np.int64)
        steps = np.concatenate((wide[:1], wide[1:] - wide[:-1]))
        half = 1 << (bits - 1)
        out: IntArray = np.cumsum(np.mod(steps + half, 1 << bits) - half)
        return out
    return unwrapped(left), unwrapped(right)


def candidates(seq: IntArray, t_s: FloatArray, named: int, cycle_s: float,
               after_seq: int) -> list[int]:
    """The frames (indices) a pose naming ``named`` by its COUNTER may have meant: ``named``
    and each a lap before it while that came less than ``HALF_LAP`` cycles before the one a
    lap after (the flood), sequence numbers above ``after_seq`` (the anchor's frame)."""
    out = [named]
    k = named
    while True:
        j = int(np.searchsorted(seq, seq[k] - ENC_COUNTER_LAP))
        if (j >= len(seq) or seq[j] != seq[k] - ENC_COUNTER_LAP or seq[j] <= after_seq
                or t_s[k] - t_s[j] >= HALF_LAP * cycle_s):
            return out
        out.append(j)
        k = j


def heading_bam(geometry: Geometry, d_left: float, d_right: float) -> float:
    """The heading change (BAM16 LSB, not wrapped) of ``d_left``, ``d_right`` counts."""
    rad = (d_right * geometry.m_per_count_right - d_left * geometry.m_per_count_left
           ) / geometry.wheelbase_m
    return rad * BAM16 / (2 * math.pi)


def pick(geometry: Geometry, anchor: tuple[int, int, int], counts: list[tuple[int, int]],
         heading_raw: int) -> int | None:
    """Which of the candidates' cumulative ``counts`` (left, right) the pose's HEADING
    (``heading_raw``, BAM16) was made on, from ``anchor`` (left, right, HEADING of the pose
    before the flood): its position in ``counts`` when exactly one lies within ``MATCH_LSB``,
    else None."""
    left_a, right_a, raw_a = anchor
    hits = []
    for k, (left, right) in enumerate(counts):
        predicted = raw_a + heading_bam(geometry, left - left_a, right - right_a)
        off = (predicted - heading_raw + BAM16 / 2) % BAM16 - BAM16 / 2
        if abs(off) <= MATCH_LSB:
            hits.append(k)
    return hits[0] if len(hits) == 1 else None


def resolve_x(named: IntArray, enc_seq: IntArray, enc_t_s: FloatArray,
              cum: tuple[IntArray, IntArray], heading_raw: IntArray, cycle_s: float | None,
              geometry: Geometry) -> IntArray:
    """``named`` (the ODOM_POSE_X halves' encoder frames, ``match_encoder``) with each name a
    flood makes ambiguous taken to the candidate its HEADING alone matches (module
    docstring); the anchor is the last half before it named without doubt. Vectorized to the
    ambiguous halves (a flood's few): a log of millions of poses walks none."""
    if cycle_s is None or len(named) == 0:
        return named
    doubt = _in_flood(named, enc_seq, enc_t_s, cycle_s)
    if not doubt.any():
        return named
    sure = np.flatnonzero((named >= 0) & ~doubt)
    out = named.copy()
    for i in np.flatnonzero(doubt).tolist():
        k = int(np.searchsorted(sure, i)) - 1
        if k < 0:
            continue
        a_half = int(sure[k])
        a = int(named[a_half])
        cands = candidates(enc_seq, enc_t_s, int(named[i]), cycle_s, int(enc_seq[a]))
        if len(cands) == 1:
            continue
        found = pick(geometry, (int(cum[0][a]), int(cum[1][a]), int(heading_raw[a_half])),
                     [(int(cum[0][c]), int(cum[1][c])) for c in cands], int(heading_raw[i]))
        if found is not None:
            out[i] = cands[found]
    return out


def _in_flood(named: IntArray, enc_seq: IntArray, enc_t_s: FloatArray,
              cycle_s: float) -> npt.NDArray[np.bool_]:
    """Which names have a frame a COUNTER lap before them less than ``HALF_LAP`` cycles
    earlier on the bus (``candidates`` finds more than one, the anchor aside)."""
    at = np.maximum(named, 0)
    before = np.minimum(np.searchsorted(enc_seq, enc_seq[at] - ENC_COUNTER_LAP),
                        len(enc_seq) - 1)
    doubt: npt.NDArray[np.bool_] = ((named >= 0)
                                    & (enc_seq[before] == enc_seq[at] - ENC_COUNTER_LAP)
                                    & (enc_t_s[at] - enc_t_s[before] < HALF_LAP * cycle_s))
    return doubt


def follow(named: IntArray, enc_counter: IntArray, t_s: FloatArray,
           renamed: tuple[IntArray, IntArray, IntArray, FloatArray], cycle_s: float) -> IntArray:
    """``named`` with each frame sent with a renamed ODOM_POSE_X half (``renamed``: its plain
    name, its resolved one, its ENC_COUNTER and bus time) taking its name: the same ENC_COUNTER
    and plain name, less than a cycle before it or ``FOLLOW_CYCLES`` after it (the firmware's
    one state of that tick: the Y half, the twist; a first tick that drained a backlog of 79
    frames sent them 17.7 ms after its X, ``lapfirst._tick_window_s``; a later tick naming the
    same plain frame by the same ENC_COUNTER named the same frame)."""
    out = named.copy()
    for plain, resolved, counter, sent_s in zip(*(r.tolist() for r in renamed), strict=True):
        off_s = t_s - sent_s
        out[(named == plain) & (enc_counter == counter) & (off_s > -cycle_s)
            & (off_s < FOLLOW_CYCLES * cycle_s)] = resolved
    return out
