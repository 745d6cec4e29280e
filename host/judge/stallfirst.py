"""The first sample after a stall, judged by its neighbours (issue #11, rule 5).

``stalls.after_stalls`` leaves out the first sample a firmware sent after a silence: it may
name a frame of its backlog (its FIFO kept the first frames after it halted), which ENC_COUNTER
cannot resolve, so the reference cannot place it on one frame. Left out unjudged, it let any
pose through: +10 m on that one frame PASSed every judge. It is not free, though. The frame it
names has its ENC_COUNTER and lies either in the backlog, a few frames after the last sample
before the silence (``before``), which the firmware reached from that sample by the log's own
count steps (it had not yet merged the frames it missed); or among the frames it took after it
ran again, a few frames before the next sample (``after``), which it reached from there by the
count steps. So the sample must sit within the tolerance, plus the worst merge of those few
frames (``breaks.merge_allowance_m``: its mailbox may have dropped some), of the pose carried
from one of its neighbours over the steps to one candidate frame: the heading exact (linear in
the counts), the position by the same integrator. Candidates are the frames within
``NEAR_FRAMES`` of a neighbour (the counter's cycle, longer than any receive FIFO) whose E2E
COUNTER is the one the sample named; the carried pose is its neighbours' own, which the
reference judges in turn, so a neighbour cannot vouch for a pose it does not reach.

A pose let out in a burst (``senderseq.queued_frames``: a busy bus held it back, the firmware
did not stall) is not this rule's. A left-out sample without a neighbour on either side, or with
no candidate frame, is counted
as not judged (``FirstVerdict.unjudged``), never as judged."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from odocan.host.judge.breaks import merge_allowance_m
from odocan.host.judge.losses import OneSteps
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound, wrap_delta
from odocan.host.judge.reference_path import firmware_steps
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    SILENCE_CYCLES,
    Encoders,
    FloatArray,
    IntArray,
    PoseHalves,
    Poses,
)
from odocan.host.judge.senderseq import queued_frames
from odocan.host.judge.stallnext import follow_ons
from odocan.host.judge.stallresume import FIFO_FRAMES, resume_excess

STALL_DETAIL = ("the firmware was silent or held its pose (a stall): it took the frames it "
                "missed as one step or several, so the reference's position is placed again "
                "after it, at a pose the firmware can resume at from its own before the stall "
                "(stallresume), by no more than the worst merge error there plus the tolerance "
                "(reference_breaks)")
NEAR_FRAMES = FIFO_FRAMES  # a counter cycle of ENC_COUNTER: candidates within it of a neighbour
# A neighbour vouches only from near: ``before`` the last pose sent before the silence, ``after``
# within this many encoder cycles of the pose. A kept sample further off (the poses between
# refused, e.g. reordered by a delaying bus) has an alias of the named ENC_COUNTER in every
# 16-frame window, so carrying its pose there FAILed a correct firmware (kobuki seed 2,
# delay=0.5:100,stall=2:1: 762 mm "beyond" at 3.021 s, 4 of 42 poses kept).
NEAR_CYCLES = 4


@dataclass
class FirstVerdict:
    """The poses sent first after a silence that the samples lack: how many were judged by a
    neighbour, how many could not be, and the worst excess (m, rad) beyond the tolerance (and
    allowance) of those judged (each at its best candidate)."""

    judged: int = 0
    unjudged: int = 0
    unmatched: int = 0  # of both, those ``match_encoder`` left unmatched (``unmatched_poses``)
    worst_position_m: float = -math.inf  # beyond tolerance + merge allowance (<= 0: within)
    worst_heading_rad: float = -math.inf  # beyond the heading tolerance
    worst_at_s: float | None = None  # bus time of the worst pose (ODOM_POSE_X)
    resumes: int = 0  # first samples after the silence judged by ``stallresume``
    worst_resume_m: float = -math.inf  # beyond every pose the firmware can resume at
    resume_at_s: float | None = None  # bus time of that sample (ODOM_POSE_X)
    lone_rows: set[int] = field(default_factory=set)  # X halves judged alone (lonehalves)

    def passed(self) -> bool:
        return (self.worst_position_m <= 0.0 and self.worst_heading_rad <= 0.0
                and self.worst_resume_m <= 0.0)

    def judge(self, t_s: float, excess: tuple[float, float] | None) -> None:
        """Count the pose sent at ``t_s``: not judged (``excess`` None), or judged with its
        (position m, heading rad) ``excess`` beyond the tolerance, the worst kept."""
        if excess is None:
            self.unjudged += 1
            return
        self.judged += 1
        if excess[0] > self.worst_position_m or excess[1] > self.worst_heading_rad:
            self.worst_at_s = t_s
        self.worst_position_m = max(self.worst_position_m, excess[0])
        self.worst_heading_rad = max(self.worst_heading_rad, excess[1])

    def resumed(self, t_s: float, excess_m: float | None) -> None:
        """``stallresume.resume_excess`` of the sample after a silence sent at ``t_s``."""
        if excess_m is None:
            return
        self.resumes += 1
        if excess_m > self.worst_resume_m:
            self.worst_resume_m, self.resume_at_s = excess_m, t_s

    def counts(self) -> dict[str, int]:
        """The ``samples`` counts (``judgedfloor.judged_share``)."""
        return {"stall_first_judged": self.judged, "stall_first_unjudged": self.unjudged,
                "stall_first_unmatched": self.unmatched}

    def as_dict(self) -> dict[str, object]:
        return {"judged": self.judged, "unjudged": self.unjudged,
                "max_position_beyond_m": _finite(self.worst_position_m),
                "max_heading_beyond_rad": _finite(self.worst_heading_rad),
                "worst_at_s": self.worst_at_s, "resumes": self.resumes,
                "max_resume_beyond_m": _finite(self.worst_resume_m),
                "resume_at_s": self.resume_at_s, "passed": self.passed()}


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


@dataclass(frozen=True)
class Pair:
    """One pose as sent: its ODOM_POSE_X and the ODOM_POSE_Y nearest it naming the same frame."""

    t_s: float  # ODOM_POSE_X's bus time
    named: int  # ENC_COUNTER
    enc: int  # the encoder frame ``match_encoder`` gave the X half (-1: none)
    x_m: float
    y_m: float
    heading_rad: float
    quiet_s: float = 0.0  # since the ODOM_POSE_X before it (any: paired or not)
    queued: bool = False  # its X in a burst (``senderseq.queued_frames``)
    lone: bool = False  # its ODOM_POSE_Y lost: X and HEADING alone (y_m NaN, no TURNS)


class _Pairs:
    """The poses as sent (``Pair``), made on demand by their ODOM_POSE_X's index: each X with the
    ODOM_POSE_Y nearest it in time, within an encoder cycle (``cycle_s``), that names the same
    ENC_COUNTER (an X without one is no pose: None). Few poses come after a silence, so the
    rule makes only theirs and the kept neighbours' it walks to (making all of them was 3.6 of
    the 5.4 s of CPU an hour's ``analyze`` took, on a drive without a stall)."""

    def __init__(self, halves: PoseHalves, quiet_s: FloatArray, queued: npt.NDArray[np.bool_],
                 cycle_s: float) -> None:
        self._halves = halves
        self._ty = np.asarray(halves.py["timestamp_s"], dtype=np.float64)
        self._quiet_s, self._queued, self._cycle_s = quiet_s, queued, cycle_s
        self._made: dict[int, Pair | None] = {}
        self.count = len(quiet_s)

    def at(self, k: int) -> Pair | None:
        """The pose of ODOM_POSE_X ``k``, None without its ODOM_POSE_Y."""
        if k not in self._made:
            self._made[k] = self._make(k)
        return self._made[k]

    def lone_at(self, k: int) -> Pair:
        """ODOM_POSE_X ``k`` alone (its Y lost: ``host.judge.lonehalves``)."""
        px = self._halves.px
        return Pair(float(px["timestamp_s"][k]), int(px["ENC_COUNTER"][k]),
                    int(self._halves.ex[k]), float(px["X"][k]) * POSITION_LSB_M, math.nan,
                    float(px["HEADING"][k]) * HEADING_LSB_RAD, float(self._quiet_s[k]),
                    bool(self._queued[k]), lone=True)

    def _make(self, k: int) -> Pair | None:
        px, py, ty = self._halves.px, self._halves.py, self._ty
        t, named = float(px["timestamp_s"][k]), int(px["ENC_COUNTER"][k])
        lo, hi = np.searchsorted(ty, [t - self._cycle_s, t + self._cycle_s])
        near = [m for m in range(int(lo), int(hi)) if int(py["ENC_COUNTER"][m]) == named]
        if not near:
            return None
        m = min(near, key=lambda j: abs(float(ty[j]) - t))
        return Pair(t, named, int(self._halves.ex[k]), float(px["X"][k]) * POSITION_LSB_M,
                    float(py["Y"][m]) * POSITION_LSB_M,
                    float(py["TURNS"][m]) * 2 * math.pi
                    + float(px["HEADING"][k]) * HEADING_LSB_RAD,
                    float(self._quiet_s[k]), bool(self._queued[k]))


