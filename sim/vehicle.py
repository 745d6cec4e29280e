"""The simulated robot: drivetrain (motors, wheels, encoders) + error model + ground truth.

Time is quantised to the substep grid: a time ``t_s`` maps to substep ``floor(t_s * hz + 1e-6)``
(the 1e-6 absorbs float noise such as 0.3 * 1000 = 299.99999999999994). Between commands the
motors evolve in closed form, so ``advance_to`` and ``encoder_counts`` cost a few microseconds
whatever the step; the per-substep ground truth (exact arcs, slip noise) is computed lazily in
vectorised batches when ``truth()`` or ``truth_trace()`` is asked for, or every
``_MAX_PENDING`` substeps. Batching never changes a result: the same calls give bit-identical
encoder counts and poses however often the truth is observed.
"""

from __future__ import annotations

import math

import numpy as np

from odocan.sim.drivetrain import Drivetrain, MotorConfig
from odocan.sim.errors import ErrorModel
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import RobotProfile
from odocan.sim.truth import GroundTruth, TruthPose, TruthTrace

_MAX_PENDING = 1 << 16  # substeps held before the ground truth is brought up to date
_TIME_EPS = 1e-6  # in substeps


class VehicleError(ConfigurationError):
    """A vehicle was misconfigured or driven backwards in time."""


class Vehicle:
    """A differential-drive robot in simulation: commanded by wheel speeds, read by encoders.

    Args:
        profile: nominal robot (what the motor controller and the firmware believe).
        errors: systematic and random errors of the real robot (default: none).
        seed: seed of the numpy Generator drawing the slip noise.
        substep_hz: integer substep rate, >= 1000 Hz (exact arcs per substep).
        quadrature: x4 quadrature decoding (effective counts per rev = 4 * counts_per_rev).
        motor: motor controller parameters (default ``MotorConfig()``).
        trace_hz: also record the true pose at this rate (0 = off); must divide ``substep_hz``.
        counter_offset: (left, right) encoder counter values at start (default 0, 0).
    """

    def __init__(
        self,
        profile: RobotProfile,
        errors: ErrorModel | None = None,
        seed: int = 0,
        substep_hz: int = 1000,
        quadrature: bool = False,
        motor: MotorConfig | None = None,
        trace_hz: int = 0,
        counter_offset: tuple[int, int] = (0, 0),
    ) -> None:
        """Robot at rest at the origin, heading 0, counters 0, t = 0."""
        if isinstance(substep_hz, bool) or not isinstance(substep_hz, int) or substep_hz < 1000:
            raise VehicleError(f"substep_hz must be an integer >= 1000, got {substep_hz!r}")
        if trace_hz < 0 or (trace_hz and substep_hz % trace_hz):
            raise VehicleError(f"trace_hz must be 0 or divide {substep_hz}, got {trace_hz}")
        self.profile = profile
        self.errors = errors or ErrorModel()
        self.substep_hz = substep_hz
        self._rng = np.random.default_rng(seed)
        radii = self.errors.actual_radii_m(profile)
        self.drivetrain = Drivetrain(profile, radii, substep_hz, quadrature, motor, counter_offset)
        self._truth = GroundTruth(
            self.errors.actual_wheelbase_m(profile),
            substep_hz,
            trace_stride=substep_hz // trace_hz if trace_hz else 0,
        )

    @property
    def t_s(self) -> float:
        """Current simulated time, s (on the substep grid)."""
        return self.drivetrain.substep / self.substep_hz

    @property
    def actual_radii_m(self) -> tuple[float, float]:
        """Actual (left, right) effective wheel radii, m."""
        return self.drivetrain.actual_radii_m

    @property
    def actual_wheelbase_m(self) -> float:
        """Actual wheelbase, m."""
        return self._truth.wheelbase_m

    def _substep_of(self, t_s: float) -> int:
        """The substep index of time ``t_s``; refuses times before the current one."""
        if not math.isfinite(t_s):
            raise VehicleError(f"time must be finite, got {t_s}")
        n = math.floor(t_s * self.substep_hz + _TIME_EPS)
        if n < self.drivetrain.substep:
            raise VehicleError(f"time runs backwards: {t_s} s is before {self.t_s} s")
        return n

    def advance_to(self, t_s: float) -> None:
        """Run the simulation up to time ``t_s`` (s, >= current time, floored to the grid)."""
        drivetrain = self.drivetrain
        drivetrain.advance(self._substep_of(t_s))
        if drivetrain._pending >= _MAX_PENDING:  # pending_substeps, read every tick
            self._sync_truth()

    def command(self, left_mps: float, right_mps: float, t_s: float) -> None:
        """A MOTOR_CMD arriving at ``t_s``: advance to it, then latch the rim-speed setpoints."""
        self.advance_to(t_s)
        self.drivetrain.command(left_mps, right_mps)

    def encoder_counts(self) -> tuple[int, int]:
        """Raw (left, right) encoder counters now, wrapped unsigned to the profile's width."""
        return self.drivetrain.encoder_counts()

    def wheel_speeds_mps(self) -> tuple[float, float]:
        """Actual (left, right) wheel ground speeds now, m/s (before the random slip)."""
        return self.drivetrain.wheel_speeds_mps()

    def truth(self) -> TruthPose:
        """The true pose now."""
        self._sync_truth()
        return self._truth.pose()

    def truth_trace(self) -> TruthTrace:
        """True poses recorded at ``trace_hz`` since t = 0 (empty arrays if tracing is off)."""
        self._sync_truth()
        return self._truth.trace()

    def _sync_truth(self) -> None:
        """Integrate the ground truth over every substep the drivetrain has run ahead."""
        ds = self.drivetrain.take_travel()
        self._truth.advance(self.errors.apply_slip(ds, self._rng))
