"""A lone pose half judged against every encoder frame it may name (issue #11: a PASS must never
hide a wrong pose).

``lonehalves`` judges a lone half against the reference at the frame its ENC_COUNTER is matched to;
where that frame is not sure it left the half unjudged, and a pose of any value PASSed: the first
pose after a stall on a lossy bus (kobuki seed 5, ``stall=4:0.2,drop=0.05``: the logger missed
frames of the silence too, the X at 4.201 s raised 10 m), a lone X that may alias a later frame of
its ENC_COUNTER (``resendalias``; kobuki seed 3, ``delay=0.3:55,dup=0.1``, +10 mm at 6.136 s), one
in a segment of the reference without a kept sample. Such a half still names one frame of a few: the
frames whose sender sequence number has its ENC_COUNTER, from a counter lap before the frame it is
matched to (or ``REACH_LAPS`` laps before the last pose frame sent before it: a stall's backlog), to
the last encoder frame heard when it was sent; not a frame the log lacks that the firmware's pages
prove it missed too (``_missed``: pmir figure8 seed 10, ``burst=0.05:10``, a lost frame a lap before
the one a lone Y names, its neighbours 3 periods off, fitted that Y raised 10 mm by pmir's 40 mm
reach a period). It is judged against each (``judge_half``): it PASSes if it fits one, FAILs if it
fits none, and stays unjudged only if one of them cannot be bounded (it may name that one).

The pose at a candidate frame the log holds is a kept sample's (the firmware's own, judged by the
reference in turn) carried over the count steps to it (``stallfirst.carried_pose``: the counts are
absolute; its slack the worst merge of the frames between and the sample's rounding), from the
nearest kept sample on either side within ``NEAR_FRAMES`` frames, not across a counter restart or a
re-prime (the firmware's pose jumps there); the better side counts. A candidate the log lacks (lost,
or refused by the host's E2E: the firmware may have taken it) lies between the nearest frames the
log holds on either side, and within the plausibility bound's reach of each (the robot profile's
maximum wheel speed over the periods between: position and heading): it is bounded by theirs less
that reach."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from odocan.host.judge.gapseen import NOTHING, Seen
from odocan.host.judge.reference import Geometry
from odocan.host.judge.reference_path import Reference
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    Encoders,
    FloatArray,
    IntArray,
    PoseHalves,
    Poses,
)
from odocan.host.judge.stallfirst import NEAR_FRAMES, Pair, better, carried_pose
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP

REACH_LAPS = 2  # counter laps before the last pose sent before the half: a stall's backlog
Excess = tuple[float, float]  # (position m, heading rad) beyond the allowance


@dataclass(frozen=True)
class Half:
    """One lone half: ODOM_POSE_X (``x``: X and HEADING) or ODOM_POSE_Y (Y and TURNS)."""

    x: bool
    t_s: float  # bus time
    named: int  # its ENC_COUNTER
    matched: int  # the encoder frame it was matched to (index into Encoders)
    value_m: float  # X or Y
    heading_rad: float  # X: HEADING (0 .. 2 pi); Y: TURNS * 2 pi (the turn's start)
    prev_sent_s: float  # the last pose frame sent before it (t_s: none)


class CandidateJudge:
    """Judges lone halves against their candidate frames (module docstring)."""

    def __init__(self, enc: Encoders, kept: Poses, ref: Reference,
                 robot: tuple[Geometry, str, int], seen: Seen = NOTHING) -> None:
        self.enc, self.ref, self.robot, self.seen = enc, ref, robot, seen
        self._restarts = frozenset(ref.counter_restarts)  # for ``_missed``
        order = np.argsort(kept.enc, kind="stable")
        self.kept_enc = kept.enc[order]
        self.kept = Poses(kept.enc[order], kept.x_m[order], kept.y_m[order],
                          kept.heading_rad[order], kept.heading_raw[order])
        jumps = {*ref.counter_restarts, *ref.unseen_restarts,
                 *(ref.start + b for b in ref.stall_reprimes)}
        self.jumps = np.array(sorted(jumps), dtype=np.int64)
        self.end = ref.start + len(ref.x_m)
        cycle_s = enc.cycle_s or 0.0
        speed_m_s = robot[0].max_wheel_speed_mm_s * 1e-3
        self.reach = (speed_m_s * cycle_s, 2.0 * speed_m_s / robot[0].wheelbase_m * cycle_s)
        self._made: dict[tuple[int, int], tuple[float, float, float, float]] = {}

    def judge_half(self, half: Half) -> Excess | None:
        """``half``'s excess at the candidate it fits best; None when a candidate (or every
        one) cannot be bounded."""
        best: Excess | None = None
        seqs = self._candidates(half)
        if not seqs:
            return None
        for s in seqs:
            excess = self._at_seq(half, s)
            if excess is None:
                return None
            best = better(best, excess)
        return best

    def _candidates(self, half: Half) -> list[int]:
        """The sender sequence numbers of the frames ``half`` may name (module docstring)."""
        enc, cycle_s = self.enc, self.enc.cycle_s
        if cycle_s is None or not self.ref.start <= half.matched < self.end:
            return []
        seq = enc.seq
        lap = ENC_COUNTER_LAP
        t_lo = half.prev_sent_s - REACH_LAPS * lap * cycle_s
        lo = int(np.searchsorted(enc.timestamp_s, t_lo, side="left"))
        hi = int(np.searchsorted(enc.timestamp_s, half.t_s, side="right")) - 1
        s_lo = min(int(seq[half.matched]) - lap, int(seq[min(lo, len(seq) - 1)]))
        s_hi = max(int(seq[half.matched]), int(seq[max(hi, 0)]))
        s_lo = max(s_lo, int(seq[self.ref.start]))
        s_hi = min(s_hi, int(seq[self.end - 1]))
        # the COUNTER of a sequence number, from the matched frame's (seq unwraps it)
        first = s_lo + (half.named - int(enc.counter[half.matched]) + int(
            seq[half.matched]) - s_lo) % lap
        return [s for s in range(first, s_hi + 1, lap) if not self._missed(s)]

    def _missed(self, s: int) -> bool:
        """Whether the firmware's pages prove it took no frame of sequence number ``s``: one
        the log lacks, in a gap it missed whole or over which it took exactly the log's frames
        (``gapseen.Seen.gap_missed``): a frame it never took is no frame it names."""
        k = int(np.searchsorted(self.enc.seq, s))
        if k >= len(self.enc.seq) or int(self.enc.seq[k]) == s:
            return False
        return self.seen.gap_missed(k, self._restarts)

    def _at_seq(self, half: Half, s: int) -> Excess | None:
        """``half``'s excess at the frame of sequence number ``s`` (module docstring)."""
        seq = self.enc.seq
        k = int(np.searchsorted(seq, s))
        if k < len(seq) and int(seq[k]) == s:
            return self._at_frame(half, k)
        sides = []
        for c in (k - 1, k):  # the frames the log holds around it
            if not self.ref.start <= c < self.end:
                continue
            there = self._at_frame(half, c)
            if there is not None:
                periods = abs(int(seq[c]) - s)
                sides.append((there[0] - periods * self.reach[0],
                              there[1] - periods * self.reach[1]))
        if not sides:
            return None
        return (max(p for p, _ in sides), max(h for _, h in sides))

    def _at_frame(self, half: Half, c: int) -> Excess | None:
        """``half``'s excess at encoder frame ``c``: carried from the nearest kept sample on
        either side (the better), None without one."""
        i = int(np.searchsorted(self.kept_enc, c, side="right"))
        best: Excess | None = None
        for j in (i - 1, i):
            if not 0 <= j < len(self.kept_enc):
                continue
            k = int(self.kept_enc[j])
            a, b = min(k, c), max(k, c)
            if b - a > NEAR_FRAMES or np.any((self.jumps > a) & (self.jumps <= b)):
                continue
            x, y, heading, slack_m = self._carried(j, c)
            best = better(best, _beyond(half, (x, y, heading), slack_m))
        return best

    def _carried(self, j: int, c: int) -> tuple[float, float, float, float]:
        """Kept sample ``j`` carried to encoder frame ``c`` (``carried_pose``), made once: a
        frame is a candidate of several halves, and the neighbour of the frames lost beside it."""
        key = (j, c)
        if key not in self._made:
            k = int(self.kept_enc[j])
            a, b = min(k, c), max(k, c)
            near = Pair(0.0, 0, k, float(self.kept.x_m[j]), float(self.kept.y_m[j]),
                        float(self.kept.heading_rad[j]))
            self._made[key] = carried_pose(
                near, (self.enc.left[a:b + 1], self.enc.right[a:b + 1]), c > k, self.robot)
        return self._made[key]


