"""The pose's uncertainty: the worst-case position error of the steps integrated across more than
one encoder period, summed since the last set-pose (issue #11, point 5).

A step spanning n > 1 periods (lost frames, a stall's backlog merged into one step) is integrated
as one arc (EXACT), chord (RK2) or Euler step, but the wheels' path inside it is unknown. Its
end heading is exact (the heading is the exact sum of the counts' constants, whatever the path),
so only the position is uncertain. Over tau = n * T with the wheels' rim speeds |v| <= V (the
configured ``max_wheel_speed_mm_s``) and rim accelerations |a| <= A (``MAX_WHEEL_ACCEL_MM_S2``),
and with d, dtheta the step's travel and heading change, b the wheelbase, the end position of
every such path is within

* ``2 V tau`` of the integrated one (each lies within V tau of the start), and within
* ``A tau^2 (|d| + A tau^2 / 2) / (6 b) + A tau^2 |dtheta| / 12`` of the constant-speed arc
  (each wheel's travel leaves its constant-speed line by at most A t (tau - t) / 2, so the
  heading leaves the arc's by at most A t (tau - t) / b and the centre's travel by half the sum;
  integrated over the step, the second term by parts), plus the integrator's own distance from
  that arc: 0 (EXACT), ``|d| dtheta^2 / 24`` (RK2: the chord factor sin(u)/u, u = dtheta/2),
  ``|d| |dtheta| / 2`` more for EULER (its heading is the step's end, not its middle).

The bound taken is the smaller, rounded up to whole micrometres (tests/test_pose_uncertainty.py
proves it against brute-force float64 paths). A single lost frame on kobuki at 0.3 m/s turning
1 rad/s: ~5 um. The 2 s stall the last trial found (kobuki, 149.7 mm off, OK again after
110 ms): 2.8 m.

The sum saturates at u32 um; past ``UNCERTAINTY_TOLERANCE_UM`` the firmware goes DEGRADED
(POSE_UNCERTAIN, a sticky bit), latched until ODOM_SET_POSE APPLY, which restarts the sum.

C: ``merged_step_bound_um`` and ``add_merged_step`` in firmware/c/ecu.c.
"""

from __future__ import annotations

from odocan.firmware.config import ENCODER_PERIOD_US, Integrator, RobotParams
from odocan.firmware.fixmath import I64_MIN, U32_MAX
from odocan.firmware.health import Health

# The fastest a wheel's rim speed can change (mm/s^2): the robots' drivetrain limit (2 m/s^2 at
# the nominal rim, sim/drivetrain.py DrivetrainConfig.accel_limit_mps2, which no shipped profile
# changes). A build-time constant: ODOM_CONFIG has no field for it yet, so a robot that
# accelerates harder needs a build with its own. At twice the limit (4 m/s^2) an hour of random
# driving with 1 % of the frames lost would sum to ~57 mm on kobuki (60 s measured, 0.955 mm).
MAX_WHEEL_ACCEL_MM_S2 = 2_000
# The position uncertainty past which the firmware stops saying OK (um): 50 mm, above what an
# hour's random drive with 1 % of its frames lost sums to (bench/uncertainty.py: kobuki 22.7 mm,
# pmir 18.8 mm, 3688 frames lost each; no faults: 0 in every scenario),
# far below the 149.7 mm the 2 s stall left unflagged (its bound: metres).
UNCERTAINTY_TOLERANCE_UM = 50_000
# Steps longer than this take the speed bound alone (keeps A tau^2 products below 2^63).
ACCEL_PERIODS_MAX = 64
TWO_PI_URAD_CEIL = 6_283_186  # ceil(2 pi 10^6)


def _ceil_div(num: int, den: int) -> int:
    """ceil(num / den) of u64 ``num`` >= 0, ``den`` > 0. C: ``(num + den - 1u) / den``."""
    return (num + den - 1) // den


def merged_step_bound_um(
    periods: int,
    ds_q49_m: int,
    dheading_bam64: int,
    dheading_turns: int,
    params: RobotParams,
) -> int:
    """The worst-case position error (um, u64) of one step of ``periods`` (>= 2, u16) encoder
    periods whose travel is ``ds_q49_m`` (i64, Q49 m) and heading change ``dheading_bam64`` (i64
    BAM64) plus ``dheading_turns`` whole turns (see the module docstring). Products < 2^63."""
    speed_um = 20 * params.max_wheel_speed_mm_s * periods  # 2 V tau: < 2^37
    if dheading_turns != 0 or periods > ACCEL_PERIODS_MAX or ds_q49_m == I64_MIN:
        return speed_um
    tau_us = periods * ENCODER_PERIOD_US  # <= 640 000
    at2_um = _ceil_div(MAX_WHEEL_ACCEL_MM_S2 * tau_us * tau_us, 1_000_000_000)  # < 2^21
    ds_abs = -ds_q49_m if ds_q49_m < 0 else ds_q49_m  # (uint64_t)
    d_um = ((ds_abs >> 29) * 1_000_000 >> 20) + 1  # rounded up; |ds| < 2^57: < 2^50
    th_abs = -dheading_bam64 if dheading_bam64 < 0 else dheading_bam64  # <= 2^63 (u64)
    th_urad = ((th_abs >> 32) * TWO_PI_URAD_CEIL >> 32) + 1  # <= 3.2e6
    b_um = params.wheelbase_nm // 1_000  # >= 10 000, rounded down (a larger bound)
    bound = _ceil_div(at2_um * (d_um + (at2_um >> 1) + 1), 6 * b_um)
    bound += _ceil_div(at2_um * th_urad, 12_000_000)
    integrator = params.integrator
    if integrator != Integrator.EXACT:
        d_th = _ceil_div(d_um * th_urad, 1_000_000)  # |d| |dtheta| (um): < 2^48
        bound += _ceil_div(d_th * th_urad, 24_000_000)
        if integrator == Integrator.EULER:
            bound += _ceil_div(d_th, 2)
    return bound if bound < speed_um else speed_um


class PoseUncertainty:
    """The summed bound since the last set-pose (C: a u32 in the ECU) and its tolerance."""

    __slots__ = ("_health", "params", "tolerance_um", "uncertainty_um")

    def __init__(self, health: Health, params: RobotParams) -> None:
        self._health = health
        self.params = params  # the configuration applied (ODOM_CONFIG APPLY replaces it)
        self.tolerance_um = UNCERTAINTY_TOLERANCE_UM  # u32
        self.uncertainty_um = 0  # u32, saturated

    def merged_step(
        self, periods: int, ds_q49_m: int, dheading_bam64: int, dheading_turns: int
    ) -> None:
        """A step of ``periods`` > 1 was integrated: add its bound; past the tolerance,
        DEGRADED (POSE_UNCERTAIN), latched until a set-pose."""
        bound = merged_step_bound_um(
            periods, ds_q49_m, dheading_bam64, dheading_turns, self.params
        )
        total = self.uncertainty_um + bound  # < 2^33 + 2^37
        self.uncertainty_um = total if total < U32_MAX else U32_MAX
        if self.uncertainty_um > self.tolerance_um:
            self._health.pose_uncertain()

    def pose_set(self) -> None:
        """ODOM_SET_POSE APPLY: the pose is given again, its uncertainty restarts at 0."""
        self.uncertainty_um = 0
