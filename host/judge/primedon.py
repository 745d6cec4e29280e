"""A power-up whose prime frame the stall leaves open, judged from every frame it may have
primed on (issue #11: "a FAIL must never blame a correct firmware", and a wrong one must not
PASS unjudged).

``host.judge.stallpowerup`` proves the firmware halted at power-up before it primed, so it
primed on one of encoder frames 0 .. ``lo`` (its FIFO kept the first frames it had not read).
When the robot moved over them the frame is not known, and the whole log's rule said the start
unproven and fitted it at the first sample kept: a firmware 1 m off from its first pose PASSed
``analyze`` with only a line saying that pose not judged. Yet each of those frames gives an
exact start: pose (0, 0, 0) at frame p is, at frame 0, the inverse of the reference's motion
over frames 0 .. p (``start_pose_primed_on``; the reference is rigid-motion equivariant). The
life is judged from each (as a set-pose's exact start): a firmware that passes from one of them
is one that primed there, PASS, the frame said; one that fails from every one is off whichever
it primed on, FAIL (the least error reported)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar, cast

import numpy as np

from odocan.host.judge.reference import Geometry, integrate, wrap_delta
from odocan.host.judge.samples import WIRE_COUNTER_BITS, Encoders
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:
    from odocan.host.judge.analysis import Analysis

Pose = tuple[float, float, float]
F = TypeVar("F", bound=Callable[..., Any])
Rerun = Callable[[Pose, "int | None"], "Analysis"]  # a life judged from a start (and a cut)
COUNTED = ("frames", "e2e", "unknown_frames")  # a report's counts of the frames on the bus
PRIMED_KIND = "power_up_primed_on"  # the report's event: the frame it was judged from
FRAMES_KEY = "start_poses"  # the unproven event's candidates (frame, start pose at frame 0)
WHY_KEY = "why"  # the event's reason for its candidates (``{frames}``: theirs), if not a stall
STALL_WHY = ("the firmware stalled before its first pose after its power-up (INIT at UPTIME 0) "
             "while the robot moved over encoder frames {frames}, one of which it primed on")


def start_pose_primed_on(enc: Encoders, p: int, robot: RobotProfile, integrator: str) -> Pose:
    """The pose at encoder frame 0 from which the reference reads (0, 0, 0) at frame ``p``: the
    inverse of its motion over frames 0 .. ``p``."""
    if p == 0:
        return 0.0, 0.0, 0.0
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    moved = integrate(wrap_delta(np.diff(enc.left[: p + 1]), bits),
                      wrap_delta(np.diff(enc.right[: p + 1]), bits), Geometry.of(robot),
                      integrator)
    x_m, y_m, heading_rad = (float(moved.x_m[-1]), float(moved.y_m[-1]),
                             float(moved.heading_rad[-1]))
    cos_h, sin_h = math.cos(-heading_rad), math.sin(-heading_rad)
    return (-(cos_h * x_m - sin_h * y_m), -(sin_h * x_m + cos_h * y_m), -heading_rad)


def candidates(enc: Encoders, lo: int, robot: RobotProfile, integrator: str) -> list[list[Any]]:
    """[frame, [x m, y m, heading rad]] of each frame 0 .. ``lo`` it may have primed on (the
    unproven event's ``FRAMES_KEY``, JSON as the report is)."""
    return [[p, list(start_pose_primed_on(enc, p, robot, integrator))] for p in range(lo + 1)]


def judged_from_each(first: Analysis, rerun: Rerun) -> Analysis:
    """``first`` (fitted, its start unproven) judged again from each candidate start of its
    unproven event (``rerun``: the life from that exact start; from the candidate's position in
    the life's frames on when it has one, ``silentboot``, its frame and E2E counts then
    ``first``'s: the bus carried the frames before it all the same): the first that passes
    (the later ones not judged: a streamed life is read again per candidate), else the one with
    the least error beyond its allowance, its events saying which frame; ``first`` when it has
    no candidates."""
    event = next((e for e in first.report["events"] if FRAMES_KEY in e), None)
    if event is None:
        return first
    tries: list[tuple[int, Analysis]] = []
    for p, pose, *cut in event[FRAMES_KEY]:  # up to the first that passes: the one taken
        tries.append((p, rerun((pose[0], pose[1], pose[2]), int(cut[0]) if cut else None)))
        if cut:  # the frames the bus carried before the cut: counted as the whole life's
            tries[-1][1].report.update({k: first.report[k] for k in COUNTED if k in first.report})
        if tries[-1][1].passed:
            break
    passed = [t for t in tries if t[1].passed]
    p, best = passed[0] if passed else min(tries, key=lambda t: t[1].report[
        "onboard_vs_reference"]["max_position_error_beyond_allowance_m"])
    frames = [int(f) for f, *_ in event[FRAMES_KEY]]
    verdict = (f"it passes from frame {p}" if passed else f"it fails from frame {p}"
               if len(tries) == 1 else f"it fails from every one (the least error from frame {p})")
    best.report["reference_start"] = "power-up"
    named = f"{frames[0]}" if len(frames) == 1 else f"{min(frames)} .. {max(frames)}"
    why = str(event.get(WHY_KEY, STALL_WHY)).format(frames=named)
    best.report["events"] = [{
        "kind": PRIMED_KIND, "t_s": event["t_s"], "encoder_frame": p,
        "detail": f"{why}: judged from {'it' if len(frames) == 1 else 'each'}, {verdict}"}] + [
        e for e in best.report["events"] if e.get("kind") != PRIMED_KIND]
    return best


def each_prime(analyze_life: F) -> F:
    """``analyze_life`` (``analysis._analyze_life``) with its unproven start judged from each
    frame it may have primed on (``judged_from_each``: again with ``start_pose``, its frames
    from the candidate's position on when it has one)."""
    @functools.wraps(analyze_life)
    def judged(*args: Any, **kwargs: Any) -> Analysis:
        def rerun(pose: Pose, cut: int | None) -> Analysis:
            frames = args[0] if cut is None else args[0].select(slice(cut, None))
            return cast("Analysis", analyze_life(frames, *args[1:], **{**kwargs,
                                                                   "start_pose": pose}))
        return judged_from_each(analyze_life(*args, **kwargs), rerun)
    return cast(F, judged)
