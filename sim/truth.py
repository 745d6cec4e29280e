"""Ground truth: the continuous kinematic model integrated with exact circular arcs.

The model is seed 000's eq. 16 with the ACTUAL geometry:

    xdot = v cos(phi),  ydot = v sin(phi),  phidot = omega,
    v = (v_R + v_L) / 2,  omega = (v_R - v_L) / b_actual.

Within one substep (>= 1 kHz) each wheel's ground speed is taken as constant (its mean over the
substep, i.e. ds/dt), so the motion is an exact circular arc. With ds the centre travel and
dtheta = (ds_R - ds_L)/b the heading change, the arc's chord is ds * sin(dtheta/2)/(dtheta/2)
along the midpoint heading phi + dtheta/2; the ratio is evaluated by its Taylor series near 0, so
straight motion (dtheta -> 0) and spin in place (ds = 0) need no special case.

Sums run as sequential left folds (``np.cumsum`` with the running value prepended), so the result
is bit-identical however the substeps are batched. The heading is accumulated unwrapped and
wrapped to (-pi, pi] only when reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.sim.pose import Pose, wrap_angle

FloatArray = npt.NDArray[np.float64]
_SMALL_HALF_ANGLE = 1e-4  # below this, sin(h)/h = 1 - h^2/6 to better than 1e-17


@dataclass(frozen=True)
class TruthPose:
    """Ground-truth pose of the wheel-axle midpoint at one instant (``pose``: its plain
    ``sim.pose.Pose``).

    Attributes:
        t_s: simulated time, s.
        x_m, y_m: position in the start frame (x forward at start, y to the left), m.
        heading_rad: heading, wrapped to (-pi, pi], counter-clockwise positive.
        distance_m: distance travelled by the axle midpoint, sum of |ds| per substep, m.
    """

    t_s: float
    x_m: float
    y_m: float
    heading_rad: float
    distance_m: float

    @property
    def pose(self) -> Pose:
        """x_m, y_m and the heading in (-pi, pi] as a plain ``Pose``."""
        return Pose(self.x_m, self.y_m, self.heading_rad)


@dataclass(frozen=True)
class TruthTrace:
    """Ground truth sampled every ``stride`` substeps: equal-length float64 arrays."""

    t_s: FloatArray
    x_m: FloatArray
    y_m: FloatArray
    heading_rad: FloatArray
    distance_m: FloatArray


def chord_factor(dtheta: FloatArray) -> FloatArray:
    """sin(dtheta/2)/(dtheta/2): chord length over arc length, 1 at dtheta = 0."""
    return _chord_factor_of_half(0.5 * dtheta)


def _chord_factor_of_half(half: FloatArray) -> FloatArray:
    """``chord_factor`` of ``2 * half`` (``half = 0.5 * dtheta``, which the caller keeps)."""
    small = np.abs(half) < _SMALL_HALF_ANGLE
    if not np.count_nonzero(small):  # the common case when turning: no series term to patch in
        result: FloatArray = np.sin(half) / half
        return result
    safe = np.where(small, 1.0, half)
    result = np.where(small, 1.0 - half * half / 6.0, np.sin(safe) / safe)
    return result


class GroundTruth:
    """Integrates the actual wheel ground travel into the true pose, substep by substep."""

    def __init__(self, wheelbase_m: float, substep_hz: int, trace_stride: int = 0) -> None:
        """Start at the origin, heading 0.

        Args:
            wheelbase_m: ACTUAL wheelbase, m (> 0).
            substep_hz: substep rate, Hz (for the time stamps).
            trace_stride: record the pose every this many substeps (0 = no trace).
        """
        self.wheelbase_m = wheelbase_m
        self.substep_hz = substep_hz
        self.trace_stride = trace_stride
        self.substep = 0
        self.x_m = 0.0
        self.y_m = 0.0
        self.heading_unwrapped_rad = 0.0
        self.distance_m = 0.0
        self._trace: list[FloatArray] = []
        if trace_stride:
            self._trace.append(np.zeros((5, 1)))

    def advance(self, ds_m: FloatArray) -> None:
        """Integrate substeps of ground travel ``ds_m`` (shape (n, 2): left, right; m)."""
        if ds_m.shape[0]:
            self.advance_folds(ds_m)

    def advance_folds(self, ds_m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``advance`` over n >= 1 substeps, returning its folds: (x, y, distance) of shape
        (3, n + 1) and the unwrapped heading (n + 1,), index 0 the state before the first
        substep, index i the state after substep i (``sim.lookahead`` reads a block's poses).

        Each sum is a sequential left fold (``np.cumsum`` in place over a row that starts with
        the running value), so batching never changes a bit; one preallocated row per fold
        keeps the small-array calls few (this runs at every SIM_TRUTH).
        """
        n = ds_m.shape[0]
        ds_l, ds_r = ds_m[:, 0], ds_m[:, 1]
        ds = 0.5 * (ds_r + ds_l)
        heading = np.empty(n + 1)
        heading[0] = self.heading_unwrapped_rad
        dtheta = heading[1:]  # (ds_r - ds_l) / b, computed in place before the fold
        np.subtract(ds_r, ds_l, out=dtheta)
        dtheta /= self.wheelbase_m
        half = 0.5 * dtheta  # the midpoint heading's and the chord factor's half angle
        heading.cumsum(out=heading)  # np.cumsum without its Python wrapper: the same fold
        mid = heading[:-1] + half
        chord = ds * _chord_factor_of_half(half)
        folds = np.empty((3, n + 1))
        folds[:, 0] = (self.x_m, self.y_m, self.distance_m)
        np.multiply(chord, np.cos(mid), out=folds[0, 1:])
        np.multiply(chord, np.sin(mid), out=folds[1, 1:])
        np.abs(ds, out=folds[2, 1:])
        folds.cumsum(axis=1, out=folds)
        x, y, dist = folds
        if self.trace_stride:
            self._record(x, y, heading, dist)
        self.x_m, self.y_m, self.distance_m = folds[:, -1].tolist()
        self.heading_unwrapped_rad = heading.item(-1)
        self.substep += n
        return folds, heading

    def _record(self, x: FloatArray, y: FloatArray, h: FloatArray, d: FloatArray) -> None:
        """Keep the states (index 1..n of the folds) that fall on the trace stride."""
        n = x.size - 1
        first = (-(self.substep + 1)) % self.trace_stride + 1  # first index on the stride
        idx = np.arange(first, n + 1, self.trace_stride)
        t = (self.substep + idx) / self.substep_hz
        self._trace.append(np.stack((t, x[idx], y[idx], h[idx], d[idx])))

    def pose(self) -> TruthPose:
        """The current pose, heading wrapped to (-pi, pi] (``sim.pose.wrap_angle``)."""
        return TruthPose(
            t_s=self.substep / self.substep_hz,
            x_m=self.x_m,
            y_m=self.y_m,
            heading_rad=wrap_angle(self.heading_unwrapped_rad),
            distance_m=self.distance_m,
        )

    def trace(self) -> TruthTrace:
        """Poses recorded every ``trace_stride`` substeps so far (empty without a trace)."""
        data = np.concatenate(self._trace, axis=1) if self._trace else np.zeros((5, 0))
        heading = np.pi - np.mod(np.pi - data[3], 2.0 * np.pi)
        return TruthTrace(data[0], data[1], data[2], heading, data[4])
