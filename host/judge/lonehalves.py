"""Lone pose halves (issue #11, rule 5): an ODOM_POSE_X (X, HEADING) or ODOM_POSE_Y (Y, TURNS)
whose partner naming the same encoder frame was lost on the bus is judged on what it carries.

Before, ``samples.onboard_samples`` paired the halves and dropped a half without a partner
unsaid: a lone X raised 10 m PASSed, "judged 316 of 316 (100 %)" (kobuki random seed 5, 8 s,
drop=0.1: 38 X frames without their Y). Each lone half is completed by the reference at the
encoder frame it names, so only its own signals are judged, one LSB each as a full pose's:
an X half's Y is the reference's (its position error is X's alone) and its TURNS the whole
turns that bring its HEADING nearest the reference's heading; a Y half's HEADING is the BAM16
that brings TURNS * 2 pi + HEADING nearest the reference's heading (0 .. 65535: the error is
how far the reference lies outside the turn TURNS names) and its X the reference's
(``posehalves``: the replay reads a lone half nearest the replayed firmware's pose alike).

A lone half is judged where the reference at its frame is told: after the reference's start,
in a segment of the reference holding a kept sample (``budgets``), not from a re-primed stall
to the first sample after it (the re-prime's frame is the samples' choice: ``reprime_window``),
its position within the samples' loss and twin allowances; the half not sent after a silence
of the firmware (a stall's first pose: ``stallfirst``'s), not aliased by a resend
(``resendalias``). Any other lone half is judged against every frame it may name
(``candidates``: it FAILs only if it fits none); one of whose candidates none can bound is
counted as sent and not judged (``judgedfloor``: the summary's judged line), never dropped
unsaid. The streamed analysis reads a log with lone
halves whole (``stream_first``: ``NotStreamable``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.judge.aheadnamed import AheadJudge, judge_ahead
from odocan.host.judge.candidates import CandidateJudge, Half, lone_halves_of
from odocan.host.judge.compare import pose_errors
from odocan.host.judge.gapseen import NOTHING, Seen
from odocan.host.judge.latehalves import NEAR_PERIODS
from odocan.host.judge.losses import Placements, loss_allowance
from odocan.host.judge.posehalves import BAM, x_half_heading_bam, y_half_heading_bam
from odocan.host.judge.reference import Geometry
from odocan.host.judge.reference_path import Reference
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    SILENCE_CYCLES,
    WIRE_COUNTER_BITS,
    Encoders,
    FloatArray,
    IntArray,
    PoseHalves,
    Poses,
)
from odocan.host.judge.twins import twin_allowance_of
from odocan.host.protocol.busfacts import POSE_PERIOD_S
from odocan.sim.robot import RobotProfile


@dataclass
class LoneVerdict:
    """The lone halves judged (their errors beyond allowance) and those left unjudged."""

    judged: int = 0
    unjudged: int = 0
    position_m: float = -math.inf  # the worst position error beyond the allowance
    heading_rad: float = -math.inf  # the worst |heading error|
    t_s: list[float] = field(default_factory=list)  # the bus times of the halves judged
    ahead: tuple[int, int] = (0, 0)  # halves naming ahead (``aheadnamed``): judged, unjudged

    def counts(self) -> dict[str, int]:
        """The report's ``samples`` entries (none when there is no lone half)."""
        out = {}
        if self.judged > self.ahead[0] or self.unjudged > self.ahead[1]:
            out = {"lone_halves_judged": self.judged - self.ahead[0],
                   "lone_halves_unjudged": self.unjudged - self.ahead[1]}
        if any(self.ahead):
            out |= {"names_ahead_judged": self.ahead[0], "names_ahead_unjudged": self.ahead[1]}
        return out

    def fold(self, vs_ref: dict[str, Any]) -> None:
        """Put the lone halves' worst errors into the report's ``onboard_vs_reference``."""
        if not self.judged:
            return
        for key, value in (("max_position_error_beyond_allowance_m", self.position_m),
                           ("max_heading_error_rad", self.heading_rad)):
            if vs_ref.get(key) is None or value > vs_ref[key]:
                vs_ref[key] = value


