"""Pose halves naming an encoder frame ahead of every frame the host heard before them, judged
against the frames they may name (issue #11: a PASS must never hide a wrong pose).

``samples.match_encoder`` resolves a pose frame's ENC_COUNTER -8..+7 from the latest accepted
encoder frame before it and leaves the pose out when the frame resolved comes later in the log
or never: such a pose named a frame not sent yet. ``namesahead`` FAILs it only where the host
heard that frame and the 16 before it at their cadence and the pose's sender was on time: a
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
unjudged. A correct firmware's frame is among its candidates, so it is never blamed.

A candidate the host's E2E refused (a delay fault's reordering: kobuki random seed 9,
``delay=0.2:12``, refused most frames near the end, and the firmware's E2E the same ones: its
poses held one name) bounded only by its accepted neighbours less the robot's reach over the
periods between (14 mm on kobuki) fitted the last pose raised 10 mm. The log holds that frame
with its CRC right (``refusedenc``): where its accepted neighbours lie at most
``NEIGHBOUR_SPAN`` frames apart (no other frame of its COUNTER between them), a refused frame
of its COUNTER heard between them (give or take a period) whose counts lie between theirs is
that frame; the pose is judged at it by its own counts (``AheadJudge``). Several: the best."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import STAMPING_S
from odocan.host.judge.candidates import CandidateJudge, Excess, Half, _beyond
from odocan.host.judge.namesahead import HALF_LAP, STAMP_S
from odocan.host.judge.reference import wrap_delta
from odocan.host.judge.refusedenc import Refused
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    Encoders,
    FloatArray,
    IntArray,
    PoseHalves,
    named_targets,
)
from odocan.host.judge.stallfirst import NEAR_FRAMES, Pair, better, carried_pose
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

NEIGHBOUR_SPAN = HALF_LAP  # accepted neighbours this many frames apart at most: one COUNTER each


def forward_rows(enc: Encoders, rows: dict[str, np.ndarray], named: IntArray) -> IntArray:
    """Positions in ``rows`` (one pose message's accepted frames, ``named``: the encoder frame
    each names, -1: none) of the frames ``forward`` finds."""
    return np.flatnonzero(forward(enc, rows["index"].astype(np.int64),
                                  rows["ENC_COUNTER"].astype(np.int64),
                                  rows["timestamp_s"].astype(np.float64), named))


def forward(enc: Encoders, index: IntArray, enc_counter: IntArray, t_s: FloatArray,
            named: IntArray) -> npt.NDArray[np.bool_]:
    """Per pose frame (bus position ``index``, ENC_COUNTER ``enc_counter``, stamp ``t_s``,
    ``named``: the encoder frame it names, -1: none): left unmatched while its ENC_COUNTER
    resolves ahead of the latest accepted encoder frame before it, or while it has none less
    than half a counter lap older (the host's E2E refused the frames since, as a firmware
    holding one frame does). ``enc``: the accepted encoder frames (the stream's known ones)."""
    if len(enc.index) == 0 or len(named) == 0:
        return np.zeros(len(named), dtype=bool)
    has, target = named_targets(enc, index, enc_counter, t_s)
    latest = np.maximum(np.searchsorted(enc.index, index) - 1, 0)
    out: npt.NDArray[np.bool_] = (named < 0) & (~has | (target > enc.seq[latest]))
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
    """``CandidateJudge`` that judges a candidate the host's E2E refused at its own counts
    where the log holds it (module docstring)."""

    refused: Refused | None = None

    def judge_half(self, half: Half) -> Excess | None:
        """``CandidateJudge.judge_half``, and the refused frames of its COUNTER heard after
        the frame it is matched to (the last accepted one heard by it, give or take the
        stamping jitter) judged too: the firmware may have taken one the host's E2E refused
        (module docstring); one that cannot be bounded leaves the half unjudged."""
        found = super().judge_half(half)
        after = self._refused_after(half)
        if not after:
            return found
        if found is None and self._candidates(half):
            return None  # a candidate of the log's accepted frames cannot be bounded
        for i in after:
            there = self._at_refused(half, half.matched + 1, i)
            if there is None:
                return None
            found = better(found, there)
        return found

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
        if (self.refused is None or self.enc.cycle_s is None or not 0 < k < len(seq)
                or int(seq[k]) == s or int(seq[k] - seq[k - 1]) > NEIGHBOUR_SPAN):
            return super()._at_seq(half, s)
        r, cycle_s = self.refused, self.enc.cycle_s
        near = np.flatnonzero((r.counter == s & ENC_COUNTER_MASK)
                              & (r.t_s >= t[k - 1] - cycle_s) & (r.t_s <= t[k] + cycle_s))
        best: Excess | None = None
        for i in near.tolist():
            if self._between(k, int(r.left[i]), int(r.right[i])):
                best = better(best, self._at_refused(half, k, i))
        return best if best is not None else super()._at_seq(half, s)

    def _between(self, k: int, left: int, right: int) -> bool:
        """Whether counts (``left``, ``right``) lie between those of accepted frames k-1 and
        k, per wheel (wrapping)."""
        bits = self.robot[2]
        for counts, own in ((self.enc.left, left), (self.enc.right, right)):
            to_own = int(wrap_delta(own - int(counts[k - 1]), bits))
            to_next = int(wrap_delta(int(counts[k]) - int(counts[k - 1]), bits))
            if not min(0, to_next) <= to_own <= max(0, to_next):
                return False
        return True

    def _at_refused(self, half: Half, k: int, i: int) -> Excess | None:
        """``half``'s excess at refused frame ``i`` (between accepted frames k-1 and k):
        carried from the nearest kept sample on either side to its counts."""
        assert self.refused is not None
        own = (np.array([self.refused.left[i]]), np.array([self.refused.right[i]]))
        j = int(np.searchsorted(self.kept_enc, k - 1, side="right"))
        best: Excess | None = None
        for jj, c in ((j - 1, k - 1), (j, k)):  # a sample at or before k-1; at or after k
            if not 0 <= jj < len(self.kept_enc):
                continue
            kept = int(self.kept_enc[jj])
            a, b = min(kept, c), max(kept, c)
            if b - a > NEAR_FRAMES or np.any((self.jumps > a) & (self.jumps <= b)):
                continue
            forward = jj == j - 1
            left, right = self.enc.left[a:b + 1], self.enc.right[a:b + 1]
            counts = ((np.concatenate((left, own[0])), np.concatenate((right, own[1])))
                      if forward else
                      (np.concatenate((own[0], left)), np.concatenate((own[1], right))))
            pair = Pair(0.0, 0, kept, float(self.kept.x_m[jj]), float(self.kept.y_m[jj]),
                        float(self.kept.heading_rad[jj]))
            x, y, heading, slack_m = carried_pose(pair, counts, forward, self.robot)
            best = better(best, _beyond(half, (x, y, heading), slack_m))
        return best