def quiet_times(tx_s: FloatArray, pose_sent_s: FloatArray | None) -> FloatArray:
    """Per ODOM_POSE_X (bus times ``tx_s``): seconds since the X before it (0 for the first),
    or since the latest pose frame sent before it (``pose_sent_s``) if sooner."""
    quiet_s = np.zeros(len(tx_s), dtype=np.float64)
    quiet_s[1:] = tx_s[1:] - tx_s[:-1]
    if pose_sent_s is not None and len(pose_sent_s):
        k = np.searchsorted(pose_sent_s, tx_s) - 1
        since_s = np.where(k >= 0, tx_s - pose_sent_s[np.maximum(k, 0)], math.inf)
        np.minimum(quiet_s, since_s, out=quiet_s)
    return quiet_s


def judge_left_out(
    halves: PoseHalves, kept: Poses, enc: Encoders, geometry: Geometry, integrator: str,
    bits: int, tolerance: tuple[float, float], pose_sent_s: FloatArray | None = None,
    breaks: IntArray | None = None, max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED,
) -> FirstVerdict:
    """Judge every pose sent first after a silence of ``SILENCE_CYCLES`` encoder cycles or
    more (as ``stalls.silent`` reads one) that the samples ``kept`` lack: left out by
    ``after_stalls``, unmatched by ``match_encoder`` (its backlog frame's counter unresolved),
    or dropped as a second pose naming a frame (module docstring); ``tolerance``: (position m,
    heading rad). ``pose_sent_s`` (``stalls.pose_sent_times``: every CRC-right ODOM_POSE_Y,
    those the E2E check refused too) narrows the silence: under a reordering bus the poses
    refused as out of sequence were sent all the same (delay=0.5:100, kobuki seed 2: the quiet
    read from the accepted halves alone FAILed a correct firmware 163.9 mm). The first pose
    of the life is not this rule's (the reboot rules judge it). ``breaks``: the stalls' (
    ``stalls.after_stalls``), each judged by the resume rule too (``resume_across``), which
    takes the steps by the firmware's plausibility bound ``max_wheel_speed_mm_s``."""
    verdict = FirstVerdict()
    if enc.cycle_s is None or len(enc.index) < 2 or len(kept.enc) == 0:
        return verdict
    if breaks is not None:
        resume_across(verdict, kept, breaks, enc, (geometry, integrator, bits), tolerance[0],
                      max_wheel_speed_mm_s)
    tx = np.asarray(halves.px["timestamp_s"], dtype=np.float64)
    quiet_s = quiet_times(tx, pose_sent_s)
    queued = queued_frames(tx, enc.cycle_s)
    quiet = (SILENCE_CYCLES - 0.5) * enc.cycle_s
    silent = np.flatnonzero((quiet_s >= quiet) & ~queued)  # a burst's pose: held back, no stall
    if not len(silent):
        return verdict
    pairs = _Pairs(halves, quiet_s, queued, enc.cycle_s)
    first = next((k for k in range(pairs.count) if pairs.at(k) is not None), pairs.count)
    is_kept = _kept_test(kept)
    silent_set = set(silent.tolist())
    for k in silent.tolist():
        pose = pairs.at(k)
        if pose is None and k > first:  # its ODOM_POSE_Y lost: judged on what it carries
            pose = pairs.lone_at(k)
        if k <= first or pose is None or is_kept(pose):
            continue
        if not heard_through(enc, pose.t_s - pose.quiet_s, pose.t_s):
            continue  # the logger was deaf too (a gap of the log): not a stall, its own rules
        before = _kept_next(pairs, is_kept, range(k - 1, -1, -1))
        after = _kept_next(pairs, is_kept, range(k + 1, pairs.count))
        before, after = _near(pose, before, after, enc.cycle_s)
        if before is not None and after is not None and not heard_all(enc, before, after):
            continue  # a gap of the log (frames the logger missed): no stall of this rule's
        robot = (geometry, integrator, bits)
        _judge_one(verdict, pose, (before, after), enc, robot, tolerance)
        if pose.lone:  # counted here, not by lonehalves
            verdict.lone_rows.add(k)
        _judge_followers(verdict, follow_ons(pairs, is_kept, k, silent_set), (before, after),
                         enc, robot, tolerance)
    return verdict


