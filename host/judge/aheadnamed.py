"""Pose halves naming an encoder frame ahead of every frame the host heard before them, judged
against the frames they may name (issue #11: a PASS must never hide a wrong pose).

``samples.match_encoder`` resolves a pose frame's ENC_COUNTER -8..+7 from the latest accepted
encoder frame before it and leaves the pose out when the frame resolved comes later in the log
or never, or when that latest frame is half a counter lap old (the frames since refused): such
a pose named a frame not sent yet, or one the host refused. ``namesahead`` FAILs it only where
the host heard that frame and the 16 before it at their cadence and the pose's sender was on time: a
delayed encoder frame before it (a delay fault) or the drive's end turned the rule off, and a
pose 10 mm off PASSed unjudged (outside trial: pmir figure8 seed 2, ``reboot=5,delay=0.1:7``,
the pair at 6.001 s named the frame sent at 6.010 s, X +10 mm; kobuki figure8 seed 5 and random
seed 9, the drive's last pair named a frame never sent, X +10 mm: each PASSed).

A firmware names the frame it took, which the bus carried before the pose; the 4-bit name
stands for any frame of its COUNTER, a lap (16 frames) apart. So such a half is judged as a
lone half the reference cannot place (``candidates.CandidateJudge``): against each frame of
its COUNTER it may have taken, from a counter lap before the latest frame heard (or
``candidates.REACH_LAPS`` laps before the last pose frame sent before it: a stall's backlog, a
firmware held on one frame) to the last frame heard at most the recorder's stamping jitter
(``logs.STAMPING_S``) after it (a recorder may write a pose line before its encoder line). It
PASSes if it fits one, FAILs if it fits none; where a candidate cannot be bounded it is counted
unjudged. A correct firmware's frame is among its candidates, so it is never blamed. A pose
after a silence (``silent``: of its sender, a stall's backlog; of the accepted encoder frames a
COUNTER lap long, frames its COUNTER cannot tell apart) is left to the rules main judged it by.

A candidate the host's E2E refused (a delay fault's reordering: kobuki random seed 9,
``delay=0.2:12``, refused most frames near the end, and the firmware's E2E the same ones: its
poses held one name) bounded only by its accepted neighbours less the robot's reach over the
periods between (14 mm on kobuki) fitted the last pose raised 10 mm, though the robot stood
still. The log holds such frames with their CRC right (``refusedenc``). Where one of the half's
COUNTER was heard between the accepted neighbours (give or take a period; at most
``NEIGHBOUR_SPAN`` frames apart), the firmware's pose at the candidate is its pose at the
neighbour before, moved at most by the wheels' whole way (``_moved``: over the accepted frames
of ``STILL_FRAMES`` sender steps before it and to the neighbour after, and to that refused
frame's counts: the frames the firmware took there are not known, the counts are absolute);
the half is judged there less that way where it is shorter than the reach (``AheadJudge``). A
refused frame of its COUNTER heard after the frame it is matched to (the firmware's E2E may
have taken what the host's refused) is a candidate too, judged alike. A refused frame's own
counts alone are no bound: under a heavy reordering (kobuki seed 703, ``delay=0.5:100``: two
streams 100 ms apart interleaved) one of the COUNTER between the neighbours may be a lap off,
and the host's accepted frames are not the path the firmware integrated: a correct Y judged at
such a frame's counts lay 0.31 mm off."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import STAMPING_S
from odocan.host.judge.candidates import CandidateJudge, Excess, Half
from odocan.host.judge.namesahead import HALF_LAP, STAMP_S
from odocan.host.judge.reference import wrap_delta
from odocan.host.judge.refusedenc import Refused
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    SILENCE_CYCLES,
    Encoders,
    FloatArray,
    IntArray,
    PoseHalves,
    named_targets,
)
from odocan.host.judge.stallfirst import better
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

NEIGHBOUR_SPAN = HALF_LAP  # accepted neighbours this many frames apart at most: one COUNTER each
STILL_FRAMES = 2 * 16  # sender steps before the neighbour whose way is counted: two laps
LAP_CYCLES = ENC_COUNTER_LAP - 0.5  # a silence of the encoder frames this long: a COUNTER lap


def forward_rows(enc: Encoders, rows: dict[str, np.ndarray], named: IntArray) -> IntArray:
    """Positions in ``rows`` (one pose message's accepted frames of one life, ``named``: the
    encoder frame each names, -1: none) of the frames ``forward`` finds."""
    return np.flatnonzero(forward(enc, rows["index"].astype(np.int64),
                                  rows["ENC_COUNTER"].astype(np.int64),
                                  rows["timestamp_s"].astype(np.float64), named, None))


def forward(enc: Encoders, index: IntArray, enc_counter: IntArray, t_s: FloatArray,
            named: IntArray, prev_t_s: float | None) -> npt.NDArray[np.bool_]:
    """Per pose frame (bus position ``index``, ENC_COUNTER ``enc_counter``, stamp ``t_s``,
    ``named``: the encoder frame it names, -1: none): left unmatched while its ENC_COUNTER
    resolves ahead of the latest accepted encoder frame before it, or while it has none less
    than half a counter lap older (the host's E2E refused the frames since, as a firmware
    holding one frame does); not after a silence (``silent``). ``enc``: the accepted encoder
    frames (the stream's known ones); ``prev_t_s``: the stamp of the kind's frame before the
    first (None: the life's first)."""
    if len(enc.index) == 0 or len(named) == 0:
        return np.zeros(len(named), dtype=bool)
    has, target = named_targets(enc, index, enc_counter, t_s)
    latest = np.maximum(np.searchsorted(enc.index, index) - 1, 0)
    out: npt.NDArray[np.bool_] = ((named < 0) & (~has | (target > enc.seq[latest]))
                                  & ~silent(enc, index, t_s, prev_t_s))
    return out


def silent(enc: Encoders, index: IntArray, t_s: FloatArray, prev_t_s: float | None
           ) -> npt.NDArray[np.bool_]:
    """Per pose frame: whether a silence leaves its name to other rules, as ``samples`` left
    it. Its sender silent ``SILENCE_CYCLES`` encoder cycles before it (or the life's first
    pose): a stall's first pose names a frame of its backlog, a lap or more back (a 13-tick
    pmir stall: the pose at 5.131 s named the frame of 5.00 s), which ``stallfirst`` (or the
    reboot rules) judges. Or the accepted encoder frames silent a COUNTER lap (``LAP_CYCLES``)
    or more just before it (since the latest, or between the latest and the one before it):
    the frames of its COUNTER the firmware may have taken there, one a lap, the log cannot
    tell apart (a recorder gap of the encoder frames: kobuki 16k-period gaps, every pose in
    the gap judged at the frames before it FAILed a correct firmware; a controller silent 2 s
    then restarted, the pose 1 ms after its first frame named the last before the silence)."""
    cycle_s = enc.cycle_s
    if cycle_s is None:
        return np.zeros(len(index), dtype=bool)
    before = np.r_[np.inf if prev_t_s is None else prev_t_s, t_s[:-1]]
    quiet = (t_s - before >= (SILENCE_CYCLES - 0.5) * cycle_s) | ~np.isfinite(before)
    latest = np.searchsorted(enc.index, index) - 1
    t_enc = enc.timestamp_s
    t_latest = np.where(latest >= 0, t_enc[np.maximum(latest, 0)], -np.inf)
    t_before = np.where(latest >= 1, t_enc[np.maximum(latest - 1, 0)], -np.inf)
    lap_s = LAP_CYCLES * cycle_s
    out: npt.NDArray[np.bool_] = quiet | (t_s - t_latest >= lap_s) | (t_latest - t_before >= lap_s)
    return out


def ahead_halves(halves: PoseHalves, enc: Encoders, sent_s: FloatArray) -> list[Half]:
    """The halves ``forward_rows`` finds as ``candidates.Half``s (X ones first), each matched to
    the last encoder frame heard at most the stamping jitter after it (``sent_s``: every pose
    frame's bus time, sorted)."""
    out = []
    for x, rows, named in ((True, halves.px, halves.ex), (False, halves.py, halves.ey)):
        for r in forward_rows(enc, rows, named).tolist():
            t_s = float(rows["timestamp_s"][r])
            heard = int(np.searchsorted(enc.timestamp_s, t_s + STAMPING_S + STAMP_S,
                                        side="right")) - 1
            if heard < 0:
                continue
            k = int(np.searchsorted(sent_s, t_s, side="left")) - 1
            heading = (float(rows["HEADING"][r]) * HEADING_LSB_RAD if x
                       else float(rows["TURNS"][r]) * 2 * math.pi)
            out.append(Half(x, t_s, int(rows["ENC_COUNTER"][r]), heard,
                            float(rows["X" if x else "Y"][r]) * POSITION_LSB_M, heading,
                            float(sent_s[k]) if k >= 0 else t_s))
    return out


def judge_ahead(halves: PoseHalves, enc: Encoders, sent_s: FloatArray, judge: AheadJudge
                ) -> tuple[list[tuple[float, float, float]], int]:
    """Each half ``ahead_halves`` finds judged by ``judge`` (given ``halves.refused``): (bus
    time, position m and heading rad beyond the allowance) of those judged, and how many no
    candidate judge could bound."""
    judge.refused = halves.refused
    judged, unjudged = [], 0
    for half in ahead_halves(halves, enc, sent_s):
        excess = judge.judge_half(half)
        if excess is None:
            unjudged += 1
        else:
            judged.append((half.t_s, excess[0], excess[1]))
    return judged, unjudged


class AheadJudge(CandidateJudge):
    """``CandidateJudge`` that judges a candidate the host's E2E refused where the robot stood
    still at the neighbour before it, without the reach (module docstring)."""

    refused: Refused | None = None

    def judge_half(self, half: Half) -> Excess | None:
        """``CandidateJudge.judge_half``, and the refused frames of its COUNTER heard after
        the frame it is matched to, at most the stamping jitter after it, judged too (module
        docstring); one that cannot be bounded leaves the half unjudged."""
        found = super().judge_half(half)
        after = self._refused_after(half)
        if not after:
            return found
        if found is None and self._candidates(half):
            return None  # a candidate of the log's accepted frames cannot be bounded
        there = self._at_frame(half, half.matched)
        if there is None:
            return None
        return better(found, _less(there, self._moved(half.matched, half.matched, after)))

    def _candidates(self, half: Half) -> list[int]:
        """``CandidateJudge._candidates``, and the frame of ``half``'s COUNTER the log lacks
        between its matched frame and the next one heard: the sender sent it before that next
        one, maybe before the pose, and the host alone may have lost it (a recorder's loss, a
        stamp set aside by ``stampglitch``): a correct firmware's pose names it."""
        seqs = super()._candidates(half)
        seq, m = self.enc.seq, half.matched
        if not seqs or m + 1 >= min(len(seq), self.end):
            return seqs
        lap = ENC_COUNTER_LAP
        lost = int(seq[m]) + 1 + (half.named - int(self.enc.counter[m]) - 1) % lap
        if lost < int(seq[m + 1]) and lost not in seqs and not self._missed(lost):
            seqs.append(lost)
        return seqs

    def _refused_after(self, half: Half) -> list[int]:
        """The refused frames of ``half``'s COUNTER heard after its matched frame and at most
        the stamping jitter after it."""
        r = self.refused
        if r is None:
            return []
        t_matched = float(self.enc.timestamp_s[half.matched])
        return np.flatnonzero((r.counter == half.named) & (r.t_s > t_matched)
                              & (r.t_s <= half.t_s + STAMPING_S + STAMP_S)).tolist()

    def _at_seq(self, half: Half, s: int) -> Excess | None:
        seq, t = self.enc.seq, self.enc.timestamp_s
        k = int(np.searchsorted(seq, s))
        plain = super()._at_seq(half, s)
        if (self.refused is None or self.enc.cycle_s is None or not 0 < k < len(seq)
                or int(seq[k]) == s or int(seq[k] - seq[k - 1]) > NEIGHBOUR_SPAN):
            return plain
        r, cycle_s = self.refused, self.enc.cycle_s
        near = np.flatnonzero((r.counter == s & ENC_COUNTER_MASK)
                              & (r.t_s >= t[k - 1] - cycle_s) & (r.t_s <= t[k] + cycle_s))
        there = self._at_frame(half, k - 1)
        if len(near) == 0 or there is None or plain is None:
            return plain
        moved = self._moved(k - 1, k, near.tolist())
        return plain if moved[0] >= self.reach[0] else max(plain, _less(there, moved))

    def _moved(self, before: int, after: int, refused: list[int]) -> Excess:
        """How far (m, rad) the robot may have moved from where it was at accepted frame
        ``before``, as the firmware may have integrated it: its wheels' whole way over the
        accepted frames of the ``STILL_FRAMES`` sender steps up to ``before`` and to ``after``,
        and from ``before`` to each of the ``refused`` frames (module docstring)."""
        assert self.refused is not None
        geometry, bits = self.robot[0], self.robot[2]
        lo = int(np.searchsorted(self.enc.seq, int(self.enc.seq[before]) - STILL_FRAMES))
        way = 0.0
        for counts, theirs, per in ((self.enc.left, self.refused.left,
                                     geometry.m_per_count_left),
                                    (self.enc.right, self.refused.right,
                                     geometry.m_per_count_right)):
            run = np.concatenate((counts[lo:before + 1], counts[after:after + 1]))
            steps = np.abs(wrap_delta(np.diff(run), bits)).sum()
            jumps = np.abs(wrap_delta(theirs[refused] - counts[before], bits)).sum()
            way += float(steps + jumps) * per
        return 0.5 * way, way / geometry.wheelbase_m


def _less(excess: Excess, by: Excess) -> Excess:
    """``excess`` less ``by`` (position m, heading rad)."""
    return excess[0] - by[0], excess[1] - by[1]
