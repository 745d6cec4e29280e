"""UMBmark (Borenstein & Feng, 1996): the bidirectional square test and the calibration of E_d, E_b.

**Convention.** Everything is in the robot's start frame: origin at the wheel-axle midpoint at
the start, x forward along the start heading, y to the left, angles counter-clockwise positive
(the ``sim.pose.Pose`` frame, which is also the on-board odometry's frame). The counter-clockwise
(CCW) run drives the goals (L, 0), (L, L), (0, L), (0, 0) turning left; the clockwise (CW) run
(L, 0), (L, -L), (0, -L), (0, 0) turning right; each corner's goal carries the heading of the
next side (the last one heading 0), so the robot makes four 90-degree turns in place, as in the
paper, and the firmware navigates turn-go-turn from its own odometry.

**Return error** of a run: epsilon = (x, y)_true - (x, y)_odometry at the end, Borenstein's
x_abs - x_calc: the settled ground truth minus the on-board pose decoded from ODOM_POSE_X/Y (both
in the start frame; the firmware stops within 5 mm of its goal, so subtracting its own end pose
removes that tolerance from the measurement). Centres of gravity: x_cg = mean(epsilon_x),
y_cg = mean(epsilon_y) per direction, r_cg = hypot(x_cg, y_cg), E_max,syst = max(r_cw, r_ccw).

**Borenstein's estimate.** alpha is the under-rotation of each 90-degree turn (rad, > 0 when the
robot turns less than it believes, i.e. E_b > 1) and beta the heading the robot gains, counter-
clockwise, over one side it believes straight (rad, > 0 when the right wheel is the larger,
E_d > 1). To first order (derived in the README for this frame, and checked by simulation)
x_cw = -2L(alpha + beta), x_ccw = 2L(beta - alpha), so

    alpha = (x_cg,cw + x_cg,ccw) / (-4L),   beta = (x_cg,cw - x_cg,ccw) / (-4L),
    E_b = (pi/2) / (pi/2 - alpha),   R = (L/2) / sin(beta/2),   E_d = (R + b/2) / (R - b/2),

with b = E_b * b_nominal, the actual wheelbase (Borenstein writes b; the difference is E_b - 1
of E_d - 1, here 1 %).

**Model-based estimate.** The host also hears every WHEEL_ENCODERS frame: dead reckoning the
logged counts with the float64 reference (``host.reference.integrate``, exact arcs) and a
candidate geometry (r_L = r * 2/(E_d + 1), r_R = r * 2 E_d/(E_d + 1), b = E_b * b_nominal) must
end where the truth ended. Gauss-Newton on (E_d, E_b) over the true end positions of every run
(two residuals per run), from Borenstein's estimate. It uses the wheels' actual motion, so it
is free of the first-order approximation and of the closed loop's small departures from the
ideal square (the 0.5-degree turn tolerance corrected while driving).

**Correction** (Borenstein's): the firmware's radii become r_L * 2/(E_d + 1) and
r_R * 2 E_d/(E_d + 1) (the mean kept) and its wheelbase E_b * b, written over CAN.

**Verdicts** (``faults``: the reasons a result cannot be trusted; empty = PASS). A benchmark is
valid when, in every run, the firmware came back to the origin it navigated to (within
``drive.RETURN_TOLERANCE_M`` by its own odometry) and its on-board end agrees with the float64
reference dead-reckoning the same logged counts with the geometry the firmware had (within
``drive.ONBOARD_TOLERANCE_M``): else the return errors measure a wrong firmware, not the robot. A
calibration passes when both benchmarks are valid, the estimate is plausible (the model fit
explains the true ends: RMS residual within FIT_RESIDUAL_FRACTION of E_max,syst before, plus
FIT_RESIDUAL_FLOOR_M; both factors within PLAUSIBLE_RANGE) and the correction cuts E_max,syst by
at least ``min_improvement``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import astuple, dataclass

import numpy as np

from odocan.host.experiments.drive import (
    DriveResult,
    ExperimentError,
    NavSession,
    Waypoint,
    dead_reckon,
    drive_faults,
)
from odocan.host.experiments.seeding import run_seed
from odocan.host.experiments.umbmark_bounds import refused_parameters, small_angle_faults
from odocan.host.judge.reference import Geometry
from odocan.sim.errors import ErrorModel
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import RobotProfile

DIRECTIONS = ("cw", "ccw")
SIDE_M = 4.0
RUNS_PER_DIRECTION = 5
_FIT_STEP = 1e-7  # finite-difference step of the Gauss-Newton Jacobian (dimensionless)
_FIT_ITERATIONS = 20
_FIT_TOLERANCE = 1e-12
_EXPERIMENT_CODE = {"cw": 3, "ccw": 4}
FIT_RESIDUAL_FRACTION = 0.1
FIT_RESIDUAL_FLOOR_M = 0.005
PLAUSIBLE_RANGE = (0.5, 2.0)  # the error model's own range of E_d and E_b
MIN_IMPROVEMENT = 2.0  # calibrate's default: E_max,syst at least halved


@dataclass(frozen=True)
class Correction:
    """The firmware's geometry: wheel radii and wheelbase, m (sent over CAN as whole nm)."""

    wheel_radius_left_m: float
    wheel_radius_right_m: float
    wheelbase_m: float

    @classmethod
    def nominal(cls, robot: RobotProfile) -> Correction:
        """The profile's own geometry (what the firmware boots with)."""
        return cls(robot.wheel_radius_left_m, robot.wheel_radius_right_m, robot.wheelbase_m)

    def corrected(self, ed: float, eb: float) -> Correction:
        """Borenstein's correction for a measured (E_d, E_b): mean radius kept."""
        return Correction(
            self.wheel_radius_left_m * 2.0 / (ed + 1.0),
            self.wheel_radius_right_m * 2.0 * ed / (ed + 1.0),
            self.wheelbase_m * eb,
        )


