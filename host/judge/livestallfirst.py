"""``stallfirst`` for the live judge (``odocan monitor``): the pose sent first after a silence,
judged by the poses around it as it comes (issue #11: +10 m on the first pose after a stall left
the monitor OK, its tracker leaving that sample out or never matching it).

Fed every encoder frame and pose half the monitor takes (CRC right, in bus order). A pose (its
ODOM_POSE_X and the ODOM_POSE_Y after it naming the same ENC_COUNTER) sent ``SILENCE_CYCLES``
encoder cycles or more after the pose before it waits for its neighbours: the pose before
(matched to the latest frame with its ENC_COUNTER at its time), with the frames after it (at most
``stallfirst.NEAR_FRAMES``), and the next pose not itself after a silence, with the frames
before it. ``stallfirst.carried_excess`` from either to each candidate frame; the best one
decides. A pose without a neighbour that names a frame of the window is counted unjudged."""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from odocan.firmware.encoders import WIRE_COUNTER_BITS
from odocan.host.judge.breaks import MAX_MERGE_FRAMES
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M, SILENCE_CYCLES
from odocan.host.judge.senderseq import QUEUED_GAP_CYCLES
from odocan.host.judge.stallfirst import (
    NEAR_FRAMES,
    FirstVerdict,
    Pair,
    better,
    carried_excess,
    decided,
)
from odocan.host.judge.stallresume import resume_excess

if TYPE_CHECKING:
    from cantools.database.can import Database

    from odocan.host.judge.tracking import PoseTracker
    from odocan.sim.robot import RobotProfile

MAX_MARKS = 64  # verdicts kept to take back: more silences than a late reboot's tell spans
Frame = tuple[int, int, int, int, float]  # position, E2E COUNTER, LEFT, RIGHT, bus time