def lone_frames(halves: PoseHalves, paired: IntArray) -> tuple[IntArray, IntArray]:
    """Positions (in ``halves.px``, ``halves.py``) of the frames naming an encoder frame no
    sample ``paired`` (``onboard_samples``' frames, before any is left out) names."""
    ix = np.flatnonzero((halves.ex >= 0) & ~np.isin(halves.ex, paired))
    iy = np.flatnonzero((halves.ey >= 0) & ~np.isin(halves.ey, paired))
    return ix, iy


def unmatched_sent(halves: PoseHalves) -> int:
    """The poses sent that the halves naming no encoder frame stand for, whole (``judgedfloor``:
    the poses sent; counting halves / 2 said "judged 500 of 500.5" of an X renamed one frame on,
    its Y judged alone): a half whose partner (the other message's accepted frame of its COUNTER
    heard nearest it within half a COUNTER lap: one tick's, ``latehalves``) names a frame is
    that partner's pose, counted with it; two unmatched partners are one pose, a half without
    a partner heard one."""
    t_x, t_y = halves.px["timestamp_s"], halves.py["timestamp_s"]
    c_x, c_y = halves.px["COUNTER"], halves.py["COUNTER"]
    near_s = NEAR_PERIODS * POSE_PERIOD_S
    taken = np.zeros(len(t_y), dtype=bool)  # unmatched Y halves counted with their X
    sent = 0
    for i in np.flatnonzero(halves.ex < 0).tolist():
        j = _partner(t_y, c_y, float(t_x[i]), int(c_x[i]), near_s)
        sent += j is None or halves.ey[j] < 0
        if j is not None:
            taken[j] = True
    for k in np.flatnonzero((halves.ey < 0) & ~taken).tolist():
        x = _partner(t_x, c_x, float(t_y[k]), int(c_y[k]), near_s)
        sent += x is None or halves.ex[x] < 0
    return int(sent)


def _partner(times_s: FloatArray, counters: npt.NDArray[np.generic], t_s: float, counter: int,
             near_s: float) -> int | None:
    """The frame of ``counter`` heard nearest ``t_s``, within ``near_s``; None without one."""
    near = np.flatnonzero((np.abs(times_s - t_s) < near_s) & (counters == counter))
    if len(near) == 0:
        return None
    return int(near[np.argmin(np.abs(times_s[near] - t_s))])


def budgets(enc: Encoders, ref: Reference, breaks: IntArray, kept: Poses,
            named: IntArray) -> FloatArray:
    """Per encoder frame ``named``: 0 where ``ref`` there is the one the samples are judged
    against (a segment of ``reference_path.build_reference``, opened by a gap of the log or a
    stall break after its start, placed on the kept samples it holds), NaN where it cannot be
    told: a segment without a sample, or holding a new start (an unseen restart, a stall's
    re-prime), or from a re-primed stall's break to the first sample after it
    (``reprime_window``). A segment without a sample keeps the previous placement and the
    firmware may lie off it by the allowances of the openings since (``breaks.placed_offsets``),
    but under a reordering bus its frames may not be the firmware's: kobuki seed 1,
    delay=0.5:150, a lone X there 1.68 mm and 11.1 mrad off a correct firmware; so it is not
    judged (counted)."""
    e0 = ref.start
    starts = np.zeros(len(enc.seq) - e0, dtype=bool)
    starts[1:] = np.diff(enc.seq[e0:]) > 1
    inside = breaks[(breaks > e0) & (breaks < len(enc.seq))] - e0
    starts[inside] = True
    segment = np.cumsum(starts)
    n = int(segment[-1]) + 1
    sampled = np.zeros(n, dtype=bool)
    sampled[segment[kept.enc[kept.enc >= e0] - e0]] = True
    restarted = [*ref.unseen_restarts, *(e0 + k for k in ref.stall_reprimes)]
    sampled[segment[[r - e0 for r in restarted if e0 <= r < len(enc.seq)]]] = False
    out: FloatArray = np.where(sampled[segment[named - e0]], 0.0, np.nan)
    out[reprime_window(ref, kept, named)] = np.nan
    return out