@dataclass(frozen=True)
class CentreOfGravity:
    """Mean return error of one direction's runs, m (start frame)."""

    x_m: float
    y_m: float

    @property
    def r_m(self) -> float:
        """r_cg = hypot(x_cg, y_cg), m."""
        return math.hypot(self.x_m, self.y_m)


@dataclass(frozen=True)
class UmbmarkRun:
    """One run: its direction, return error (m) and the drive it measured."""

    direction: str
    error_x_m: float
    error_y_m: float
    drive: DriveResult


@dataclass(frozen=True)
class UmbmarkResult:
    """Both directions' runs, in run order, and the side length (m)."""

    side_m: float
    runs: tuple[UmbmarkRun, ...]
    geometry: Correction | None = None  # written to the firmware (None: the profile's)

    def of(self, direction: str) -> list[UmbmarkRun]:
        """The runs of one direction ("cw" or "ccw")."""
        return [r for r in self.runs if r.direction == direction]

    def cg(self, direction: str) -> CentreOfGravity:
        """The centre of gravity of one direction's return errors."""
        return centre_of_gravity([(r.error_x_m, r.error_y_m) for r in self.of(direction)])

    @property
    def emax_m(self) -> float:
        """E_max,syst = max(r_cg,cw, r_cg,ccw), m."""
        return max(self.cg(d).r_m for d in DIRECTIONS)


@dataclass(frozen=True)
class BorensteinEstimate:
    """alpha, beta (rad, module docstring), the radius R of a side (m), E_d and E_b."""

    alpha_rad: float
    beta_rad: float
    radius_m: float
    ed: float
    eb: float


def square_path(side_m: float, direction: str) -> list[Waypoint]:
    """The UMBmark square of side ``side_m`` m, "cw" or "ccw", from and back to the origin."""
    sign = 1.0 if direction == "ccw" else -1.0
    half = math.pi / 2.0
    return [
        Waypoint(side_m, 0.0, sign * half),
        Waypoint(side_m, sign * side_m, sign * 2.0 * half),
        Waypoint(0.0, sign * side_m, sign * 3.0 * half),
        Waypoint(0.0, 0.0, 0.0),
    ]


TURN_RIM_SPEED_M_S = 0.3  # the firmware turns in place at most 0.3 m/s at the rims (firmware.nav)


def square_timeout_s(side_m: float, wheelbase_m: float = 0.3) -> float:
    """Simulated seconds a square may take: 4 sides at 0.3 m/s and 5 s per corner, plus, on a
    wheelbase wider than 0.3 m, twice a quarter turn at the firmware's rim turn speed (a 2 m
    robot turns at 0.3 rad/s: 5 s per quarter turn)."""
    wider_m = max(wheelbase_m - 0.3, 0.0)
    turn_s = 2.0 * (math.pi / 2.0) * (wider_m / 2.0) / TURN_RIM_SPEED_M_S
    return 4.0 * (side_m / 0.3 + 5.0 + turn_s)


def centre_of_gravity(errors: Sequence[tuple[float, float]]) -> CentreOfGravity:
    """Mean of (x, y) return errors, m; ConfigurationError when there is none."""
    if not errors:
        raise ConfigurationError("no runs to average")
    xs, ys = zip(*errors, strict=True)
    return CentreOfGravity(math.fsum(xs) / len(xs), math.fsum(ys) / len(ys))