def _judge_followers(verdict: FirstVerdict, poses: list[Pair],
                     neighbours: tuple[Pair | None, Pair | None], enc: Encoders,
                     robot: tuple[Geometry, str, int], tolerance: tuple[float, float]) -> None:
    """Judge the poses sent after a silence's first one, before the next sample
    (``stallnext.follow_ons``: the backlog's next), by the silence's ``neighbours`` (the later
    one where near each)."""
    for pose in poses:
        after = _near(pose, None, neighbours[1], enc.cycle_s or 0.0)[1]
        verdict.unmatched += pose.enc < 0
        verdict.judge(pose.t_s, _best(pose, (neighbours[0], after), enc, robot, tolerance))


def resume_across(verdict: FirstVerdict, kept: Poses, breaks: IntArray, enc: Encoders,
                  robot: tuple[Geometry, str, int], tolerance_m: float,
                  max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED) -> None:
    """``stallresume.resume_excess`` of the first kept sample after each of ``breaks`` (frames
    the reference restarts at after a stall) from the last kept before it, on the accepted
    frames between, into ``verdict`` (at the later sample's frame's bus time). Issue #11 (rule
    3): under ``delay`` and ``dup`` the host's E2E refuses the reordered frames and pairs few
    poses, so the firmware's first pose after a stall is seldom a sample and ``judge_left_out``
    never judges it (nor where the log's sequence skips); the first sample after was placed
    within the stall's merge allowance plus the gaps' (pmir, seed 2,
    ``delay=0.3:55,dup=0.1,stall=4:2``: 32 mm), absorbing a pose 10 mm off from the stall's
    end. The counts are absolute: a frame the host refused changes the fine path only between
    frames, within the rule's merge allowance at either end. The steps as the firmware's rules
    take them (``taken_steps``) are one more candidate (``stallresume`` module docstring)."""
    order = np.argsort(kept.enc, kind="stable")
    at = kept.enc[order]
    for b in breaks.tolist():
        i = int(np.searchsorted(at, b, side="left"))
        if 0 < i < len(at) and enc.cycle_s is not None:
            s0, s1 = int(order[i - 1]), int(order[i])
            span = slice(int(kept.enc[s0]), int(kept.enc[s1]) + 1)
            if _one_by_one(enc.seq[span], enc.timestamp_s[span], enc.cycle_s):
                continue  # heard one by one: judge_left_out's neighbours vouch (as before)
            verdict.resumed(float(enc.timestamp_s[kept.enc[s1]]), resume_excess(
                (float(kept.x_m[s0]), float(kept.y_m[s0]), float(kept.heading_rad[s0])),
                (float(kept.x_m[s1]), float(kept.y_m[s1])), (enc.left[span], enc.right[span]),
                robot, tolerance_m, taken_steps(enc, span, robot, max_wheel_speed_mm_s)))