def reprime_window(ref: Reference, kept: Poses, named: IntArray) -> npt.NDArray[np.bool_]:
    """Per encoder frame ``named``: whether it lies after a stall the reference re-primed
    after (``stallreprime``: its break ``b``) and before the first kept sample after it. The
    frames the firmware took last before the stall (``f``) and re-primed on (``r``) are
    chosen by the samples after, which cannot tell (f, r) from (f + 1, r + 1) where the robot
    turns evenly: the reference between ``b`` and that sample may be a few steps off the
    firmware's (issue #11: kobuki circle seed 7163, delay=0.1:150, stall=8:2, the firmware
    re-primed on seq 1001, the samples chose 1003, and its lone Y naming 1002, named right,
    lay 3.47 mm off the reference held there: a correct firmware FAILed)."""
    out = np.zeros(len(named), dtype=bool)
    for b in ref.stall_reprimes:
        lo = ref.start + b
        after = kept.enc[kept.enc >= lo]
        hi = int(after.min()) if len(after) else np.iinfo(np.int64).max
        out |= (named >= lo) & (named < hi)
    return out


def judge_lone(
    halves: PoseHalves, kept: Poses, enc: Encoders, ref: Reference,
    breaks: IntArray, pose_sent_s: FloatArray | None,
    allowed: tuple[RobotProfile, str, list[tuple[int, int, int]], Placements],
    first_rows: set[int] | None = None, seen: Seen = NOTHING,
) -> LoneVerdict:
    """Judge every lone half (module docstring) against ``ref`` (``kept``: the samples
    judged, ``breaks``: the stalls' encoder frames); ``allowed``: robot, integrator, the firmware's
    loss spans and the placements, for the samples' loss and twin allowances at its frames;
    ``first_rows``: the ODOM_POSE_X halves ``stallfirst`` judged (a stall's first pose): its;
    ``seen``: what the firmware's pages prove it took (``gapseen``), for the candidates."""
    verdict = LoneVerdict()
    paired = np.intersect1d(halves.ex[halves.ex >= 0], halves.ey[halves.ey >= 0])
    ix, iy = lone_frames(halves, paired)
    if first_rows:
        ix = ix[~np.isin(ix, sorted(first_rows))]
    sent = np.sort(np.concatenate((np.asarray(halves.px["timestamp_s"], dtype=np.float64),
                                   np.asarray(halves.py["timestamp_s"], dtype=np.float64),
                                   np.zeros(0) if pose_sent_s is None else pose_sent_s)))
    robot, integrator, losses, placed = allowed
    judged_as = (Geometry.of(robot), integrator, min(robot.counter_bits, WIRE_COUNTER_BITS))
    candidates = CandidateJudge(enc, kept, ref, judged_as, seen)
    by_ahead(verdict, judge_ahead(halves, enc, sent, AheadJudge(enc, kept, ref, judged_as)))
    if not len(ix) and not len(iy):
        return verdict
    end = ref.start + len(ref.x_m)

    def judgeable(named: IntArray, t_s: FloatArray, alias: npt.NDArray[np.bool_] | None,
                  rows: IntArray) -> npt.NDArray[np.bool_]:
        ok = (named >= ref.start) & (named < end)
        if alias is not None:
            ok &= ~alias[rows]
        if enc.cycle_s is not None:  # sent after a silence: a stall's first pose (stallfirst)
            k = np.searchsorted(sent, t_s) - 1
            quiet = np.where(k >= 0, t_s - sent[np.maximum(k, 0)], np.inf)
            ok &= quiet < (SILENCE_CYCLES - 0.5) * enc.cycle_s
        return ok

    ex, tx = halves.ex[ix], np.asarray(halves.px["timestamp_s"][ix], dtype=np.float64)
    ey, ty = halves.ey[iy], np.asarray(halves.py["timestamp_s"][iy], dtype=np.float64)
    okx, oky = judgeable(ex, tx, halves.ax, ix), judgeable(ey, ty, halves.ay, iy)
    bx = np.full(len(ex), np.nan)
    by = np.full(len(ey), np.nan)
    bx[okx] = budgets(enc, ref, breaks, kept, ex[okx])
    by[oky] = budgets(enc, ref, breaks, kept, ey[oky])
    okx &= ~np.isnan(bx)
    oky &= ~np.isnan(by)
    by_candidates(verdict, lone_halves_of(halves, ix[~okx], iy[~oky], sent), candidates)
    ix, ex, tx, iy, ey, ty = ix[okx], ex[okx], tx[okx], iy[oky], ey[oky], ty[oky]
    poses = _completed(halves, ix, ex, iy, ey, ref)
    if len(poses.enc) == 0:
        return verdict
    pos, head = pose_errors(poses, ref.at(poses.enc))
    beyond = pos - np.concatenate((bx[okx], by[oky]))
    beyond -= loss_allowance(enc, robot, integrator, losses, poses.enc, kept.enc, placed)
    beyond -= twin_allowance_of(enc, robot, integrator, ref, poses.enc, record=False)
    verdict.judged += len(poses.enc)
    verdict.position_m = max(verdict.position_m, float(np.max(beyond)))
    verdict.heading_rad = max(verdict.heading_rad, float(np.max(np.abs(head))))
    verdict.t_s += np.concatenate((tx, ty)).tolist()
    return verdict