def _beyond(half: Half, carried: tuple[float, float, float], slack_m: float) -> Excess:
    """How far ``half`` lies from the ``carried`` pose beyond ``slack_m`` (position) and the
    carried heading's half LSB: an X half's X and HEADING (modulo a turn), a Y half's Y and how
    far the heading lies outside the turn its TURNS names."""
    x, y, heading = carried
    if half.x:
        return (abs(half.value_m - x) - slack_m,
                abs(math.remainder(half.heading_rad - heading, 2 * math.pi))
                - 0.5 * HEADING_LSB_RAD)
    outside = max(half.heading_rad - heading, heading - (half.heading_rad + 2 * math.pi), 0.0)
    return abs(half.value_m - y) - slack_m, max(outside - 0.5 * HEADING_LSB_RAD, 0.0)


def lone_halves_of(halves: PoseHalves, ix: IntArray, iy: IntArray, sent_s: FloatArray
                   ) -> list[Half]:
    """The X halves at positions ``ix`` and the Y halves at ``iy`` of ``halves`` as ``Half``s,
    X ones first (``sent_s``: every pose frame's bus time, sorted)."""
    out = []
    for x, rows, frames, named in ((True, ix, halves.px, halves.ex),
                                   (False, iy, halves.py, halves.ey)):
        for r in rows.tolist():
            t_s = float(frames["timestamp_s"][r])
            k = int(np.searchsorted(sent_s, t_s, side="left")) - 1
            heading = (float(frames["HEADING"][r]) * HEADING_LSB_RAD if x
                       else float(frames["TURNS"][r]) * 2 * math.pi)
            out.append(Half(x, t_s, int(frames["ENC_COUNTER"][r]), int(named[r]),
                            float(frames["X" if x else "Y"][r]) * POSITION_LSB_M, heading,
                            float(sent_s[k]) if k >= 0 else t_s))
    return out