def taken_steps(enc: Encoders, span: slice, robot: tuple[Geometry, str, int],
                max_wheel_speed_mm_s: SpeedBound) -> tuple[IntArray, IntArray]:
    """The count steps between the encoder frames of ``span`` (the first one taken: a sample
    names it) as the firmware's plausibility and counter-restart rules take them, the
    reference's (``reference_path.firmware_steps``) on those frames alone: a refused frame's
    step 0 and the next accepted one's from the last accepted, a re-prime's step 0."""
    part = replace(enc, index=enc.index[span], counter=enc.counter[span], seq=enc.seq[span],
                   left=enc.left[span], right=enc.right[span],
                   timestamp_s=enc.timestamp_s[span],
                   twinned=None if enc.twinned is None else enc.twinned[span], twins=None,
                   uptime=None if enc.uptime is None else enc.uptime[span], renamed=None)
    steps = firmware_steps(part, 0, robot[0], robot[2], max_wheel_speed_mm_s)
    return steps.d_left, steps.d_right


def _kept_test(kept: Poses) -> Callable[[Pair], bool]:
    """Whether a pose is one of the samples ``kept`` (its frame and position to the µm)."""
    keys = {(int(e), round(float(x), 6), round(float(y), 6))
            for e, x, y in zip(kept.enc, kept.x_m, kept.y_m, strict=True)}
    return lambda p: (p.enc, round(p.x_m, 6), round(p.y_m, 6)) in keys