def by_candidates(verdict: LoneVerdict, lone: list[Half], judge: CandidateJudge) -> None:
    """The halves ``lone`` the reference at their matched frame cannot judge, each judged
    against the frames it may name (``candidates``) into ``verdict``, or counted unjudged."""
    for half in lone:
        excess = judge.judge_half(half)
        if excess is None:
            verdict.unjudged += 1
            continue
        verdict.judged += 1
        verdict.position_m = max(verdict.position_m, excess[0])
        verdict.heading_rad = max(verdict.heading_rad, excess[1])
        verdict.t_s.append(half.t_s)


def by_ahead(verdict: LoneVerdict, found: tuple[list[tuple[float, float, float]], int]
             ) -> None:
    """``aheadnamed.judge_ahead``'s ``found`` (halves judged: time, position and heading
    beyond; how many unjudged) into ``verdict``, counted apart (``ahead``)."""
    judged, unjudged = found
    verdict.ahead = (len(judged), unjudged)
    verdict.judged += len(judged)
    verdict.unjudged += unjudged
    for t_s, position_m, heading_rad in judged:
        verdict.position_m = max(verdict.position_m, position_m)
        verdict.heading_rad = max(verdict.heading_rad, heading_rad)
        verdict.t_s.append(t_s)


def _completed(halves: PoseHalves, ix: IntArray, ex: IntArray, iy: IntArray, ey: IntArray,
               ref: Reference) -> Poses:
    """The lone halves at positions ``ix`` (X, naming ``ex``) and ``iy`` (Y, naming ``ey``),
    each completed by the reference at its frame (module docstring), X ones first."""
    rx, ry = ref.at(ex), ref.at(ey)
    heading_x = halves.px["HEADING"][ix].astype(np.int64)
    bam_x = x_half_heading_bam(heading_x, rx.heading_rad / HEADING_LSB_RAD)
    bam_y = y_half_heading_bam(halves.py["TURNS"][iy].astype(np.int64),
                               ry.heading_rad / HEADING_LSB_RAD)
    return Poses(
        enc=np.concatenate((ex, ey)).astype(np.int64),
        x_m=np.concatenate((halves.px["X"][ix] * POSITION_LSB_M, ry.x_m)),
        y_m=np.concatenate((rx.y_m, halves.py["Y"][iy] * POSITION_LSB_M)),
        heading_rad=np.concatenate((bam_x, bam_y)) * HEADING_LSB_RAD,
        heading_raw=np.concatenate((heading_x, bam_y.astype(np.int64) % BAM)),
    )
