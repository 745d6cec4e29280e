"""What an applied set-pose keeps (issue #11): the fields not staged in the firmware's life.

The firmware's APPLY (firmware/commands.py ``_pose_with``, ecu.c alike) overwrites its pose with
the fields staged since its start and keeps its own values of the others; a bare APPLY keeps
X, Y and HEADING (only TURNS start again: the heading is then within [0, 2 pi)). A reboot
empties the staging (its RAM), so a bare APPLY after a reboot must leave the pose where it was.

``analyze`` judges the life after an APPLY that set fewer than all three fields from a fitted
start (``host.judge.setposes``), which follows any pose the firmware jumped to: a wrong
firmware that kept its staging across a reboot and applied it on a bare APPLY after it
PASSed. So each such APPLY is checked here, on the bus alone: the first on-board sample after
it (naming an encoder frame after the one the APPLY took effect after, C) must be the last one
before it (naming a frame before C) moved by the reference's steps between them
(``reference.integrate``), with the staged fields set at C. The difference is bounded by the
two samples' rounding (under one LSB per axis and of heading, the wire's) and the start
heading's rounding over the path between them (one heading LSB times its length); beyond,
the firmware set what it had not been given: ``passed`` False, a FAIL named in the set-pose
event (``mark_kept``). An APPLY so soon after a reboot that the new firmware sent fewer than
two poses before it is judged from the firmware's power-up pose instead ((0, 0, 0) at the first
encoder frame of its life, ``analyze``'s own rule for a reboot's life: ``powerup``), when the
window starts at that life's first frame. So is one after a rebooted firmware that stalled
before its first pose (``stalls.primed_first``, ``analyze``'s rule there too: its first count
page misses the frames its FIFO overran, so ``powerup`` cannot prove it; the life before the
APPLY, one pose or none, read whole up to ``HEAD_FRAMES``, ``_primed_up``): the firmware primed
on the life's first frame and took the frames it missed in merged runs the log cannot name, so
its position at the first pose after the APPLY (not the first after the stall: it may name a
backlog frame) is bounded by that pose's rounding plus the merge allowance of every frame from
the primed one (``stallmerge.merged_allowance_m``: the worst grouping into runs, each run's
heading exact), as the lone sample before it is placed by ``analyze``; before, not judged, and
a firmware that moved its X by 1 m at such an APPLY PASSed (4.1 mm allowed after a 3 s stall
on pmir's circle, the correct firmware 1.26 mm off the fine steps). Not when a summary says a
step was left out (``_refusal_said``: a re-prime is no merged step; ``reprimekept`` bounds it).

Two samples alone allow a jump of up to two roundings (a firmware moving X by 1.2 LSB at a bare
APPLY passed, where the live judges, which carry the reference across it, said POSE WRONG). So
a check the two pass is narrowed by up to ``NARROW_SAMPLES`` samples on each side (``_overlap``):
each, moved rigidly to C by the reference's motion, allows the pose at C within its rounding
(half an LSB each way, its heading's half LSB over the motion); the intersections of each side
must agree in every field kept (a staged one: inside the after side's). Samples at varied
sub-LSB phases narrow each side well below one LSB, as the start fits do. From the power-up
pose that side is exact: the after sample's one rounding is the bound (half an LSB each way,
nothing over the path), and up to ``NARROW_SAMPLES`` samples after the APPLY narrow it
(``_from_power_up``: the exact pose at C must be within each one's interval): a 1.2-LSB jump
1 or 2 ticks after a reboot PASSed before (two roundings allowed, not narrowed).

Not judged (``kept_check`` says why, in words: the event's ``kept_not_judged``): two samples
around C within ``WINDOW_FRAMES`` of it in the firmware's life are not there, or the steps
between them are not the plain ones (a gap of the encoder sequence of more than one frame, or
at a set-pose that staged a field, a refused or re-primed step, a twin), or the firmware is not
seen stepping plainly on each side (the sample before the last one before C, and the one after
the first after C, must continue them by the plain steps between, nothing staged: after a stall
the first poses name backlog frames the window cannot resolve, and merged steps leave the fine
reference): the fitted start alone judges that life then. A stall (the firmware silent
``SILENCE_CYCLES`` encoder cycles: it takes the frames it missed merged) further off than the
samples around C only bounds the samples that narrow the check (``_voiced``: those after it,
less the first): an APPLY a few poses after a stall is judged from the poses after it. When
the last sample before C is the first after the stall and names the latest encoder frame heard
before it (``_caught_up``: the firmware took every frame it missed, merged, and names no
backlog frame), the firmware and the reference agree again there: the check starts from it
(the side before C is that one sample). With no sample between the stall and C (before, not
judged) it is judged from the two samples around C when every frame between them was heard,
the bound widened by how far merged runs of them leave the fine steps (``_across_stall``).
A gap of one frame (the recorder lost a frame the firmware took, or the firmware took two
periods merged) between the samples around a bare APPLY, or between two samples on a side,
is judged across: the reference takes its merged step, and the bound is widened by how far the
firmware's position can lie from it (``gapbound.gap_allowance_m``, ``_gap_m``: a few mm for
pmir; the heading after it is exact): a firmware that applied a staging it had lost jumps far
beyond (before, skipped, and its fitted life PASSed a 1.1 m jump).
The window is read alike from a whole log and from a streamed one (its frames only), so
``analyze`` and ``analyze_file`` give the same check bit for bit."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from odocan.firmware.errors import ErrorFlag
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapbound import gap_allowance_m, period_bounds
from odocan.host.judge.keptjump import FLOAT_M, FLOAT_RAD, TURN_RAD, jump_judged
from odocan.host.judge.livesetpose import FIELDS
from odocan.host.judge.nearthreshold import ResetLog
from odocan.host.judge.powerup import life_powered_up
from odocan.host.judge.reference import Geometry, SpeedBound, integrate
from odocan.host.judge.reference_path import firmware_steps
from odocan.host.judge.reprimekept import reprime_kept, summaries_of
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    SILENCE_CYCLES,
    WIRE_COUNTER_BITS,
    AnalysisError,
    Encoders,
    FloatArray,
    Poses,
    accepted_rows,
    encoder_frames,
    onboard_samples,
)
from odocan.host.judge.stallmerge import merged_allowance_m, silent_inside
from odocan.host.judge.stalls import alive_times, primed_first
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:
    from odocan.host.judge.setposes import SetPoseCut
    from odocan.host.protocol.dbcplan import DatabaseSpec

REFUSED_BITS = int(ErrorFlag.IMPLAUSIBLE_STEP | ErrorFlag.COUNTER_RESET)  # steps left out
WINDOW_FRAMES = 512  # log frames read on each side of the APPLY's encoder frame
NARROW_SAMPLES = 16  # samples on each side whose rounding intervals narrow the check
HEAD_FRAMES = 64 * WINDOW_FRAMES  # a reboot's life before the APPLY read whole up to this long
Kept = dict[str, Any] | str | None  # the check, why it was not made, or None: all staged
NO_START = ("fewer than two on-board poses before the APPLY in this firmware life, and its "
            "power-up pose not known")


class Odo(NamedTuple):
    """How the firmware steps: its geometry, counter width on the wire (bits), integrator and
    step bound (``reference_path.firmware_steps``)."""

    geometry: Geometry
    bits: int
    integrator: str
    max_wheel_speed_mm_s: SpeedBound


def window(position: int, head_start: int, tail_stop: int) -> tuple[int, int]:
    """The log positions [lo, hi) read for the cut at ``position``: ``WINDOW_FRAMES`` each side,
    within the life before it (from ``head_start``) and the life it opens (to ``tail_stop``)."""
    return max(head_start, position - WINDOW_FRAMES), min(tail_stop, position + WINDOW_FRAMES)


def check_cut(read: Callable[[int, int], FrameArrays], head: tuple[int, bool], tail_stop: int,
              cut: SetPoseCut, robot: RobotProfile, integrator: str, db: DatabaseSpec,
              max_wheel_speed_mm_s: SpeedBound) -> Kept:
    """``kept_check`` of the set-pose ``cut`` over its ``window``: ``read(lo, hi)``, the log's
    frames [lo, hi) (whole or streamed alike); ``head``: the first frame of the life before the
    cut, whether it starts at a reboot; ``tail_stop``: the end of the life the cut opens."""
    lo, hi = window(cut.position, head[0], tail_stop)
    kept = kept_check(read(lo, hi), lo, cut, robot, integrator, db, max_wheel_speed_mm_s,
                      boot=(head[1] or head[0] == 0) and lo == head[0], log_start=lo == 0)
    if isinstance(kept, str) and head[1] and head[0] < lo <= head[0] + HEAD_FRAMES:
        whole = kept_check(read(head[0], hi), head[0], cut, robot, integrator, db,
                           max_wheel_speed_mm_s, boot=True)  # a reboot's life read whole
        if kept == NO_START or (isinstance(whole, dict) and whole.get("reprimed")):
            return whole
    return kept


def kept_check(frames: FrameArrays, lo: int, cut: SetPoseCut, robot: RobotProfile,
               integrator: str, db: DatabaseSpec, max_wheel_speed_mm_s: SpeedBound, *,
               boot: bool = False, log_start: bool = False) -> Kept:
    """The check of the module docstring for ``cut`` (a set-pose whose fields were not all
    staged) over ``frames``, the log's frames from position ``lo`` (``window``); None when
    every field was staged, why not (words) when the check cannot be made. ``boot``:
    ``frames`` start where the firmware may have started (a life read from its first frame;
    ``log_start``: the log's, ``powerup.life_powered_up``)."""
    if cut.start_pose() is not None:
        return None
    decoder = BulkDecoder(db)
    _, accepted = check_frames(frames, db)
    enc = encoder_frames(frames, accepted, decoder)
    at = np.flatnonzero(enc.index == cut.position - lo)
    if len(at) == 0:
        return "the encoder frame the APPLY took effect after is not among the frames read"
    try:
        poses, _, sent_s = onboard_samples(frames, accepted, decoder, enc)
    except AnalysisError:
        return "no on-board poses around the APPLY"
    odo = Odo(Geometry.of(robot), min(robot.counter_bits, WIRE_COUNTER_BITS), integrator,
              max_wheel_speed_mm_s)
    alive_s = alive_times(frames, accepted, decoder) if boot and not log_start else sent_s[:0]
    stalled = len(alive_s) > 0 and primed_first(float(np.min(sent_s)), enc, alive_s,
                                                      accepted_rows(frames, accepted, decoder,
                                                                    "ODOM_POSE_Y")["timestamp_s"])
    refused = stalled and _refusal_said(frames, accepted, decoder)
    kept = judge_kept((poses, enc, sent_s), int(at[0]), cut.staged, odo,
                      lambda: boot and not refused and life_powered_up(  # (a re-prime's:
                          frames, accepted, decoder, poses, log_start=log_start),  # no power-up)
                      primed=lambda: stalled and not refused)
    after = _around(poses, int(at[0]))[1]
    if isinstance(kept, str) and refused and after is not None:  # re-primed: reprimekept
        bounded = reprime_kept((poses, enc, sent_s), alive_s, int(at[0]), after, cut.staged,
                               odo, summaries_of(frames, accepted, decoder))
        return bounded if kept == NO_START or isinstance(bounded, dict) else kept
    return kept


def _refusal_said(frames: FrameArrays, accepted: np.ndarray, decoder: BulkDecoder) -> bool:
    """Whether a summary of ``frames`` says the firmware left a step out (IMPLAUSIBLE_STEP or
    COUNTER_RESET in ERROR_MASK, or it cannot tell): past ~3.7 s a stalled pmir re-primes on
    the frame it takes on resuming (``stallreprime``), the stall's motion not in its pose by
    design, beyond ``_primed_up``'s merged steps (the correct firmware FAILed at 1.55 m)."""
    log = ResetLog()
    log.feed(frames, decoder, np.flatnonzero(accepted))
    return not log.usable or any(bool(np.any(m & REFUSED_BITS)) for m in log.mask)


def judge_kept(seen: tuple[Poses, Encoders, FloatArray], c: int, staged: dict[str, float],
               odo: Odo, power_up: Callable[[], bool] = lambda: False, *,
               primed: Callable[[], bool] = lambda: False) -> Kept:
    """``kept_check``'s rule on the samples and encoder frames ``seen`` (poses, frames, each
    sample's ODOM_POSE_Y bus time s), from a log or heard live (``host.judge.livekept``): the
    APPLY took effect after encoder frame ``c`` (an index into the frames) with ``staged``;
    ``power_up()``: the frames start at the firmware's power-up (its pose (0, 0, 0) there);
    ``primed()``: they start at a reboot and the firmware stalled before its first pose, primed
    on their first frame (``stalls.primed_first``), its steps to its first poses merged."""
    poses, enc, sent_s = seen
    before, after = _around(poses, c)
    voiced = _voiced(sent_s, enc.cycle_s, before, after)
    caught = voiced is None and _caught_up(seen, before, after)
    if caught and before is not None:  # the firmware caught up at ``before``: the start
        later = _voiced(sent_s, enc.cycle_s, before + 1, after)
        voiced = None if later is None else (before, later[1])
    start = _sample(poses, before) if before is not None else None
    if before is None and power_up():
        start = (0, (0.0, 0.0, 0.0))  # applied before two poses: from its power-up pose
    elif before is None and after is not None and primed():
        return _primed_up(seen, c, after, staged, odo)
    if start is None:
        return NO_START
    if after is None:
        return "fewer than two on-board poses after the APPLY"
    if voiced is None:
        return _across_stall(seen, c, (before, after), start, staged, odo)
    return _checked(poses, enc, c, (before, after), start, staged, odo, voiced,
                    caught=caught)


def _checked(poses: Poses, enc: Encoders, c: int, around: tuple[int | None, int],
             start: tuple[int, tuple[float, float, float]], staged: dict[str, float],
             odo: Odo, voiced: tuple[int, int], *, caught: bool = False) -> Kept:
    """``kept_check`` from ``start`` (the last sample before the APPLY's frame ``c``, or the
    power-up pose when ``around``'s first is None) to the first sample after it; narrowed by
    the samples ``voiced`` (first, last) alone."""
    before, after = around
    sides = ([] if before is None or caught else [before - 1]) + [after]
    if not all(_settled(poses, i, enc, odo) for i in sides):
        return ("the firmware not seen stepping plainly around the APPLY (after a stall: poses "
                "naming backlog frames, merged steps)")
    steps = _plain_steps(enc, start[0], int(poses.enc[after]), odo, one_gap=not staged)
    if steps is None:
        return ("the encoder frames between the poses around the APPLY are not plain steps (a "
                "gap in their sequence, a refused, re-primed or twinned step)")
    judged = jump_judged(start, _sample(poses, after), steps, c - start[0], staged, odo.geometry,
                     odo.integrator, exact_start=before is None,
                     gap_m=_gap_m(enc, (start[0], int(poses.enc[after])), steps, odo))
    if judged["passed"] and before is not None:  # narrowed by more samples on each side
        judged["passed"] = _overlap(poses, (before, after), c, enc, staged, odo, voiced)
    elif judged["passed"]:  # from the power-up pose: narrowed by more samples after the APPLY
        judged["passed"] = _from_power_up(poses, after, c, enc, staged, odo, voiced[1])
    return {"fields_kept": [name for name in FIELDS if name not in staged], **judged}


def _primed_up(seen: tuple[Poses, Encoders, FloatArray], c: int, after: int,
               staged: dict[str, float], odo: Odo) -> Kept:
    """``kept_check`` from the power-up pose of a firmware that stalled before its first pose
    (``judge_kept``'s ``primed``), as ``_across_stall`` from it: the position within the merge
    allowance of the steps from the frame it primed on (it took them merged, which ones the log
    cannot say; its heading exact). Not from its first pose sent (it may name a backlog frame)."""
    if after == int(np.argmin(seen[2])):
        return "the first pose after the APPLY the first after a stall before it"
    return _across_stall(seen, c, (None, after), (0, (0.0, 0.0, 0.0)), staged, odo)


def _across_stall(seen: tuple[Poses, Encoders, FloatArray], c: int,
                  around: tuple[int | None, int], start: tuple[int, tuple[float, float, float]],
                  staged: dict[str, float], odo: Odo) -> Kept:
    """``kept_check`` across a stall between the samples ``around`` the APPLY's frame ``c``
    (before: None, ``start`` the power-up pose), every frame between them heard, the bound
    widened by ``stallmerge.merged_allowance_m``; not narrowed (steps across a stall are not the
    fine ones). Not made when a field was staged (the merged run it fell in is not known) or a
    sample around ``c`` may name a backlog frame (``stallmerge.silent_inside``, ``_settled``)."""
    poses, enc, sent_s = seen
    before, after = around
    why = "the firmware silent (a stall) between the poses around the APPLY"
    if staged or not silent_inside(sent_s, enc.cycle_s, before, after):
        return f"{why}, and a field staged or a pose around it the first after the stall"
    if not all(_settled(poses, i, enc, odo) for i in {after, before - 1 if before else after}):
        return ("the firmware not seen stepping plainly around the APPLY (after a stall: poses "
                "naming backlog frames, merged steps)")
    steps = _plain_steps(enc, start[0], int(poses.enc[after]), odo)
    if steps is None:
        return f"{why}, and the encoder frames across it not all heard as plain steps"
    judged = jump_judged(start, _sample(poses, after), steps, c - start[0], staged, odo.geometry,
                     odo.integrator, exact_start=before is None,
                     gap_m=merged_allowance_m(*steps, odo.geometry, odo.integrator))
    return {"fields_kept": list(FIELDS), **judged}


def _overlap(poses: Poses, around: tuple[int, int], c: int, enc: Encoders,
             staged: dict[str, float], odo: Odo, voiced: tuple[int, int]) -> bool:
    """Whether the pose at the APPLY's frame ``c`` that up to ``NARROW_SAMPLES`` samples on
    each side allow (each sample moved to ``c`` by the reference's steps: an interval of its
    rounding, half an LSB each way, widened by its heading's rounding over the motion)
    agrees between the sides for every field not staged (the staged ones: within the after
    side's), of the samples ``voiced`` (first, last) alone. True (nothing more to say) when
    those samples do not step plainly."""
    before, after = around
    first = max(voiced[0], before - NARROW_SAMPLES + 1)
    last = min(voiced[1], after + NARROW_SAMPLES - 1)
    steps = _plain_steps(enc, int(poses.enc[first]), int(poses.enc[last]), odo)
    if steps is None:
        return True
    rel = _relative(steps, odo)
    base = int(poses.enc[first])
    sides = [_at_cut(poses, range(first, before + 1), c - base, base, rel),
             _at_cut(poses, range(after, last + 1), c - base, base, rel)]
    if any(side is None for side in sides):
        return True  # a side's samples disagree among themselves: not judged here
    lows, highs = sides[0], sides[1]
    assert lows is not None and highs is not None
    return _agree(lows, highs, staged)


def _from_power_up(poses: Poses, after: int, c: int, enc: Encoders, staged: dict[str, float],
                   odo: Odo, voiced_last: int) -> bool:
    """``_overlap`` for an APPLY judged from the power-up pose (before the new firmware's
    second pose): the pose at the APPLY's frame ``c`` is then known exactly (the reference
    from (0, 0, 0) at the life's first encoder frame), a point that the intervals of up to
    ``NARROW_SAMPLES`` samples after it must hold in every field kept (a wrong jump of 1.2 LSB
    passed the one sample's rounding). True when those samples do not step plainly or
    disagree among themselves. Up to ``voiced_last`` (before a later stall)."""
    last = min(voiced_last, after + NARROW_SAMPLES - 1)
    steps = _plain_steps(enc, 0, int(poses.enc[last]), odo)
    if steps is None:
        return True
    rel = _relative(steps, odo)
    highs = _at_cut(poses, range(after, last + 1), c, 0, rel)
    if highs is None:
        return True
    return _agree([(float(v[c]), float(v[c])) for v in rel], highs, staged)


def _relative(steps: tuple[np.ndarray, np.ndarray],
              odo: Odo) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The reference's pose (x m, y m, heading rad) at each frame of ``steps`` (element k:
    after k steps) from (0, 0, 0) at their first."""
    rel = integrate(*steps, odo.geometry, odo.integrator)
    rel_x, rel_y, rel_h = (np.concatenate(([0.0], v)) for v in (rel.x_m, rel.y_m,
                                                                rel.heading_rad))
    return rel_x, rel_y, rel_h


def _agree(lows: list[tuple[float, float]], highs: list[tuple[float, float]],
           staged: dict[str, float]) -> bool:
    """Whether the pose at the APPLY the samples before it allow (``lows``: an interval per
    field) meets the one those after it allow (``highs``) in every field kept, and each staged
    field is within ``highs``."""
    for k, name in enumerate(FIELDS):
        lo_b, hi_b = lows[k]
        lo_a, hi_a = highs[k]
        if name in staged:
            value = staged[name]
            if k == 2:
                value = lo_a + (value - lo_a) % TURN_RAD
            if not lo_a - FLOAT_M <= value <= hi_a + FLOAT_M:
                return False
        elif k == 2:
            shift = round((lo_a - lo_b) / TURN_RAD) * TURN_RAD
            if lo_a - shift > hi_b + FLOAT_RAD or lo_b > hi_a - shift + FLOAT_RAD:
                return False
        elif lo_a > hi_b + FLOAT_M or lo_b > hi_a + FLOAT_M:
            return False
    return True


def _at_cut(poses: Poses, samples: range, c: int, base: int,
            rel: tuple[FloatArray, FloatArray, FloatArray]) -> list[tuple[float, float]] | None:
    """The intervals (x, y, heading) of the pose at frame ``c`` (from ``base``) that every one
    of ``samples`` allows, moved there rigidly by the reference's motion ``rel`` (from
    ``base``); None when they do not overlap."""
    rel_x, rel_y, rel_h = rel
    bounds = [(-math.inf, math.inf)] * 3
    h_first: float | None = None
    for i in samples:
        k = int(poses.enc[i]) - base
        dx, dy = rel_x[k] - rel_x[c], rel_y[k] - rel_y[c]
        cos_c, sin_c = math.cos(rel_h[c]), math.sin(rel_h[c])
        mx, my = cos_c * dx + sin_c * dy, -sin_c * dx + cos_c * dy  # in the frame at c
        h_c = float(poses.heading_rad[i]) - (rel_h[k] - rel_h[c])
        h_first = h_c if h_first is None else h_first
        h_c = h_first + (h_c - h_first + math.pi) % TURN_RAD - math.pi
        x_c = float(poses.x_m[i]) - (math.cos(h_c) * mx - math.sin(h_c) * my)
        y_c = float(poses.y_m[i]) - (math.sin(h_c) * mx + math.cos(h_c) * my)
        widen = 0.5 * HEADING_LSB_RAD * math.hypot(mx, my) + FLOAT_M
        half = [0.5 * POSITION_LSB_M + widen] * 2 + [0.5 * HEADING_LSB_RAD + FLOAT_RAD]
        bounds = [(max(lo, v - w), min(hi, v + w))
                  for (lo, hi), v, w in zip(bounds, (x_c, y_c, h_c), half, strict=True)]
    if any(lo > hi for lo, hi in bounds):
        return None
    return bounds


def _sample(poses: Poses, i: int) -> tuple[int, tuple[float, float, float]]:
    """Sample ``i``: its encoder frame and its pose (x m, y m, heading rad)."""
    return int(poses.enc[i]), (float(poses.x_m[i]), float(poses.y_m[i]),
                               float(poses.heading_rad[i]))


def _settled(poses: Poses, i: int, enc: Encoders, odo: Odo) -> bool:
    """Whether sample ``i + 1`` is sample ``i`` moved by the plain steps between them (a pose
    resolved to the wrong encoder frame after a silence, or a firmware taking merged steps
    after a stall, is not: the samples there cannot pin a jump)."""
    b, a = int(poses.enc[i]), int(poses.enc[i + 1])
    steps = _plain_steps(enc, b, a, odo, one_gap=True)
    return steps is not None and bool(jump_judged(
        _sample(poses, i), _sample(poses, i + 1), steps, 0, {}, odo.geometry,
        odo.integrator, gap_m=_gap_m(enc, (b, a), steps, odo))["passed"])


def _voiced(sent_s: FloatArray, cycle_s: float | None, before: int | None,
            after: int | None) -> tuple[int, int] | None:
    """The samples (first, last) around the APPLY sent without a silence of the firmware
    between them (``SILENCE_CYCLES`` encoder cycles, ``cycle_s``, or more between two samples
    on the bus, analyze's own rule: a stall, after which it took the frames it missed in merged
    steps), less the first after a silence (it may name a backlog frame); None when there is
    one between the sample before ``before`` and the one after ``after`` (or from the life's
    first sample, when ``before`` is None). All of them when the DBC gives no cycle time."""
    last = len(sent_s) - 1
    if cycle_s is None or after is None:
        return 0, last
    gaps = np.flatnonzero(np.diff(sent_s) >= SILENCE_CYCLES * cycle_s)
    low = 0 if before is None else before - 1
    if np.any((gaps >= low) & (gaps <= after)):
        return None
    earlier, later = gaps[gaps < low], gaps[gaps > after]
    return (int(earlier[-1]) + 2 if len(earlier) else 0,
            int(later[0]) if len(later) else last)


def _caught_up(seen: tuple[Poses, Encoders, FloatArray], before: int | None,
               after: int | None) -> bool:
    """Whether the last sample ``before`` the APPLY is the first after a stall (the only
    silence between it and the sample ``after``'s successor) and names the latest encoder
    frame heard before its ODOM_POSE_Y: the firmware had taken every frame it missed (merged:
    no backlog frame named), its pose there is where the reference and it agree again, and
    plain steps follow. (An APPLY 2-3 ticks after a stall was left unjudged.)"""
    poses, enc, sent_s = seen
    if before is None or after is None or enc.cycle_s is None:
        return False
    silent = np.flatnonzero(np.diff(sent_s) >= SILENCE_CYCLES * enc.cycle_s)
    if [int(g) for g in silent if before - 1 <= g <= after] != [before - 1]:
        return False
    named = int(poses.enc[before])
    return not bool(np.any(enc.timestamp_s[named + 1:] <= sent_s[before]))


def _around(poses: Poses, c: int) -> tuple[int | None, int | None]:
    """The last sample naming an encoder frame before ``c`` and the first naming one after,
    each with another sample beyond it (before the first, after the second)."""
    before = np.flatnonzero(poses.enc < c)
    after = np.flatnonzero(poses.enc > c)
    return (int(before[-1]) if len(before) > 1 else None,
            int(after[0]) if len(after) > 1 else None)


def _plain_steps(enc: Encoders, b: int, a: int, odo: Odo, *,
                 one_gap: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
    """The count steps from encoder frame ``b`` to ``a`` (element k: into ``b + k + 1``) when
    they are the plain ones: consecutive frames, none refused or re-primed, no twin.
    ``one_gap``: one gap of a single frame allowed (a merged step, ``_gap_m``)."""
    periods = np.diff(enc.seq[b:a + 1])
    gaps = periods[periods != 1]
    if len(gaps) > int(one_gap) or np.any(gaps != 2):
        return None
    if enc.twinned is not None and bool(np.any(enc.twinned[b:a + 1])):
        return None
    part = slice(b, a + 1)
    sub = Encoders(index=enc.index[part], counter=enc.counter[part], seq=enc.seq[part],
                   left=enc.left[part], right=enc.right[part],
                   timestamp_s=enc.timestamp_s[part], cycle_s=enc.cycle_s,
                   uptime=None if enc.uptime is None else enc.uptime[part])
    steps = firmware_steps(sub, 0, odo.geometry, odo.bits, odo.max_wheel_speed_mm_s)
    if steps.refused or steps.reprimed or len(steps.d_left) != a - b:
        return None
    return steps.d_left, steps.d_right


def _gap_m(enc: Encoders, frames: tuple[int, int], steps: tuple[np.ndarray, np.ndarray],
           odo: Odo) -> float:
    """How far (m) the firmware's position can lie from the reference's after ``steps`` (from
    encoder frame ``frames[0]`` to ``frames[1]``): 0 when plain; across a gap of one frame (the
    recorder lost a frame the firmware took, or the firmware took the two periods merged) the
    merged step's bound, ``gapbound.gap_allowance_m`` (the heading after it is exact: the
    counts' total is known)."""
    periods = np.diff(enc.seq[frames[0]:frames[1] + 1])
    at = np.flatnonzero(periods != 1)
    if len(at) == 0:
        return 0.0
    k = int(at[0])
    bounds = period_bounds(odo.geometry, odo.geometry.speed_bound_mm_s(odo.max_wheel_speed_mm_s))
    return gap_allowance_m(int(steps[0][k]), int(steps[1][k]), int(periods[k]), odo.geometry,
                           odo.integrator, bounds)