def _kept_next(pairs: _Pairs, is_kept: Callable[[Pair], bool], ks: range) -> Pair | None:
    """The first pose of ``ks`` (ODOM_POSE_X indices, in that order) that is a kept sample."""
    for k in ks:
        pose = pairs.at(k)
        if pose is not None and is_kept(pose):
            return pose
    return None


def _judge_one(verdict: FirstVerdict, pose: Pair, neighbours: tuple[Pair | None, Pair | None],
               enc: Encoders, robot: tuple[Geometry, str, int], tolerance: tuple[float, float]
               ) -> None:
    """Judge ``pose`` by its ``neighbours`` (before, after) into ``verdict``; the stall's
    resume too (``stallresume``: the stall is no set-pose) where both are there."""
    before, after = neighbours
    excess = _best(pose, neighbours, enc, robot, tolerance)
    verdict.unmatched += pose.enc < 0
    if before is not None and after is not None and 0 <= before.enc < after.enc:
        span = slice(before.enc, after.enc + 1)
        verdict.resumed(after.t_s, resume_excess(
            (before.x_m, before.y_m, before.heading_rad), (after.x_m, after.y_m),
            (enc.left[span], enc.right[span]), robot, tolerance[0]))
    verdict.judge(pose.t_s, excess)


def _near(pose: Pair, before: Pair | None, after: Pair | None, cycle_s: float
          ) -> tuple[Pair | None, Pair | None]:
    """``before`` and ``after`` where they may vouch for ``pose`` (``NEAR_CYCLES``), else None."""
    slack_s = (NEAR_CYCLES + 0.25) * cycle_s  # a quarter cycle of jitter: 3.341 - 3.301 s is
    # 0.04000000000000004 s, past 4 cycles of 10 ms (kobuki seed 3, stall=3:0.3: not judged)
    if before is not None and pose.t_s - before.t_s > pose.quiet_s + slack_s:
        before = None
    if after is not None and after.t_s - pose.t_s > slack_s:
        after = None
    return before, after


def heard_all(enc: Encoders, before: Pair, after: Pair) -> bool:
    """Whether the log holds every encoder frame from ``before``'s to ``after``'s, on time (no
    sender sequence number skipped, none a cycle and a half late): the firmware was silent while
    the frames went on (a stall), not the logger (a gap of the log, its own rules)."""
    if before.enc < 0 or after.enc <= before.enc or enc.cycle_s is None:
        return False
    span = slice(before.enc, after.enc + 1)
    return _one_by_one(enc.seq[span], enc.timestamp_s[span], enc.cycle_s)


