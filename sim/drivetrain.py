"""Two DC wheel motors with speed controllers, the wheels, and their incremental encoders.

Motor model (each wheel). The motor controller receives a rim-speed setpoint v_sp (m/s, from
MOTOR_CMD) and regulates the wheel *angular* speed to w_sp = v_sp / r_nom (the NOMINAL radius, all
the controller knows), v_sp saturated at the profile's +-max_wheel_speed_m_s (the response below
never overshoots, so no wheel's counts outrun the firmware's plausibility bound). The response is
first order with time constant tau, its rate limited to the acceleration limit a (m/s^2 at the
nominal rim, i.e. alpha = a / r_nom in rad/s^2):

    dw/dt = clip((w_sp - w) / tau, -alpha, +alpha)

This has a closed form (``evolve``): a linear ramp at +-alpha while |w_sp - w| > alpha*tau, then
an exponential approach, both integrated exactly for the wheel angle. The ground sees
w * r_actual, so a diameter error (``sim.errors``) shows in the motion but not in the counts.
When no command arrives for ``command_timeout_s`` the setpoint drops to 0 (the wheel then stops
through the same dynamics), as real motor controllers do.

Encoders: count = floor(angle / (2*pi) * counts_per_rev * k) from the continuous wheel angle
(positive = wheel rolling forward), k = 1, or k = 4 with x4 quadrature decoding (all edges of
both channels: the effective counts per revolution is then 4 * counts_per_rev). The counters are
free running and wrap as unsigned 16- or 32-bit integers.

Time runs on a fixed substep grid (``substep_hz``, default 1 kHz) held as an integer substep
index, so a run is exactly reproducible. Segments between commands are evolved in closed form;
the per-substep wheel travel needed by the ground truth is produced lazily, vectorised with
numpy (``take_travel``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.sim.robot import RobotProfile

FloatArray = npt.NDArray[np.float64]
TAU_RAD = 2.0 * math.pi
_EXACT_FLOOR_LIMIT = float(1 << 62)  # encoder counts (floored) int64 holds, offsets added
_MANY_SEGMENTS = 32  # take_travel handles more segments than this as one array
_CACHED_SEGMENT_LENGTHS = 64  # segment lengths whose _run_segment constants are kept
_CACHED_SEGMENT_SUBSTEPS = 256  # take_travel keeps the time columns of segments up to this long


@dataclass(frozen=True)
class MotorConfig:
    """Motor controller parameters, the same for both wheels.

    Attributes:
        time_constant_s: first-order time constant tau, > 0 (default 0.05 s).
        accel_limit_mps2: acceleration limit at the nominal rim, > 0 (default 2 m/s^2).
        command_timeout_s: setpoint drops to 0 after this long without a command, > 0 (0.5 s).
    """

    time_constant_s: float = 0.05
    accel_limit_mps2: float = 2.0
    command_timeout_s: float = 0.5

    def __post_init__(self) -> None:
        """Refuse non-positive or non-finite parameters."""
        for key in ("time_constant_s", "accel_limit_mps2", "command_timeout_s"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"motor config: {key} must be positive and finite, got {value}")


def evolve(w0: float, wsp: float, alpha: float, tau: float, t: float) -> tuple[float, float]:
    """Closed form of dw/dt = clip((wsp - w)/tau, +-alpha) after ``t`` seconds (scalar).

    Args:
        w0: initial angular speed, rad/s. wsp: setpoint, rad/s.
        alpha: acceleration limit, rad/s^2 (> 0). tau: time constant, s (> 0). t: time, s (>= 0).

    Returns:
        (w, dtheta): angular speed at ``t`` (rad/s) and angle travelled since 0 (rad).
    """
    e0 = w0 - wsp
    excess = abs(e0) - alpha * tau
    t1 = excess / alpha if excess > 0.0 else 0.0  # duration of the rate-limited ramp
    s = math.copysign(alpha, e0) if excess > 0.0 else 0.0
    tr = min(t, t1)
    te = t - tr
    e1 = e0 - s * tr
    decay = -math.expm1(-te / tau)  # 1 - exp(-te/tau), exact for small te
    w = wsp + e1 * (1.0 - decay)
    dtheta = wsp * t + e0 * tr - 0.5 * s * tr * tr + e1 * tau * decay
    return w, dtheta


def angle_travelled(
    t: FloatArray, w0: FloatArray, wsp: FloatArray, alpha: float | FloatArray, tau: float
) -> FloatArray:
    """Vectorised angle part of ``evolve``: radians travelled after ``t`` s (broadcasting)."""
    e0 = w0 - wsp
    excess = np.abs(e0) - alpha * tau
    limited = excess > 0.0
    t1 = np.where(limited, excess / alpha, 0.0)
    s = np.where(limited, np.copysign(alpha, e0), 0.0)
    tr = np.minimum(t, t1)
    e1 = e0 - s * tr
    decay = -np.expm1(-(t - tr) / tau)
    result: FloatArray = wsp * t + e0 * tr - 0.5 * s * tr * tr + e1 * tau * decay
    return result


def encoder_count(angle_rad: float, counts_per_rev: int, quadrature: bool = False) -> int:
    """Unwrapped encoder count of a wheel at ``angle_rad``: floor(angle/(2 pi) * cpr * k)."""
    k = 4 if quadrature else 1
    return math.floor(angle_rad / TAU_RAD * counts_per_rev * k)


def wrap_counter(count: int, bits: int) -> int:
    """``count`` as a free-running unsigned counter of ``bits`` (16 or 32) bits."""
    return count & ((1 << bits) - 1)


class Drivetrain:
    """Both wheel motors, wheels and encoders on a fixed substep grid.

    Wheel index 0 is left, 1 is right. ``advance(n)`` moves to substep ``n`` in closed form;
    ``take_travel()`` returns the actual rim travel of every substep since the last call.
    """

    def __init__(
        self,
        profile: RobotProfile,
        actual_radii_m: tuple[float, float],
        substep_hz: int = 1000,
        quadrature: bool = False,
        config: MotorConfig | None = None,
        counter_offset: tuple[int, int] = (0, 0),
    ) -> None:
        """Motors at rest, wheel angles 0, no command yet (setpoint 0).

        ``counter_offset``: (left, right) counts the free-running counters read at angle 0 (a
        counter powers up anywhere; tests start them near a wrap).
        """
        self.profile = profile
        self.config = config or MotorConfig()
        self.substep_hz = substep_hz
        self.quadrature = quadrature
        self.counter_offset = counter_offset
        self.nominal_radii_m = (profile.wheel_radius_left_m, profile.wheel_radius_right_m)
        self._top_mps = profile.max_wheel_speed_m_s  # the motor controller's saturation
        self.actual_radii_m = actual_radii_m
        self._alpha = np.array([self.config.accel_limit_mps2 / r for r in self.nominal_radii_m])
        self._radii = np.array(actual_radii_m)
        self._alpha_l, self._alpha_r = (float(a) for a in self._alpha)
        self._timeout_substeps = max(1, round(self.config.command_timeout_s * substep_hz))
        self.substep = 0
        self.omega = [0.0, 0.0]  # rad/s
        self.angle = [0.0, 0.0]  # rad, continuous
        self.setpoint = [0.0, 0.0]  # rad/s
        self._timeout_at: int | None = None
        self._segments: list[tuple[int, float, float, float, float]] = []
        self._pending = 0
        self._local_times_cache: dict[int, FloatArray] = {}
        self._segment_constants: dict[int, tuple[float, float, float, float, float]] = {}

    def command(self, left_mps: float, right_mps: float) -> None:
        """Latch rim-speed setpoints (m/s) at the current substep and restart the timeout. A
        setpoint beyond the profile's ``max_wheel_speed_m_s`` is clamped to it (the controller
        saturates): the wheels never outrun the firmware's plausibility bound."""
        if not (math.isfinite(left_mps) and math.isfinite(right_mps)):
            raise ValueError(f"wheel speed setpoints must be finite, got {left_mps}, {right_mps}")
        top = self._top_mps
        left_mps = min(max(left_mps, -top), top)
        right_mps = min(max(right_mps, -top), top)
        self.setpoint = [left_mps / self.nominal_radii_m[0], right_mps / self.nominal_radii_m[1]]
        self._timeout_at = self.substep + self._timeout_substeps

    def advance(self, target_substep: int) -> None:
        """Evolve both wheels up to ``target_substep`` (>= the current one), timeout included."""
        while self.substep < target_substep:
            end = target_substep
            if self._timeout_at is not None and self._timeout_at < end:
                end = self._timeout_at
            self._run_segment(end - self.substep)
            if self.substep == self._timeout_at:
                self.setpoint = [0.0, 0.0]
                self._timeout_at = None

    def _run_segment(self, n: int) -> None:
        """Evolve ``n`` substeps at constant setpoints and log the segment for ``take_travel``."""
        tau = self.config.time_constant_s
        # t, decay and keep of n substeps: the same doubles each time (most segments are ticks)
        t, decay, keep, limit_l, limit_r = self._segment_constants.get(n) or self._constants(n)
        w0l, w0r = self.omega
        spl, spr = self.setpoint
        el, er = w0l - spl, w0r - spr
        if abs(el) - limit_l > 0.0 or abs(er) - limit_r > 0.0:
            wl, dl = evolve(w0l, spl, self._alpha_l, tau, t)
            wr, dr = evolve(w0r, spr, self._alpha_r, tau, t)
        else:  # neither wheel rate-limited: evolve's own operations with t1 = s = tr = 0
            # decay = -expm1(-t / tau): te = t - 0.0 = t, the same for both wheels; keep = 1 - it
            wl, wr = spl + el * keep, spr + er * keep  # e1 = e0 - 0.0 * 0.0 = e0
            dl = (spl * t + el * 0.0) + el * tau * decay  # "- 0.5 * s * tr * tr" = "- 0.0"
            dr = (spr * t + er * 0.0) + er * tau * decay
        self._segments.append((n, w0l, spl, w0r, spr))
        self._pending += n
        self.omega = [wl, wr]
        self.angle = [self.angle[0] + dl, self.angle[1] + dr]
        self.substep += n

    def _constants(self, n: int) -> tuple[float, float, float, float, float]:
        """``_run_segment``'s constants of a segment of ``n`` substeps, computed as it did
        (t = n / hz, decay = -expm1(-t / tau), keep = 1 - decay, alpha * tau per wheel), kept
        for the next one (a few lengths: a tick's, a timeout's remainder)."""
        tau = self.config.time_constant_s
        t = n / self.substep_hz
        decay = -math.expm1(-t / tau)
        constants = (t, decay, 1.0 - decay, self._alpha_l * tau, self._alpha_r * tau)
        if len(self._segment_constants) < _CACHED_SEGMENT_LENGTHS:
            self._segment_constants[n] = constants
        return constants

    @property
    def pending_substeps(self) -> int:
        """Substeps evolved but not yet returned by ``take_travel``."""
        return self._pending

    def take_travel(self) -> FloatArray:
        """Actual rim travel (m) per substep since the last call, shape (n, 2): left, right."""
        if not self._segments:
            return np.zeros((0, 2))
        segments = self._segments
        self._segments = []
        self._pending = 0
        counts = [segment[0] for segment in segments]
        if len(segments) > _MANY_SEGMENTS:  # a block run ahead: the segments as one array
            theta = self._many_angles(segments, counts)
        elif self._all_unlimited(segments):
            theta = self._unlimited_angles(segments)
        else:
            theta = self._angles(segments)
        step = np.empty_like(theta)  # the angle of each substep, from 0 at a segment's start
        np.subtract(theta[1:], theta[:-1], out=step[1:])
        if len(set(counts)) == 1:  # segments start every n substeps: a strided view
            step[:: counts[0]] = theta[:: counts[0]]
        else:
            starts = list(itertools.accumulate(counts, initial=0))[:-1]
            step[starts] = theta[starts]
        step *= self._radii
        return step

    def _many_angles(
        self, segments: list[tuple[int, float, float, float, float]], counts: list[int]
    ) -> FloatArray:
        """``_unlimited_angles`` or ``_angles`` of many segments, bit for bit: the per-segment
        scalars (the rate-limit test, e0 * 0, e0 * tau) as whole columns, the same IEEE
        operations on the same doubles as the Python floats there."""
        # np.array(segments), the same doubles, without a Python object per row (5 columns)
        seg = np.fromiter(itertools.chain.from_iterable(segments), np.float64,
                          count=5 * len(segments)).reshape(-1, 5)
        w0, wsp = seg[:, 1::2], seg[:, 2::2]  # columns (left, right)
        e0 = w0 - wsp
        tau = self.config.time_constant_s
        limits = np.array([self._alpha_l * tau, self._alpha_r * tau])
        if np.any(np.abs(e0) - limits > 0.0):
            return self._angles(segments)
        if len(set(counts)) != 1:
            return self._unlimited_angles(segments)
        n = counts[0]
        t, decay = self._local_times(n), self._local_decay(n)  # (n, 1) against (m, 1, 2)
        theta3: FloatArray = wsp[:, np.newaxis, :] * t
        theta3 += (e0 * 0.0)[:, np.newaxis, :]
        theta3 += (e0 * tau)[:, np.newaxis, :] * decay
        return theta3.reshape(-1, 2)

    def _angles(self, segments: list[tuple[int, float, float, float, float]]) -> FloatArray:
        """Angle travelled since each segment's start, per substep (n, 2): the general case."""
        counts = [n for n, *_ in segments]
        t = np.concatenate([self._local_times(n) for n in counts])  # (n, 1): s since each start
        seg = np.array(segments)
        w0 = np.repeat(seg[:, 1::2], counts, axis=0)  # columns w0l, w0r
        wsp = np.repeat(seg[:, 2::2], counts, axis=0)  # columns spl, spr
        return angle_travelled(t, w0, wsp, self._alpha, self.config.time_constant_s)

    def _all_unlimited(self, segments: list[tuple[int, float, float, float, float]]) -> bool:
        """No wheel of any segment starts rate-limited (``angle_travelled``'s ``excess > 0``,
        the same IEEE operations on Python floats): the common case of a smooth drive."""
        limit_l = self._alpha_l * self.config.time_constant_s
        limit_r = self._alpha_r * self.config.time_constant_s
        return not any(
            abs(w0l - spl) - limit_l > 0.0 or abs(w0r - spr) - limit_r > 0.0
            for _, w0l, spl, w0r, spr in segments
        )

    def _unlimited_angles(
        self, segments: list[tuple[int, float, float, float, float]]
    ) -> FloatArray:
        """``angle_travelled`` when no wheel is rate-limited, bit for bit: there ``t1 = s = tr
        = 0`` and ``e1 = e0``, so each angle is ``(wsp t + e0 * 0) + (e0 tau) decay(t)`` (``- 0``
        changes no bit, ``e0 * 0`` keeps the sign of a zero). Per segment the scalars (wsp,
        e0 * 0, e0 tau) on Python floats, per substep the cached columns of t and ``decay(t) =
        -expm1(-t / tau)``: four whole-array operations instead of about twenty."""
        tau = self.config.time_constant_s
        rows = [
            (spl, spr, (w0l - spl) * 0.0, (w0r - spr) * 0.0, (w0l - spl) * tau, (w0r - spr) * tau)
            for _, w0l, spl, w0r, spr in segments
        ]
        counts = [n for n, *_ in segments]
        per_segment = np.array(rows)
        if len(set(counts)) == 1:  # equal segments (one per tick): (m, n, 2) by broadcasting
            n = counts[0]
            grid = per_segment[:, np.newaxis, :]  # (m, 1, 6) against the (n, 1) columns
            theta3: FloatArray = grid[..., 0:2] * self._local_times(n)
            theta3 += grid[..., 2:4]
            theta3 += grid[..., 4:6] * self._local_decay(n)
            return theta3.reshape(-1, 2)
        per_substep = np.repeat(per_segment, counts, axis=0)
        t = np.concatenate([self._local_times(n) for n in counts])
        decay = np.concatenate([self._local_decay(n) for n in counts])
        theta: FloatArray = per_substep[:, 0:2] * t
        theta += per_substep[:, 2:4]
        theta += per_substep[:, 4:6] * decay
        return theta

    def _local_decay(self, n: int) -> FloatArray:
        """Column ``-expm1(-t / tau)`` of ``_local_times(n)``, as ``angle_travelled`` computes
        it with ``tr = 0`` (cached with the times)."""
        key = -n
        column = self._local_times_cache.get(key)
        if column is None:
            column = -np.expm1(-self._local_times(n) / self.config.time_constant_s)
            if n <= _CACHED_SEGMENT_SUBSTEPS:
                self._local_times_cache[key] = column
        return column

    def _local_times(self, n: int) -> FloatArray:
        """Column (k / substep_hz for k = 1 .. n); short ones cached (most span one tick)."""
        column = self._local_times_cache.get(n)
        if column is None:
            column = (np.arange(1, n + 1) / self.substep_hz)[:, np.newaxis]
            if n <= _CACHED_SEGMENT_SUBSTEPS:
                self._local_times_cache[n] = column
        return column

    def encoder_counts(self) -> tuple[int, int]:
        """Raw (left, right) encoder counters, wrapped to ``profile.counter_bits`` (unsigned):
        ``wrap_counter(offset + encoder_count(angle, cpr, quadrature), bits)`` inlined (it runs
        every tick; the same operations in the same order)."""
        cpr = self.profile.counts_per_rev
        k = 4 if self.quadrature else 1
        mask = (1 << self.profile.counter_bits) - 1
        left0, right0 = self.counter_offset
        angle_l, angle_r = self.angle
        floor = math.floor
        return (
            (left0 + floor(angle_l / TAU_RAD * cpr * k)) & mask,
            (right0 + floor(angle_r / TAU_RAD * cpr * k)) & mask,
        )

    def encoder_counts_at(self, angles: list[list[float]]) -> list[tuple[int, int]]:
        """``encoder_counts`` at each of ``angles`` (the wheels' ``angle`` at some substeps),
        computed at once: the same IEEE operations on the same doubles element by element, the
        floor exact while |angle| is below 2^62 counts (else each one as ``encoder_counts``)."""
        cpr = self.profile.counts_per_rev
        k = 4 if self.quadrature else 1
        # np.array(angles), the same doubles, without its shape discovery over the pairs
        # (~2.5x faster on a block's 100 pairs of Python floats)
        grid = np.fromiter(itertools.chain.from_iterable(angles), np.float64,
                           count=2 * len(angles)).reshape(-1, 2)
        counts = np.floor(grid / TAU_RAD * cpr * k)
        if not np.all(np.abs(counts) < _EXACT_FLOOR_LIMIT):  # NaN, inf or beyond int64's reach
            return [self._counts_of(angle) for angle in angles]
        wrapped = (counts.astype(np.int64) + np.array(self.counter_offset, dtype=np.int64)) & (
            (1 << self.profile.counter_bits) - 1
        )
        left, right = wrapped.T.tolist()
        return list(zip(left, right, strict=True))

    def _counts_of(self, angle: list[float]) -> tuple[int, int]:
        """``encoder_counts`` with the wheels at ``angle`` (the state left as it was)."""
        now, self.angle = self.angle, angle
        try:
            return self.encoder_counts()
        finally:
            self.angle = now

    def wheel_speeds_mps(self) -> tuple[float, float]:
        """Actual (left, right) ground speeds of the wheel rims, m/s (omega * actual radius)."""
        return (
            self.omega[0] * self.actual_radii_m[0],
            self.omega[1] * self.actual_radii_m[1],
        )
