"""Seed 002's experiments (Valencia et al., 2009, Tables 1 and 2), with the firmware navigating.

* **Straight** (Table 1): ``runs`` drives to the goal (1 m, 0) of the odometry frame, turn-go-
  turn with no final heading.
* **Square** (Table 2): ``runs`` laps of the 80 cm square, counter-clockwise: goals (0.8, 0),
  (0.8, 0.8), (0, 0.8), (0, 0), each with the heading of the next side (the last 0), so the robot
  turns 90 degrees left in place at every corner.

Every run is a fresh power cycle of the robot in the closed-loop rig (``drive.NavSession``) under
the stated error model, its slip noise seeded per run. **Misalignment**: as the paper notes, "the
platform was not perfectly aligned at the start": each run draws a heading misalignment
delta ~ N(0, misalign_deg^2) (seeded); the marked line (and the marked square) is the floor's x
axis, the robot starts at its origin pointing delta to the left of it. The firmware cannot know
delta (its odometry starts at heading 0), so the whole run is rotated by delta on the floor.

**Measurements**, all from the ground truth (``Vehicle.truth()``), rotated by delta into the
floor frame (x along the marked line, y to its left, angles counter-clockwise positive):

* straight, ``distance_m``: |P_end - P_0|, the straight-line distance from the start point to
  where the robot came to rest (what a tape measures), m;
* straight, ``deviation_deg``: atan2 of (P_end - P_0), the angle of the travelled segment from
  the marked line, degrees, positive to the left;
* square, corner P_k (k = 1..4): the true position when goal k shows REACHED (the robot stopped
  at the corner after its turn in place), P_0 the start;
* square, side k: its length |P_k - P_(k-1)| and its deviation, the angle of P_k - P_(k-1) minus
  the marked side's direction (0, 90, 180, 270 degrees), wrapped to [-180, 180), positive left;
* square, turn at corner k (k = 1..3): the direction of side k + 1 minus that of side k, the
  angle of the traced square's corner as it is measured on the floor (90 = a perfect left turn);
* square, per run: ``side_m``, ``deviation_deg`` and ``turn_deg`` are the means over its four
  sides and three corners (each side and corner is also in the report).

**Verdict** (``faults``): the tables measure the robot only if the firmware did its part, so the
experiment passes when every run is valid (``drive.drive_faults``): the firmware ended at its
last goal by its own odometry, and its on-board end agrees with the float64 reference
dead-reckoning the run's logged encoder counts with the robot's nominal geometry.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

from odocan.host.experiments.drive import (
    DriveResult,
    NavSession,
    Waypoint,
    drive_faults,
)
from odocan.host.experiments.seeding import run_rng, run_seed
from odocan.host.judge.reference import Geometry
from odocan.sim.errors import ErrorModel
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.pose import wrap_angle
from odocan.sim.robot import RobotProfile

STRAIGHT_M = 1.0
SQUARE_SIDE_M = 0.8
RUNS = 10
DEFAULT_ERRORS = "ed=1.002,eb=1.01,slip=0.005"
DEFAULT_MISALIGN_DEG = 1.0
_STRAIGHT_CODE, _SQUARE_CODE = 1, 2
_CORNERS = 4


@dataclass(frozen=True)
class Seed002Config:
    """What the experiment runs: robot, real errors, misalignment std (deg), seed, runs."""

    robot: RobotProfile
    errors: ErrorModel
    misalign_deg: float = DEFAULT_MISALIGN_DEG
    seed: int = 0
    runs: int = RUNS
    integrator: str = "exact"


@dataclass(frozen=True)
class StraightRun:
    """Table 1's row: distance travelled (m), deviation (deg), and the drawn misalignment."""

    distance_m: float
    deviation_deg: float
    misalignment_deg: float
    faults: tuple[str, ...] = ()  # why the run cannot be trusted (empty: valid)


@dataclass(frozen=True)
class SquareRun:
    """Table 2's row: mean side (m), mean deviation (deg), mean turn (deg); sides and turns."""

    side_m: float
    deviation_deg: float
    turn_deg: float
    misalignment_deg: float
    sides_m: tuple[float, ...]
    deviations_deg: tuple[float, ...]
    turns_deg: tuple[float, ...]
    faults: tuple[str, ...] = ()  # why the run cannot be trusted (empty: valid)


@dataclass(frozen=True)
class Seed002Result:
    """Both tables' runs and the configuration they ran with."""

    config: Seed002Config
    straight: tuple[StraightRun, ...]
    square: tuple[SquareRun, ...]

    def faults(self) -> list[str]:
        """Why the tables cannot be trusted: every invalid run's reasons (empty: PASS)."""
        faults = [(k, "straight", run.faults) for k, run in enumerate(self.straight, start=1)]
        faults += [(k, "square", run.faults) for k, run in enumerate(self.square, start=1)]
        return [f"{table} run {k}: {reason}" for k, table, why in faults for reason in why]


def straight_path() -> list[Waypoint]:
    """Table 1: 1 m ahead, any final heading."""
    return [Waypoint(STRAIGHT_M, 0.0)]


def square_path() -> list[Waypoint]:
    """Table 2: the 80 cm square, counter-clockwise, back to the start heading 0."""
    s, half = SQUARE_SIDE_M, math.pi / 2.0
    return [Waypoint(s, 0.0, half), Waypoint(s, s, 2 * half), Waypoint(0.0, s, 3 * half),
            Waypoint(0.0, 0.0, 0.0)]


def _floor(x_m: float, y_m: float, delta_rad: float) -> tuple[float, float]:
    """A start-frame point in the floor frame (the start frame rotated by the misalignment)."""
    c, s = math.cos(delta_rad), math.sin(delta_rad)
    return c * x_m - s * y_m, s * x_m + c * y_m