def heard_through(enc: Encoders, t0_s: float, t1_s: float) -> bool:
    """Whether the log holds the encoder frames from bus time ``t0_s`` to ``t1_s`` one by one
    (no sender sequence number skipped, none more than a cycle and a half after the one before
    or the span's ends): the firmware was silent while the logger heard on. A recorder that
    lost 6.8 s of everything (``tests/files/recorder_gap16_pmir.blf``) made a silence whose
    first pose the neighbours' rule judged across the gap: a correct firmware FAILed 274.4 mm."""
    if enc.cycle_s is None:
        return False
    lo, hi = np.searchsorted(enc.timestamp_s, [t0_s, t1_s], side="right")
    return _one_by_one(enc.seq[lo:hi], np.r_[t0_s, enc.timestamp_s[lo:hi], t1_s], enc.cycle_s)


def _one_by_one(seq: IntArray, times_s: FloatArray, cycle_s: float) -> bool:
    """No sequence number skipped in ``seq``, no step of ``times_s`` a cycle and a half long."""
    return bool(np.all(np.diff(seq) == 1) and np.all(np.diff(times_s) < 1.5 * cycle_s))


def _best(pose: Pair, neighbours: tuple[Pair | None, Pair | None], enc: Encoders,
          robot: tuple[Geometry, str, int], tolerance: tuple[float, float]
          ) -> tuple[float, float] | None:
    """The smallest (position, heading) excess of ``pose`` over its candidates (module
    docstring), None without one, or when it lies beyond and only one side had a candidate
    (``decided``)."""
    sides: list[tuple[float, float] | None] = []
    for near, forward in zip(neighbours, (True, False), strict=True):
        if near is None or near.enc < 0:
            sides.append(None)
            continue
        lo, hi = (near.enc, near.enc + NEAR_FRAMES) if forward else (
            near.enc - NEAR_FRAMES, near.enc)
        side = None
        for c in range(max(lo, 0), min(hi, len(enc.index) - 1) + 1):
            if int(enc.counter[c]) == pose.named:
                side = better(side, _excess(pose, near, c, enc, robot, tolerance))
        sides.append(side)
    return decided(sides[0], sides[1])


def excess_lsb(excess: tuple[float, float]) -> float:
    """A (position m, heading rad) excess in LSBs of the wire's pose, whichever is worse."""
    return max(excess[0] / POSITION_LSB_M, excess[1] / HEADING_LSB_RAD)


def better(a: tuple[float, float] | None, b: tuple[float, float] | None
           ) -> tuple[float, float] | None:
    """The smaller of two (position m, heading rad) excesses, weighed in the wire's LSBs
    (``excess_lsb``: 0.1 mm as 0.096 mrad). Metres against rad * 1e3 weighed the heading ~1000x:
    a frame 0.005 mm and 0.019 mrad beyond lost to one 17.8 mm beyond (pmir figure8 82,
    ``delay=0.3:55,busoff=1:1``, test_stallfirst_better)."""
    if a is None or (b is not None and excess_lsb(b) < excess_lsb(a)):
        return b
    return a


def decided(forward: tuple[float, float] | None, backward: tuple[float, float] | None
            ) -> tuple[float, float] | None:
    """The verdict of the two sides' best excesses: the better; but beyond the tolerance on
    one side alone, none (not judged). The pose names either a frame its FIFO kept at the
    silence's start, which only the pose before reaches, or one taken after it ran again,
    which only the next reaches; an alias of the other side's counter is no evidence. Two
    close stalls (pmir seed 7, ``stall=7:0.5,stall=7.52:0.5``: no kept pose near before the
    second) made the next pose, carried back to an alias, FAIL a correct firmware 75.9 mm /
    1106 mrad (test_replay_halt_pairs)."""
    best = better(forward, backward)
    if best is not None and max(best) > 0 and (forward is None or backward is None):
        return None
    return best