def borenstein(
    cw: CentreOfGravity, ccw: CentreOfGravity, side_m: float, wheelbase_m: float
) -> BorensteinEstimate:
    """Borenstein & Feng's E_d and E_b from the centres of gravity (m), the side L (m) and the
    nominal wheelbase b (m); equations in the module docstring. beta = 0 gives R = inf, E_d = 1."""
    alpha = (cw.x_m + ccw.x_m) / (-4.0 * side_m)
    beta = (cw.x_m - ccw.x_m) / (-4.0 * side_m)
    eb = (math.pi / 2.0) / (math.pi / 2.0 - alpha)
    half_b = 0.5 * eb * wheelbase_m
    if beta == 0.0:
        return BorensteinEstimate(alpha, beta, math.inf, 1.0, eb)
    radius = (side_m / 2.0) / math.sin(beta / 2.0)
    return BorensteinEstimate(alpha, beta, radius, (radius + half_b) / (radius - half_b), eb)


def dead_reckoned_end(
    counts: tuple[np.ndarray, np.ndarray], geometry: Geometry, counter_bits: int
) -> np.ndarray:
    """(x, y) m where the float64 reference (exact arcs) ends on the logged raw counters of a
    ``counter_bits``-wide encoder (``drive.dead_reckon``: deltas wrap at min(counter_bits, 24)
    bits, what the wire carries)."""
    return np.array(dead_reckon(counts, geometry, counter_bits))


def candidate_geometry(robot: RobotProfile, base: Correction, ed: float, eb: float) -> Geometry:
    """The float geometry of ``base`` with (E_d, E_b) applied as the real robot has them."""
    fixed = base.corrected(ed, eb)
    return Geometry(
        robot.counts_per_rev, fixed.wheel_radius_left_m, fixed.wheel_radius_right_m,
        fixed.wheelbase_m, robot.max_wheel_speed_mm_s,
    )


def _residuals(
    robot: RobotProfile, base: Correction, drives: Sequence[DriveResult], p: np.ndarray
) -> np.ndarray:
    """True end minus dead-reckoned end, every run, flattened (m)."""
    geometry = candidate_geometry(robot, base, float(p[0]), float(p[1]))
    out = [
        np.array([d.end.x_m, d.end.y_m])
        - dead_reckoned_end(d.encoder_counts, geometry, robot.counter_bits)
        for d in drives
    ]
    return np.concatenate(out)


def model_fit(
    robot: RobotProfile,
    base: Correction,
    drives: Sequence[DriveResult],
    start: tuple[float, float] = (1.0, 1.0),
) -> tuple[float, float]:
    """(E_d, E_b) that make the logged counts dead-reckon to the true end positions (least
    squares, Gauss-Newton with a finite-difference Jacobian), relative to the ``base`` geometry
    the firmware had during the runs."""
    p = np.array(start, dtype=np.float64)
    for _ in range(_FIT_ITERATIONS):
        r = _residuals(robot, base, drives, p)
        jac = np.empty((r.size, 2))
        for k in range(2):
            dp = np.zeros(2)
            dp[k] = _FIT_STEP
            jac[:, k] = (_residuals(robot, base, drives, p + dp) - r) / _FIT_STEP
        step, *_ = np.linalg.lstsq(jac, -r, rcond=None)
        p = p + step
        if float(np.max(np.abs(step))) < _FIT_TOLERANCE:
            break
    return float(p[0]), float(p[1])


def return_error(drive: DriveResult) -> tuple[float, float]:
    """epsilon = true end - on-board end (x, y), m, in the start frame."""
    return drive.end.x_m - drive.onboard_end[0], drive.end.y_m - drive.onboard_end[1]


def _directions(runs_per_direction: int) -> Iterator[tuple[str, int]]:
    """CW runs first, then CCW (Borenstein's order), with each run's index."""
    for direction in DIRECTIONS:
        for i in range(runs_per_direction):
            yield direction, i