class LiveFirst:
    """The rule, frame by frame (module docstring); ``verdict``: its counts and worst.
    Every attribute is declared here (a mypyc-compiled class under ODOCAN_ACCEL=1)."""

    _robot: tuple[Geometry, int]
    _integrator: Callable[[], str | None]
    _tolerance: tuple[float, float]
    _quiet_s: float
    _cycle_s: float
    _recent: deque[Frame]
    _n: int
    _x: tuple[int, float, float, float] | None  # ENC_COUNTER, X, HEADING, t
    _last_t_s: float | None  # the last ODOM_POSE_X's bus time
    _quiet: bool  # that X came after a silence
    _before: tuple[Pair, list[Frame]] | None  # the last pose, the frames from it
    _waiting: list[tuple[Pair, tuple[float, float] | None]]  # poses after a silence
    _marks: deque[tuple[float, FirstVerdict]]  # the verdict before each pose that moved it
    _reprimes: set[tuple[float, int]]  # stall_reprime events taken (bus time, encoder frame)
    verdict: FirstVerdict

    def __init__(self, geometry: Geometry, bits: int, integrator: Callable[[], str | None],
                 tolerance: tuple[float, float], cycle_s: float | None) -> None:
        self._robot = (geometry, bits)
        self._integrator = integrator
        self._tolerance = tolerance
        self._quiet_s = math.inf if cycle_s is None else (SILENCE_CYCLES - 0.5) * cycle_s
        self._cycle_s = 0.0 if cycle_s is None else cycle_s
        self._recent = deque(maxlen=NEAR_FRAMES + 1)
        self._n = 0
        self._x = None
        self._last_t_s = None
        self._quiet = False
        self._before = None
        self._waiting = []
        self._marks = deque(maxlen=MAX_MARKS)
        self._reprimes = set()
        self.verdict = FirstVerdict()

    def on_encoders(self, counter: int, left: int, right: int, t_s: float) -> None:
        frame = (self._n, counter, left, right, t_s)
        self._n += 1
        self._recent.append(frame)
        if self._before is not None and len(self._before[1]) <= MAX_MERGE_FRAMES:
            self._before[1].append(frame)

    def on_pose_x(self, named: int, x_m: float, heading_rad: float, t_s: float) -> None:
        self._x = (named, x_m, heading_rad, t_s)
        self._last_t_s, self._quiet = t_s, (self._last_t_s is not None
                                            and t_s - self._last_t_s >= self._quiet_s)

    def on_pose_y(self, named: int, y_m: float, turns: int) -> None:
        if self._x is None or self._x[0] != named:
            return
        _, x_m, heading_rad, t_s = self._x
        self._x = None
        # the frame it names when its X was sent (its Y may come a halt later: the rest of a
        # tick halted after its X; read at the Y, a frame 16 on: test_halted_send)
        frame = next((f for f in reversed(self._recent) if f[1] == named and f[4] <= t_s),
                     None)
        pose = Pair(t_s, named, -1 if frame is None else frame[0], x_m, y_m,
                    turns * 2 * math.pi + heading_rad)
        if self._quiet:  # since the X before it (any, paired or not)
            self._waiting.append((pose, self._forward(pose)))
            return
        self._waiting = [w for w in self._waiting  # let out in a burst: held back, no stall
                         if t_s - w[0].t_s >= QUEUED_GAP_CYCLES * self._cycle_s]
        if self._waiting and not self._heard_all(frame):  # a gap of the log: not a stall
            self._waiting = []
        for waiting, forward in self._waiting:  # the next pose: the backward neighbour
            self._judged(waiting, forward, self._backward(waiting, pose))
        if self._waiting and self._before is not None and frame is not None:
            self._resumed(self._before, pose)  # the stall is no set-pose: stallresume
        self._waiting = []
        self._before = None if frame is None else (pose, [frame])

    def _forward(self, pose: Pair) -> tuple[float, float] | None:
        if self._before is None:
            return None
        near, frames = self._before
        return self._best(pose, near, frames[:NEAR_FRAMES + 1], forward=True)

    def _resumed(self, before: tuple[Pair, list[Frame]], after: Pair) -> None:
        near, frames = before
        integrator = self._integrator()
        span = [f for f in frames if f[0] <= after.enc]
        if integrator is None or not span or span[-1][0] != after.enc:
            return  # frames beyond the window (a stall over MAX_MERGE_FRAMES): not judged here
        self._mark(after.t_s)
        self.verdict.resumed(after.t_s, resume_excess(
            (near.x_m, near.y_m, near.heading_rad), (after.x_m, after.y_m),
            (np.array([f[2] for f in span]), np.array([f[3] for f in span])),
            (self._robot[0], integrator, self._robot[1]), self._tolerance[0]))

    def _heard_all(self, frame: Frame | None) -> bool:
        """Every encoder frame from the pose before the silence to ``frame`` heard, on time
        (``stallfirst.heard_all``): the firmware was silent, not the logger."""
        if self._before is None or frame is None:
            return frame is not None  # judged backward only (a reboot, a set-pose)
        span = [f for f in self._before[1] if f[0] <= frame[0]]
        if not span or span[-1][0] != frame[0]:
            return False
        return all((b[1] - a[1]) % 16 == 1 and b[4] - a[4] < 1.5 * self._cycle_s
                   for a, b in itertools.pairwise(span))

    def withdraw_from(self, t_s: float) -> None:
        """A reboot told late: what poses from bus time ``t_s`` on moved was not one life's
        (``Tracker.withdraw_from``; a new firmware's first pose after its boot is no resume)."""
        while self._marks and self._marks[-1][0] >= t_s:
            self.verdict = self._marks.pop()[1]

    def untie(self, events: Iterable[dict[str, Any]]) -> None:
        """A re-prime after a stall (a ``stall_reprime`` event, told once its evidence came):
        the firmware left the motion out, so the poses around its first pose vouch for nothing
        from that frame on (a staged APPLY taken just after a stall, re-primed after it, was
        POSE WRONG 2.72 mm: test_cut_reprime_latched); each taken once."""
        for event in events:
            if event["kind"] != "stall_reprime":  # (a set-pose's encoder_frame may be None)
                continue
            key = (float(event["t_s"]), int(event.get("encoder_frame", -1)))
            if key not in self._reprimes:
                self._reprimes.add(key)
                self.withdraw_from(key[0] - self._cycle_s)

    def _mark(self, t_s: float) -> None:
        self._marks.append((t_s, replace(self.verdict)))

    def new_life(self) -> None:
        """A reboot or an applied set-pose: the pose before it vouches for nothing after, and
        a pose waiting for its next is judged by neither (the next is in the new frame: a
        staged APPLY taken just after a stall FAILed a correct firmware 2.72 mm,
        test_cut_reprime_latched): counted unjudged. The new life's first pose is not this
        rule's, as offline (``stallfirst.judge_left_out`` from a life's second pose): a reset
        halted before its first pose names a backlog frame beyond the window, whose alias the
        next pose carried back to said POSE WRONG 3839 mrad (test_reset_then_halt)."""
        self._before = None
        self.verdict.unjudged += len(self._waiting)
        self._waiting = []
        self._last_t_s = None  # a life's first pose is the reboot rules' (stallfirst: from 1)

    def _backward(self, pose: Pair, near: Pair) -> tuple[float, float] | None:
        if near.enc < 0:
            return None
        frames = [f for f in self._recent if f[0] <= near.enc]
        return self._best(pose, near, frames, forward=False)

    def _best(self, pose: Pair, near: Pair, frames: list[Frame], forward: bool
              ) -> tuple[float, float] | None:
        best: tuple[float, float] | None = None
        integrator = self._integrator()
        if integrator is None:  # not known yet (ODOM_STATUS): not judged
            return None
        left = np.array([f[2] for f in frames], dtype=np.int64)
        right = np.array([f[3] for f in frames], dtype=np.int64)
        robot = (self._robot[0], integrator, self._robot[1])
        for k, frame in enumerate(frames):
            if frame[1] != pose.named:
                continue
            span = slice(0, k + 1) if forward else slice(k, len(frames))
            best = better(best, carried_excess(pose, near, (left[span], right[span]), forward,
                                               robot, self._tolerance))
        return best

    def _judged(self, pose: Pair, forward: tuple[float, float] | None,
                backward: tuple[float, float] | None) -> None:
        self._mark(pose.t_s)
        # beyond on one side alone: not judged (``decided``)
        self.verdict.judge(pose.t_s, decided(forward, backward))

    def wrong(self) -> list[str]:
        """Why the monitor says POSE WRONG for this rule (empty: it does not)."""
        v, said = self.verdict, []
        if max(v.worst_position_m, v.worst_heading_rad) > 0:
            said.append(f"the pose sent first after a silence at {v.worst_at_s:.3f} s lies "
                        f"{max(v.worst_position_m, 0.0) * 1e3:.4g} mm, "
                        f"{max(v.worst_heading_rad, 0.0) * 1e3:.4g} mrad beyond the poses "
                        "around it carried over the encoder counts (host.judge.stallfirst)")
        if v.worst_resume_m > 0:
            said.append(f"the pose at {v.resume_at_s:.3f} s lies {v.worst_resume_m * 1e3:.4g} "
                        "mm beyond any the firmware can resume at from its pose before the "
                        "stall: a jump, no placement (host.judge.stallresume)")
        return said


def first_after_of(tracker: PoseTracker, robot: RobotProfile, db: Database) -> LiveFirst:
    """The monitor's ``LiveFirst``: its robot, the tracker's integrator, one LSB each (the live
    judge's limit, ``livestanding``), the DBC's encoder cycle."""
    cycle_ms = next((m.cycle_time for m in db.messages if m.name == "WHEEL_ENCODERS"), None)
    return LiveFirst(Geometry.of(robot), min(robot.counter_bits, WIRE_COUNTER_BITS),
                     lambda: tracker.integrator, (POSITION_LSB_M, HEADING_LSB_RAD),
                     None if not cycle_ms else cycle_ms / 1000.0)