def _excess(pose: Pair, near: Pair, c: int, enc: Encoders, robot: tuple[Geometry, str, int],
            tolerance: tuple[float, float]) -> tuple[float, float]:
    """``carried_excess`` of ``pose`` from neighbour ``near`` to frame ``c`` of ``enc``."""
    a, b = min(near.enc, c), max(near.enc, c)
    return carried_excess(pose, near, (enc.left[a:b + 1], enc.right[a:b + 1]), c > near.enc,
                          robot, tolerance)


def carried_excess(pose: Pair, near: Pair, counts: tuple[np.ndarray, np.ndarray],
                   forward: bool, robot: tuple[Geometry, str, int],
                   tolerance: tuple[float, float]) -> tuple[float, float]:
    """How far ``pose`` lies beyond the pose of neighbour ``near`` carried over the count steps
    to a candidate frame (position beyond tolerance + merge allowance, heading beyond
    tolerance): ``counts`` the wire counts (left, right) of the frames from the earlier of the
    two to the later, ``forward``: the candidate is the later (``robot``: geometry,
    integrator, wire counter bits)."""
    x, y, heading, slack_m = carried_pose(near, counts, forward, robot)
    if pose.lone:  # X and HEADING alone: Y and TURNS not sent
        return (abs(pose.x_m - x) - tolerance[0] - slack_m, abs(math.remainder(
            pose.heading_rad - heading, 2 * math.pi)) - tolerance[1] - 0.5 * HEADING_LSB_RAD)
    return (math.hypot(pose.x_m - x, pose.y_m - y) - tolerance[0] - slack_m,
            abs(pose.heading_rad - heading) - tolerance[1] - 0.5 * HEADING_LSB_RAD)


def carried_pose(near: Pair, counts: tuple[np.ndarray, np.ndarray], forward: bool,
                 robot: tuple[Geometry, str, int]) -> tuple[float, float, float, float]:
    """The pose (x m, y m, heading rad) of neighbour ``near`` carried over the count steps
    ``counts`` (``carried_excess``'s) and the position slack (m) it holds: the worst merge of
    the frames between and the neighbour's own rounding."""
    geometry, integrator, bits = robot
    left, right = (np.asarray(v, dtype=np.int64) for v in counts)
    steps = OneSteps.of_deltas(wrap_delta(np.diff(left), bits), wrap_delta(np.diff(right), bits),
                               geometry, integrator)
    sign = 1.0 if forward else -1.0  # carried from the first frame to the last, or back
    e = 0 if forward else len(left) - 1
    turn = near.heading_rad - float(steps.heading[e])  # the firmware's heading frame
    dx, dy = sign * float(steps.cum_x[-1]), sign * float(steps.cum_y[-1])
    x = near.x_m + dx * math.cos(turn) - dy * math.sin(turn)
    y = near.y_m + dx * math.sin(turn) + dy * math.cos(turn)
    heading = float(steps.heading[len(left) - 1 - e]) + turn
    allowed = merge_allowance_m(left, right, geometry, bits, integrator)
    # the neighbour is rounded to the wire's LSBs too (the tolerance covers the pose's own):
    # its rounding box and its heading's half LSB over the carried way (kobuki, a 1 s stall:
    # a correct firmware FAILed 0.00097 mm beyond without them)
    rounding_m = math.sqrt(2) * 0.5 * POSITION_LSB_M + 0.5 * HEADING_LSB_RAD * math.hypot(dx, dy)
    return x, y, heading, allowed + rounding_m


def merged_first(parts: list[dict[str, object] | None]) -> dict[str, object]:
    """One ``FirstVerdict.as_dict`` of several lives' (``reboots.merge``): counts summed, the
    worst life's excess (a failed one first)."""
    given = [p for p in parts if p]
    if not given:
        return FirstVerdict().as_dict()
    worst = max(given, key=lambda p: (not p["passed"], p["max_position_beyond_m"] is not None))
    out = dict(worst)
    for key in ("judged", "unjudged", "resumes"):
        out[key] = sum(int(p.get(key) or 0) for p in given)  # type: ignore[call-overload]
    return out
