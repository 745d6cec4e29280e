"""Closed-loop drives: the firmware navigates a path of NAV_GOALs, the host measures the truth.

One ``NavSession`` is one power cycle of the robot in the lockstep rig (``RigConfig(scenario=
None)``): the vehicle at rest at the origin of its start frame (x forward, y to the left,
headings counter-clockwise positive), the firmware configured with the robot's nominal geometry.
The host may first write new geometry over CAN (``configure``: ODOM_CONFIG staged writes + APPLY,
each frame answered by ODOM_ACK), then ``drive`` a path: each goal is staged and committed by
NAV_GOAL frames, the first one REPLACE, the others APPEND; the firmware drives turn-go-turn from
its own odometry while the host listens. The commands, their ODOM_ACKs and NAV_STATUS go through
``host.protocol.session.CommandSession`` (the pytest kit's too), over what the host heard
(``host.protocol.heard``: E2E-checked, decoded from the DBC):

* every NAV_STATUS whose (STATE, GOAL_ID) differs from the previous one is a ``Mark``, stamped
  with the ground truth of that tick (``Vehicle.truth()``: the tape measure of the experiment);
* the last ODOM_POSE_X / ODOM_POSE_Y pair naming one encoder frame is the on-board pose
  (``host.protocol.pose``; 0.1 mm, 9.6e-5 rad);
* every ODOM_ACK is checked: a NACK, or none, is an ``ExperimentError``.

The drive ends when the last goal shows REACHED with an empty queue, then the robot is left
``SETTLE_S`` to come to rest before the end pose is taken.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.judge.reference import Geometry, deltas_from_counts, integrate
from odocan.host.protocol import busfacts
from odocan.host.protocol.commands import CommandRejected
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.heard import Recorder
from odocan.host.protocol.session import CommandNotAcked, CommandSession
from odocan.sim.board import TICK_S
from odocan.sim.closing import Closing
from odocan.sim.contract import database
from odocan.sim.errors import ErrorModel
from odocan.sim.exceptions import OdocanError
from odocan.sim.pose import Pose
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import RobotProfile
from odocan.sim.truth import TruthPose

BOOT_S = 0.2  # the odometry is OK (first encoder frames) before the first goal is sent
SETTLE_S = 1.0  # after the last REACHED: the zero commands, then the motors' tail
ACK_TIMEOUT_S = 0.5
IntArray = npt.NDArray[np.int64]
WIRE_COUNTER_BITS = busfacts.ENC_WIRE_COUNTER_BITS  # WHEEL_ENCODERS: each count's low 24 bits
RETURN_TOLERANCE_M = 0.01  # the firmware stops within 5 mm of a goal (POSITION_TOL), with margin
ONBOARD_TOLERANCE_M = 1e-3  # on-board end vs float64 dead reckoning (the pose LSB is 0.1 mm)
_FAILED = frozenset({"STOPPED", "ABORTED"})


class ExperimentError(OdocanError):
    """An experiment could not run as planned (a NACK, a goal not reached in time)."""


class PathNotReached(ExperimentError):
    """The firmware did not reach its path in time: the experiment ran and failed, exit 1 (not
    2: nothing the person typed was wrong)."""

    exit_code = 1


@dataclass(frozen=True)
class Waypoint:
    """One goal of a path, in the odometry (start) frame: metres, and the final heading in
    radians (None: NO_FINAL_HEADING, the robot stops in any heading)."""

    x_m: float
    y_m: float
    heading_rad: float | None = None


@dataclass(frozen=True)
class Mark:
    """The truth at a NAV_STATUS change: ``state`` (a NAV_STATUS STATE name) of goal ``goal_id``
    began in the tick whose true pose is ``pose`` (start frame, m and rad)."""

    goal_id: int
    state: str
    pose: TruthPose


@dataclass(frozen=True)
class DriveResult:
    """A path driven: the marks in order, the settled true end pose, the on-board end pose
    (the last ODOM_POSE_X/Y pair naming one encoder frame, ``host.protocol.pose``: x_m, y_m and
    the cumulative heading_rad, TURNS * 2 pi + HEADING), and the raw 24-bit
    (left, right) counters of every WHEEL_ENCODERS frame from t = 0 (the first is at rest, the
    last is of the tick of ``end``)."""

    marks: tuple[Mark, ...]
    end: TruthPose
    onboard_end: Pose
    encoder_counts: tuple[IntArray, IntArray]

    def mark(self, goal_id: int, state: str) -> Mark:
        """The first mark of ``state`` for ``goal_id``; ExperimentError when there is none."""
        for mark in self.marks:
            if mark.goal_id == goal_id and mark.state == state:
                return mark
        raise ExperimentError(f"goal {goal_id} never showed {state}")


class NavSession(Closing):
    """The robot powered on in the closed-loop rig; the host drives it over CAN through a
    ``host.protocol.session.CommandSession`` (the one the pytest kit drives with).

    Args:
        robot: nominal profile (the firmware's geometry at boot).
        errors: the real robot's errors (``sim.errors.ErrorModel``).
        seed: seed of the slip noise.
        integrator: on-board integrator name.
        channel: the python-can ``virtual`` channel of this rig.
    """

    def __init__(
        self,
        robot: RobotProfile,
        errors: ErrorModel,
        seed: int,
        integrator: str = "exact",
        channel: str = "odocan-experiment",
    ) -> None:
        self.robot = robot
        self.integrator = integrator
        self.heard = Recorder(database())
        config = RigConfig(
            robot=robot,
            integrator=integrator,
            scenario=None,
            seed=seed,
            errors=errors,
            channel=channel,
        )
        self.rig = LockstepRig(config, [self.heard])
        self.session = CommandSession(
            self.heard, self.rig.send, self._run_until, ack_timeout_s=ACK_TIMEOUT_S
        )
        self.marks: list[Mark] = []
        self._last_goal = 0
        self._finished = False

    def close(self) -> None:
        """Release the rig's buses."""
        self.rig.close()

    def _run_until(self, done: Callable[[], bool], timeout_s: float) -> bool:
        """The session's wait: step the rig until ``done()``, taking the marks after every
        tick (a goal that ends STOPPED or ABORTED meanwhile is an ``ExperimentError``)."""

        def marked_and_done() -> bool:
            self._take_marks()
            return done()

        return self.rig.run_until(marked_and_done, timeout_s)

    def _command(self, what: str, send: Callable[[], object]) -> None:
        """Run one command of the session; a refusal, a NACK or no ODOM_ACK within
        ``ACK_TIMEOUT_S`` as an ``ExperimentError`` naming ``what``."""
        try:
            send()
        except CommandRejected as exc:
            raise ExperimentError(f"{what}: {exc.reason}") from None
        except CommandNotAcked as exc:
            if exc.reason.startswith("NACK"):
                raise ExperimentError(f"{what}: NACK ({exc.reason[5:]})") from None
            raise ExperimentError(f"{what}: no ODOM_ACK within {ACK_TIMEOUT_S} s") from None

    def configure(self, radius_left_m: float, radius_right_m: float, wheelbase_m: float) -> None:
        """Write the wheel radii and the wheelbase (m, sent as whole nanometres) over CAN:
        ODOM_CONFIG staged writes + APPLY, waiting for the APPLY's ODOM_ACK."""
        self._command("config", lambda: self.session.configure(
            counts_per_rev=self.robot.counts_per_rev,
            wheel_radius_left_m=radius_left_m,
            wheel_radius_right_m=radius_right_m,
            wheelbase_m=wheelbase_m,
            counter_bits=self.robot.counter_bits,
            integrator=self.integrator,
        ))

    def drive(self, path: Sequence[Waypoint], timeout_s: float) -> DriveResult:
        """Drive ``path`` turn-go-turn (goal ids 1..n); the marks, the settled truth, the
        on-board end pose and the encoder log. ExperimentError when a goal is refused, stopped
        or aborted, or the path takes longer than ``timeout_s`` simulated seconds."""
        if self.rig.ticks * TICK_S < BOOT_S:
            self.rig.run(BOOT_S)
        self._last_goal = len(path)
        self._finished = False
        for goal_id, point in enumerate(path, start=1):
            self._goal(goal_id, point)
        if not self._finished and not self.rig.run_until(self._take_marks, timeout_s):
            raise PathNotReached(f"path of {len(path)} goals not reached within {timeout_s:g} s"
                                  f"{self._where_stuck()}")
        self.rig.run(SETTLE_S)
        onboard = self.heard.latest_pose()
        if onboard is None:
            raise ExperimentError("no ODOM_POSE_X/Y heard from the firmware")
        return DriveResult(
            tuple(self.marks), self.rig.vehicle.truth(), onboard, self._encoder_counts()
        )

    def _where_stuck(self) -> str:
        """Where a path that timed out stands, from the last NAV_STATUS and pose heard: the
        goal and its state, the distance and heading error left, the on-board pose."""
        status = self.heard.decoded("NAV_STATUS")
        if not status:
            return " (no NAV_STATUS heard from the firmware)"
        last = status[-1]
        text = (f": goal {last['GOAL_ID']} of {self._last_goal} still {last['STATE']}, "
                f"{float(last['DISTANCE']) * 1e3:.1f} mm and "
                f"{float(last['HEADING_ERROR']) * 1e3:.1f} mrad from it by the firmware's own "
                "odometry")
        pose = self.heard.latest_pose()
        if pose is not None:
            text += f" (on-board pose x {pose.x_m:.4f} m, y {pose.y_m:.4f} m)"
        return text

    def _goal(self, goal_id: int, point: Waypoint) -> None:
        """Goal ``goal_id`` (the first replaces the path, the others are appended), ACKed."""
        self._command(f"goal {goal_id}", lambda: self.session.goal(
            point.x_m, point.y_m, point.heading_rad, goal_id=goal_id, append=goal_id > 1
        ))

    def _take_marks(self) -> bool:
        """Turn the NAV_STATUS changes heard into marks with this tick's truth (called after
        every tick); True once the path's last goal is REACHED with an empty queue."""
        changes = self.session.status_changes()
        if changes:
            pose = self.rig.vehicle.truth()
            for change in changes:
                if change.state in _FAILED:
                    raise ExperimentError(f"goal {change.goal_id} ended {change.state}")
                self.marks.append(Mark(change.goal_id, change.state, pose))
                if (change.goal_id, change.state, change.queue_depth) == (
                    self._last_goal, "REACHED", 0
                ):
                    self._finished = True
        return self._finished

    def _encoder_counts(self) -> tuple[IntArray, IntArray]:
        """(left, right) LEFT_COUNT/RIGHT_COUNT of every WHEEL_ENCODERS frame heard (raw u24)."""
        decoded = BulkDecoder(database()).decode(self.heard.arrays(), "WHEEL_ENCODERS")
        return decoded["LEFT_COUNT"].astype(np.int64), decoded["RIGHT_COUNT"].astype(np.int64)


def dead_reckon(
    counts: tuple[IntArray, IntArray], geometry: Geometry, counter_bits: int,
    integrator: str = "exact",
) -> tuple[float, float]:
    """(x, y) m where the float64 reference ends on the logged raw counters of a
    ``counter_bits``-wide encoder, from the power-up pose 0: the wire carries the low
    min(counter_bits, 24) bits, so the deltas wrap there (a 16-bit counter at 2^16)."""
    bits = min(counter_bits, WIRE_COUNTER_BITS)
    d_left = deltas_from_counts(counts[0], bits)
    d_right = deltas_from_counts(counts[1], bits)
    if d_left.size == 0:
        return 0.0, 0.0
    poses = integrate(d_left, d_right, geometry, integrator)
    return float(poses.x_m[-1]), float(poses.y_m[-1])


def drive_faults(
    drive: DriveResult, goal: Waypoint, geometry: Geometry, counter_bits: int, integrator: str
) -> list[str]:
    """Why a drive's measurement cannot be trusted (empty: it can): the firmware did not end at
    its last ``goal`` by its own odometry, or its on-board end departs from the float64
    reference dead-reckoning the same logged counts with the firmware's ``geometry`` (then the
    truth measures a wrong firmware, not the robot)."""
    reasons = []
    x_m, y_m = drive.onboard_end[0], drive.onboard_end[1]
    away_m = math.hypot(x_m - goal.x_m, y_m - goal.y_m)
    if away_m > RETURN_TOLERANCE_M:
        reasons.append(f"the firmware stopped {away_m * 1e3:.1f} mm from its goal by its own "
                       "odometry")
    ref_x, ref_y = dead_reckon(drive.encoder_counts, geometry, counter_bits, integrator)
    off_m = math.hypot(x_m - ref_x, y_m - ref_y)
    if off_m > ONBOARD_TOLERANCE_M:
        reasons.append(f"the on-board end is {off_m * 1e3:.1f} mm from the float64 reference on "
                       "the same encoder counts (a wrong firmware)")
    return reasons