def run_umbmark(
    robot: RobotProfile,
    errors: ErrorModel,
    seed: int,
    *,
    side_m: float = SIDE_M,
    runs_per_direction: int = RUNS_PER_DIRECTION,
    geometry: Correction | None = None,
    phase: int = 0,
    on_run: Callable[[], None] | None = None,
) -> UmbmarkResult:
    """UMBmark: ``runs_per_direction`` squares each way, each on a freshly powered robot whose
    firmware is first given ``geometry`` over CAN (None: it keeps the profile's). ``phase``
    separates the noise of a second benchmark (after calibration) from the first's;
    ``on_run`` is called after each square (a progress line)."""
    if side_m <= 0 or not math.isfinite(side_m):
        raise ConfigurationError(f"--side must be a positive length, got {side_m}")
    if runs_per_direction < 1:
        raise ConfigurationError(f"--runs must be at least 1, got {runs_per_direction}")
    runs = []
    for direction, i in _directions(runs_per_direction):
        run_id = run_seed(seed, _EXPERIMENT_CODE[direction] + 10 * phase, i)
        with NavSession(robot, errors, run_id) as session:
            if geometry is not None:
                session.configure(
                    geometry.wheel_radius_left_m, geometry.wheel_radius_right_m,
                    geometry.wheelbase_m,
                )
            timeout_s = square_timeout_s(side_m, robot.wheelbase_m)
            drive = session.drive(square_path(side_m, direction), timeout_s)
        runs.append(UmbmarkRun(direction, *return_error(drive), drive))
        if on_run is not None:
            on_run()
    return UmbmarkResult(side_m, tuple(runs), geometry)


def faults(result: UmbmarkResult, robot: RobotProfile) -> list[str]:
    """Why the benchmark's return errors cannot be trusted (module docstring, ``drive_faults``
    of every run: back at the origin, on-board end = float64 reference); empty when valid."""
    firmware = result.geometry or Correction.nominal(robot)
    geometry = Geometry(robot.counts_per_rev, firmware.wheel_radius_left_m,
                        firmware.wheel_radius_right_m, firmware.wheelbase_m,
                        robot.max_wheel_speed_mm_s)
    reasons = []
    for direction in DIRECTIONS:
        for k, run in enumerate(result.of(direction), start=1):
            goal = square_path(result.side_m, direction)[-1]
            for reason in drive_faults(run.drive, goal, geometry, robot.counter_bits, "exact"):
                reasons.append(f"{direction.upper()} run {k}: {reason}")
    return reasons


METHODS = ("model", "borenstein")


@dataclass(frozen=True)
class Findings:
    """What a calibration found before the benchmark after: the benchmark before, both estimates,
    the one applied (``method``) and the geometry written to the firmware. ``Calibration`` and
    ``Refusal`` share these fields, first and in this order (positional construction as before)."""

    before: UmbmarkResult
    borenstein: BorensteinEstimate
    model: tuple[float, float]
    method: str
    nominal: Correction
    corrected: Correction


@dataclass(frozen=True)
class Calibration(Findings):
    """A calibration: its ``Findings``, the benchmark after and the model fit's residual."""

    after: UmbmarkResult
    fit_residual_m: float = 0.0  # RMS of true end - dead-reckoned end at the model fit

    @property
    def estimated(self) -> tuple[float, float]:
        """The applied (E_d, E_b)."""
        if self.method == "borenstein":
            return self.borenstein.ed, self.borenstein.eb
        return self.model


@dataclass(frozen=True)
class Refusal(Findings):
    """A calibration whose corrected geometry the firmware refused: its ``Findings`` but the
    benchmark after, which never ran."""

    fit_residual_m: float
    estimated: tuple[float, float]  # the (E_d, E_b) applied


class CorrectionRefused(ExperimentError):
    """The calibration's estimate is a geometry the firmware refuses (e.g. a 1 cm wheelbase times
    E_b 0.7, below its 1 cm minimum): the calibration failed, exit 1, not bad input. ``refusal``:
    what the calibration found up to it (for its report)."""

    exit_code = 1

    def __init__(self, message: str, refusal: Refusal) -> None:
        super().__init__(message)
        self.refusal = refusal