def measure_straight(drive: DriveResult, delta_rad: float) -> StraightRun:
    """Table 1's measurements of one drive (module docstring); ``delta_rad`` the misalignment."""
    x, y = _floor(drive.end.x_m, drive.end.y_m, delta_rad)
    return StraightRun(math.hypot(x, y), math.degrees(math.atan2(y, x)), math.degrees(delta_rad))


def measure_square(drive: DriveResult, delta_rad: float) -> SquareRun:
    """Table 2's measurements of one lap (module docstring); ``delta_rad`` the misalignment."""
    corners = [(0.0, 0.0)]
    for goal_id in range(1, _CORNERS + 1):
        pose = drive.mark(goal_id, "REACHED").pose
        corners.append(_floor(pose.x_m, pose.y_m, delta_rad))
    lengths, directions = [], []
    for (x0, y0), (x1, y1) in itertools.pairwise(corners):
        lengths.append(math.hypot(x1 - x0, y1 - y0))
        directions.append(math.atan2(y1 - y0, x1 - x0))
    deviations = [math.degrees(wrap_angle(d - k * math.pi / 2)) for k, d in enumerate(directions)]
    turns = [math.degrees(wrap_angle(b - a)) for a, b in itertools.pairwise(directions)]
    return SquareRun(
        _mean(lengths), _mean(deviations), _mean(turns), math.degrees(delta_rad),
        tuple(lengths), tuple(deviations), tuple(turns),
    )


def _mean(values: list[float] | tuple[float, ...]) -> float:
    return math.fsum(values) / len(values)


def _drive(config: Seed002Config, code: int, index: int, path: list[Waypoint]) -> DriveResult:
    """One run on a fresh robot, its slip noise seeded by (seed, code, index)."""
    timeout_s = 20.0 * len(path) + 10.0
    seed = run_seed(config.seed, code, index)
    with NavSession(config.robot, config.errors, seed, config.integrator) as session:
        return session.drive(path, timeout_s)


def _misalignment_rad(config: Seed002Config, code: int, index: int) -> float:
    """The run's start misalignment, rad: N(0, misalign_deg^2) degrees, seeded."""
    draw = float(run_rng(config.seed, code, index).normal())
    return math.radians(config.misalign_deg * draw) + 0.0  # + 0.0: no -0.0 in the report


def run_seed002(
    config: Seed002Config, on_run: Callable[[], None] | None = None
) -> Seed002Result:
    """Both experiments, ``config.runs`` runs each, measured from the ground truth (``on_run``
    after each run: a progress line)."""
    if config.runs < 1:
        raise ConfigurationError(f"--runs must be at least 1, got {config.runs}")
    if not (math.isfinite(config.misalign_deg) and 0.0 <= config.misalign_deg <= 45.0):
        raise ConfigurationError(f"--misalign must be 0 .. 45 degrees, got {config.misalign_deg}")
    straight = []
    for i in range(config.runs):
        drive = _drive(config, _STRAIGHT_CODE, i, straight_path())
        run = measure_straight(drive, _misalignment_rad(config, _STRAIGHT_CODE, i))
        straight.append(replace(run, faults=_faults(config, drive, straight_path())))
        if on_run is not None:
            on_run()
    square = []
    for i in range(config.runs):
        drive = _drive(config, _SQUARE_CODE, i, square_path())
        lap = measure_square(drive, _misalignment_rad(config, _SQUARE_CODE, i))
        square.append(replace(lap, faults=_faults(config, drive, square_path())))
        if on_run is not None:
            on_run()
    return Seed002Result(config, tuple(straight), tuple(square))


def _faults(config: Seed002Config, drive: DriveResult, path: list[Waypoint]) -> tuple[str, ...]:
    """``drive_faults`` of one run with the robot's nominal geometry (the firmware's)."""
    robot = config.robot
    return tuple(drive_faults(drive, path[-1], Geometry.of(robot), robot.counter_bits,
                              config.integrator))


def report(result: Seed002Result) -> dict[str, object]:
    """The ``--report`` JSON contract (README, "Experiments")."""
    c = result.config
    straight_runs = [
        {"distance_m": r.distance_m, "deviation_deg": r.deviation_deg,
         "misalignment_deg": r.misalignment_deg}
        for r in result.straight
    ]
    square_runs = [
        {"side_m": r.side_m, "deviation_deg": r.deviation_deg, "turn_deg": r.turn_deg,
         "misalignment_deg": r.misalignment_deg, "sides_m": list(r.sides_m),
         "side_deviations_deg": list(r.deviations_deg), "turns_deg": list(r.turns_deg)}
        for r in result.square
    ]
    return {
        "experiment": "seed002",
        "robot": c.robot.name,
        "integrator": c.integrator,
        "seed": c.seed,
        "error_model": {"ed": c.errors.ed, "eb": c.errors.eb, "slip": c.errors.slip,
                        "misalign_std_deg": c.misalign_deg},
        "straight_1m": {
            "goal_m": STRAIGHT_M,
            "runs": straight_runs,
            "mean": {"distance_m": _mean([r.distance_m for r in result.straight]),
                     "deviation_deg": _mean([r.deviation_deg for r in result.straight])},
        },
        "square_80cm": {
            "side_goal_m": SQUARE_SIDE_M,
            "direction": "ccw",
            "runs": square_runs,
            "mean": {"side_m": _mean([r.side_m for r in result.square]),
                     "deviation_deg": _mean([r.deviation_deg for r in result.square]),
                     "turn_deg": _mean([r.turn_deg for r in result.square])},
        },
    }