def calibrate(
    robot: RobotProfile,
    errors: ErrorModel,
    seed: int,
    *,
    side_m: float = SIDE_M,
    runs_per_direction: int = RUNS_PER_DIRECTION,
    method: str = "model",
    on_run: Callable[[], None] | None = None,
) -> Calibration:
    """UMBmark, both estimates of (E_d, E_b), the corrected geometry written to the firmware over
    CAN (ODOM_CONFIG + APPLY, ACK awaited) at every power-up of a second UMBmark (``on_run``
    after each of the 4 x ``runs_per_direction`` squares)."""
    if method not in METHODS:
        raise ConfigurationError(f"unknown method {method!r} (known: {', '.join(METHODS)})")
    runs = runs_per_direction
    before = run_umbmark(robot, errors, seed, side_m=side_m, runs_per_direction=runs,
                         on_run=on_run)
    nominal = Correction.nominal(robot)
    estimate = borenstein(before.cg("cw"), before.cg("ccw"), side_m, robot.wheelbase_m)
    start = (estimate.ed, estimate.eb) if _plausible(estimate.ed, estimate.eb) else (1.0, 1.0)
    drives = [r.drive for r in before.runs]
    fitted = model_fit(robot, nominal, drives, start)
    residual = _residuals(robot, nominal, drives, np.array(fitted))
    fit_residual_m = float(np.sqrt(np.mean(residual * residual)) * math.sqrt(2.0))
    chosen = (estimate.ed, estimate.eb) if method == "borenstein" else fitted
    corrected = nominal.corrected(*chosen)
    try:
        after = run_umbmark(
            robot, errors, seed, side_m=side_m, runs_per_direction=runs, geometry=corrected,
            phase=1, on_run=on_run,
        )
    except ExperimentError as exc:
        if not str(exc).startswith("config:"):
            raise
        raise CorrectionRefused(
            f"the firmware refused the corrected geometry (E_d {chosen[0]:.6g}, E_b "
            f"{chosen[1]:.6g}: radii {corrected.wheel_radius_left_m:.6g}/"
            f"{corrected.wheel_radius_right_m:.6g} m, wheelbase {corrected.wheelbase_m:.6g} m), "
            f"{exc}: " + "; ".join(refused_parameters(*astuple(corrected)) or ["the whole set"])
            + "".join(f"; {r}" for r in small_angle_faults(before.emax_m, side_m)),
            Refusal(before, estimate, fitted, method, nominal, corrected, fit_residual_m, chosen),
        ) from None
    return Calibration(
        before, estimate, fitted, method, nominal, corrected, after, fit_residual_m
    )


def calibration_faults(
    cal: Calibration, robot: RobotProfile, min_improvement: float = MIN_IMPROVEMENT
) -> list[str]:
    """Why the calibration failed (module docstring); empty when it passed."""
    reasons = [f"before: {r}" for r in faults(cal.before, robot)]
    reasons += [f"after: {r}" for r in faults(cal.after, robot)]
    ed, eb = cal.estimated
    low, high = PLAUSIBLE_RANGE
    if not all(math.isfinite(v) and low <= v <= high for v in (ed, eb)):
        reasons.append(f"implausible estimate E_d {ed:.6g}, E_b {eb:.6g} (outside {low}..{high})")
    limit_m = FIT_RESIDUAL_FRACTION * cal.before.emax_m + FIT_RESIDUAL_FLOOR_M
    if cal.fit_residual_m > limit_m:
        reasons.append(
            f"implausible estimate: the model fit leaves {cal.fit_residual_m * 1e3:.1f} mm RMS "
            f"between the true and the dead-reckoned ends (more than {limit_m * 1e3:.1f} mm): "
            "the errors are beyond what the fit explains"
        )
    before, after = cal.before.emax_m, cal.after.emax_m
    if not after * min_improvement <= before:
        reasons.append(
            f"the correction does not cut E_max,syst {min_improvement:g}x "
            f"({before * 1e3:.1f} mm -> {after * 1e3:.1f} mm)"
        )
    if cal.method == "borenstein" or reasons:  # a model fit that passes needs no small angles
        reasons += [f"before: {r}" for r in small_angle_faults(before, cal.before.side_m)]
    return reasons


def _plausible(ed: float, eb: float) -> bool:
    """Both factors finite and within the error model's 0.5 .. 2 (a sane fit start)."""
    return all(math.isfinite(v) and 0.5 <= v <= 2.0 for v in (ed, eb))


def umbmark_report(result: UmbmarkResult) -> dict[str, object]:
    """One benchmark as JSON: per direction the runs' return errors (with the true and on-board
    end positions), the centre of gravity and r_cg; E_max,syst (all m)."""
    out: dict[str, object] = {"side_m": result.side_m}
    for direction in DIRECTIONS:
        cg = result.cg(direction)
        out[direction] = {
            "runs": [_run_report(r) for r in result.of(direction)],
            "cg": {"x_m": cg.x_m, "y_m": cg.y_m},
            "r_cg_m": cg.r_m,
        }
    out["emax_syst_m"] = result.emax_m
    return out


def _run_report(run: UmbmarkRun) -> dict[str, float]:
    """A run's return error (x_m, y_m) and the two end positions it is the difference of."""
    d = run.drive
    return {"x_m": run.error_x_m, "y_m": run.error_y_m,
            "true_end_x_m": d.end.x_m, "true_end_y_m": d.end.y_m,
            "onboard_end_x_m": d.onboard_end[0], "onboard_end_y_m": d.onboard_end[1]}
