"""The live judge's start fit (``host.judge.tracking``): the reference's start narrowed as the
drive goes, in constant memory, as ``host.judge.reference_path`` fits it over a whole log.

A live reference starts at the first on-board pose it hears (its *anchor* ``A``), whose position
and heading are rounded to half an LSB of the pose signals. The firmware's true start is
``A + s`` with heading ``h_first + d``, ``|s_x|, |s_y| <= POSITION_LSB_M / 2`` and
``|d| <= HEADING_LSB_RAD / 2``. The raw reference ``r_k`` (integrated from ``A`` at ``h_first``)
is corrected to

    C(r_k) = A + s + R(d) (r_k - A),    heading: r_h + d

with, after every on-board sample (fed before it is judged, as ``analyze`` fits over the samples
it judges):

* ``d`` the least-squares rotation of the path about the start onto the on-board positions
  (``reference_path._rotation_fit``'s, the start position eliminated; here in closed form, the
  2-D Procrustes angle ``atan2(sum q_c x p_c, sum q_c . p_c)`` of the centred paths, from
  running sums), kept within the running overlap of the heading offsets' rounding intervals
  (``reference_path._start_pose``'s ``lo``, ``hi``), weighed against that interval by its
  spread (``bounded_mean``: the mean of the fit's normal, deviation ``ROUNDING_SIGMA_M /
  sqrt(sum |q_c|^2)``, restricted to the interval): the interval's middle while the path has
  no lever arm, the fit once its lever arm outweighs the rounding. Clamped alone, a fit over a
  few centimetres (mostly the positions' rounding) sat at an edge of the interval, up to 0.79
  heading LSB from the firmware's heading after an unseen restart
  (``tests/test_live_unseen_restart.py``);
* ``s`` the least-squares position given ``d``, kept within the running overlap of the samples'
  position rounding intervals, each widened by what the heading interval of its time could turn
  it (``|q| (hi - lo) / 2``): every interval holds a correct firmware's start, so their overlap
  does.

Each interval is widened by the firmware's own drift from float64 along the path fed
(``POSITION_DRIFT_PER_M``, ``HEADING_DRIFT_RAD_PER_M``: 0.1 um and 2e-15 rad per metre). A sample
whose intervals leave no overlap cannot come from a correct firmware: it is not fed
(``refused``), and the samples after it are, as before it: every sample fed narrows the
intervals, which hold a correct firmware's start, so the fit never absorbs an error bigger than
the rounding. (The fit used to freeze at such a sample: a firmware X 3 LSB off at one pose 10
samples into an unseen restart's new start left the reference with 10 samples' rotation, 0.82
LSB off the independent odometry 100 frames on, and the correct samples there were latched as
an episode of 0.127 mm: ``tests/test_live_fit_refused.py``.) Running
sums only: O(1) memory and a few dozen float operations per sample. A reference that starts at
the power-up pose (0, 0, 0) is exact (``C`` the identity), as ``analyze`` takes it. After a
stall's placement (``rebase``) the correction is taken into the reference and the fit goes on
from the placed pose: the heading interval carried, and the rotation's evidence (its least
squares and the spread behind it: the heading goes on across a placement, one rotation fits
every segment, as ``analyze`` fits a life's), the position within a pose's rounding of it.
Started afresh, the rotation after a placement had only the centimetres since, and sat up to
0.48 heading LSB off where the segments before had it to 0.02.

``pose_wrong`` is the verdict's rule, ``analyze``'s: beyond one LSB of position (after the loss
allowance) or of heading.
"""

from __future__ import annotations

import math

from odocan.host.judge.livepose import FramePose
from odocan.host.judge.reference import ReferenceOdometry
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M

HALF_POSITION_M = 0.5 * POSITION_LSB_M + 1e-9  # a pose's rounding, plus the firmware's nm
HALF_HEADING_RAD = 0.5 * HEADING_LSB_RAD + 1e-12
# ... plus the firmware's drift from float64 per metre of path: measured 4.3e-11 m and 5.2e-16
# rad per metre on bench/judge_error.py's 112 km drives (3.3-4.8 um, 5.9e-11 rad at the end)
POSITION_DRIFT_PER_M = 1e-10
HEADING_DRIFT_RAD_PER_M = 2e-15
# one sample's position rounding as a deviation (m per axis: uniform over one LSB), which
# weighs the rotation's least-squares fit against its interval (``bounded_mean``)
ROUNDING_SIGMA_M = POSITION_LSB_M / math.sqrt(12.0)
_SQRT_HALF = math.sqrt(0.5)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_TINY_MASS = 1e-300
_PI = math.pi
_TURN = 2.0 * math.pi


def bounded_mean(fit: float, sigma: float, bounds: tuple[float, float]) -> float:
    """The mean of a normal (mean ``fit``, deviation ``sigma``) restricted to ``bounds`` (lo,
    hi): a least-squares estimate weighed against the interval the rounding proves. A short
    lever arm (``sigma`` wide against the interval) keeps about its middle instead of the edge
    the noise pulls the estimate to; a long one (``sigma`` narrow) its fit, clamped."""
    lo, hi = bounds
    if not sigma > 0.0 or hi <= lo:
        return min(max(fit, lo), hi)
    a, b = (lo - fit) / sigma, (hi - fit) / sigma
    if a > 0.0:  # the tail above: erfc keeps its mass from cancelling
        mass = 0.5 * (math.erfc(a * _SQRT_HALF) - math.erfc(b * _SQRT_HALF))
    else:
        mass = 0.5 * (math.erfc(-b * _SQRT_HALF) - math.erfc(-a * _SQRT_HALF))
    if mass < _TINY_MASS:  # the fit far outside: its nearest bound
        return min(max(fit, lo), hi)
    pull = (math.exp(-0.5 * a * a) - math.exp(-0.5 * b * b)) * _INV_SQRT_2PI
    return min(max(fit + sigma * pull / mass, lo), hi)


def pose_wrong(dpos_m: float, dheading_rad: float, allowance_m: float = 0.0) -> bool:
    """``analyze``'s limit on one sample: the position error (m) beyond its loss allowance (m)
    over one LSB (0.1 mm), or the heading error (rad) over one LSB of HEADING."""
    return dpos_m - allowance_m > POSITION_LSB_M or abs(dheading_rad) > HEADING_LSB_RAD


class LiveFit:
    """The start fit of one live reference (module docstring); ``exact``: nothing to fit."""

    __slots__ = ("_fit", "_last_q", "ax", "ay", "d_hi", "d_lo", "exact", "frozen", "n",
                 "path_m", "placed", "prior", "refused", "sbx", "sby", "scross", "sdot", "sqq",
                 "sqx", "sqy", "x_hi", "x_lo", "y_hi", "y_lo")

    def __init__(self, anchor_x_m: float, anchor_y_m: float, *, exact: bool = False,
                 heading_rad: tuple[float, float] = (-HALF_HEADING_RAD, HALF_HEADING_RAD),
                 placed: bool = False, prior: tuple[float, float] = (0.0, 0.0)) -> None:
        """Anchored at the raw reference position (m) where it started; ``heading_rad``: the
        interval ``d`` is known to lie in (a correct firmware's); ``placed``: anchored at a
        placement (``carried``), not at the reference's start; ``prior``: the rotation the
        segments before it fitted (rad, relative to ``d`` = 0 here) and its weight (their
        spread, m^2: ``carried``)."""
        self.ax, self.ay, self.exact, self.frozen = anchor_x_m, anchor_y_m, exact, exact
        self.placed, self.prior = placed, prior
        self.d_lo, self.d_hi = (0.0, 0.0) if exact else heading_rad
        h = 0.0 if exact else HALF_POSITION_M
        self.x_lo, self.x_hi, self.y_lo, self.y_hi = -h, h, -h, h
        self.n, self.refused = 0, 0  # samples fed, samples refused (no overlap left)
        self.sqx = self.sqy = self.sbx = self.sby = 0.0  # sums of q and b = pose - r
        self.sqq = self.scross = self.sdot = 0.0  # sums of q.q, q x b, q.b
        self._fit: tuple[float, float, float, float, float] | None = None  # d, s_x, s_y, cos, sin
        self.path_m, self._last_q = 0.0, (0.0, 0.0)  # the path between the samples fed (m)

    @classmethod
    def start(cls, pose: FramePose) -> LiveFit:
        """The fit of a reference started at ``pose``: exact at the power-up pose (0, 0, 0)."""
        exact = pose.x_m == 0.0 and pose.y_m == 0.0 and pose.heading_rad == 0.0
        return cls(pose.x_m, pose.y_m, exact=exact)

    def feed(self, pose: FramePose, raw: FramePose) -> None:
        """One on-board sample and the raw reference at its encoder frame; not fed when it
        leaves no overlap (``refused``: module docstring)."""
        if self.frozen:
            return
        qx, qy = raw.x_m - self.ax, raw.y_m - self.ay
        path = self.path_m = self.path_m + math.hypot(qx - self._last_q[0], qy - self._last_q[1])
        self._last_q = (qx, qy)
        rounding_m = HALF_POSITION_M + POSITION_DRIFT_PER_M * path
        rounding_rad = HALF_HEADING_RAD + HEADING_DRIFT_RAD_PER_M * path
        dh = pose.heading_rad - raw.heading_rad
        if not -_PI < dh <= _PI:
            dh = math.remainder(dh, _TURN)
        d_lo, d_hi = max(self.d_lo, dh - rounding_rad), min(self.d_hi, dh + rounding_rad)
        bx, by = pose.x_m - raw.x_m, pose.y_m - raw.y_m
        # s = pose - A - R(d) q within a pose's rounding, for every d in [d_lo, d_hi]: about its
        # middle m, s moves by at most |q| (d_hi - d_lo) / 2 on each axis
        m, half = 0.5 * (d_lo + d_hi), 0.5 * (d_hi - d_lo)
        cos_m, sin_m = math.cos(m), math.sin(m)
        cx = pose.x_m - self.ax - (cos_m * qx - sin_m * qy)
        cy = pose.y_m - self.ay - (sin_m * qx + cos_m * qy)
        wx, wy = abs(qy) * half + rounding_m, abs(qx) * half + rounding_m
        x_lo, x_hi = max(self.x_lo, cx - wx), min(self.x_hi, cx + wx)
        y_lo, y_hi = max(self.y_lo, cy - wy), min(self.y_hi, cy + wy)
        if d_lo > d_hi or x_lo > x_hi or y_lo > y_hi:
            self.refused += 1  # not a correct firmware's sample: not fed, the later ones are
            return
        self.d_lo, self.d_hi, self.x_lo, self.x_hi, self.y_lo, self.y_hi = (
            d_lo, d_hi, x_lo, x_hi, y_lo, y_hi)
        self.n += 1
        self.sqx += qx
        self.sqy += qy
        self.sbx += bx
        self.sby += by
        self.sqq += qx * qx + qy * qy
        self.scross += qx * by - qy * bx
        self.sdot += qx * bx + qy * by
        self._fit = None

    def solve(self) -> tuple[float, float, float]:
        """``d`` (rad), ``s_x``, ``s_y`` (m) from the samples fed (module docstring)."""
        fit = self._current()
        return fit[0], fit[1], fit[2]

    def _current(self) -> tuple[float, float, float, float, float]:
        fit = self._fit
        if fit is not None:
            return fit
        n = self.n
        d = self._rotation()
        sx = sy = 0.0
        cos_d, sin_d = math.cos(d), math.sin(d)
        if n:
            mqx, mqy, mbx, mby = self.sqx / n, self.sqy / n, self.sbx / n, self.sby / n
            # s = mean(pose - A - R(d) q) = mean(b) + (I - R(d)) mean(q)
            sx = mbx + (1.0 - cos_d) * mqx + sin_d * mqy
            sy = mby - sin_d * mqx + (1.0 - cos_d) * mqy
            sx, sy = min(max(sx, self.x_lo), self.x_hi), min(max(sy, self.y_lo), self.y_hi)
        fit = self._fit = (d, sx, sy, cos_d, sin_d)
        return fit

    def _rotation(self) -> float:
        """``d`` (rad): the rotation the segments so far fit (``_fitted``) weighed against the
        heading interval (``bounded_mean``); the interval's middle without a lever arm."""
        fit, weight = self._fitted()
        if not weight > 0.0:
            return 0.5 * (self.d_lo + self.d_hi)
        return bounded_mean(fit, ROUNDING_SIGMA_M / math.sqrt(weight), (self.d_lo, self.d_hi))

    def _fitted(self) -> tuple[float, float]:
        """The least-squares rotation (rad) of this segment's centred path and the segments'
        before it (``prior``), each weighed by its spread (one rotation, an offset each, as
        ``analyze`` fits a life's segments), and their spread (m^2)."""
        here, spread = self._segment_fit()
        fit, weight = self.prior
        total = weight + spread
        return ((fit * weight + here * spread) / total if total > 0.0 else 0.0), total

    def _segment_fit(self) -> tuple[float, float]:
        """This segment's least-squares rotation of its centred path onto the on-board
        positions (rad: the 2-D Procrustes angle) and the path's spread (sum |q_c|^2, m^2);
        (0, 0) without a lever arm."""
        n = self.n
        if not n:
            return 0.0, 0.0
        mqx, mqy, mbx, mby = self.sqx / n, self.sqy / n, self.sbx / n, self.sby / n
        spread = self.sqq - n * (mqx * mqx + mqy * mqy)  # of the centred q
        if not spread > 0.0:
            return 0.0, 0.0
        cross = self.scross - n * (mqx * mby - mqy * mbx)  # of the centred q, b
        dot = self.sdot - n * (mqx * mbx + mqy * mby)
        return math.atan2(cross, spread + dot), spread

    def correct(self, raw: FramePose) -> FramePose:
        """``C(raw)``: the raw reference pose corrected by the fit."""
        if self.exact:
            return raw
        d, sx, sy, cos_d, sin_d = self._current()
        qx, qy = raw.x_m - self.ax, raw.y_m - self.ay
        return FramePose(raw.seq, self.ax + sx + cos_d * qx - sin_d * qy,
                         self.ay + sy + sin_d * qx + cos_d * qy, raw.heading_rad + d)

    def carried(self, anchor_x_m: float, anchor_y_m: float) -> LiveFit:
        """The fit after the reference was corrected by this one (``correct``) and placed again
        at ``anchor`` (after a stall): the heading interval goes on, less the ``d`` taken; the
        position is the placement's, within a pose's rounding (``liveplace.StallPlacer``)."""
        if self.exact:  # the heading is exact across a stall: only the position is placed
            return LiveFit(anchor_x_m, anchor_y_m, heading_rad=(0.0, 0.0), placed=True)
        d = self.solve()[0]
        fit, weight = self._fitted()  # the rotation's evidence goes on: the heading does
        return LiveFit(anchor_x_m, anchor_y_m, heading_rad=(self.d_lo - d, self.d_hi - d),
                       placed=True, prior=(fit - d, weight))

    def placed_shift_m(self) -> tuple[float, float]:
        """The position this fit moves the reference by at its anchor (``s``: dx, dy m) when
        it was anchored at a placement (``carried``): taken into the reference at the next
        placement (``rebase``), it is part of the placements' offset, bounded as they are
        (``liveplace.StallPlacer.shift``); (0, 0) for the reference's start fit, which
        ``analyze`` fits apart from the placements (``reference_path``)."""
        if not self.placed or self.exact:
            return 0.0, 0.0
        return self.solve()[1:]


def rebase(fit: LiveFit, odometry: ReferenceOdometry, kept: dict[int, FramePose],
           at: FramePose, shift: tuple[float, float] | None
           ) -> tuple[dict[int, FramePose], LiveFit, FramePose]:
    """A placement after a stall or gap at ``at`` (the corrected reference at the sample's
    frame): the reference (``odometry`` now, ``kept`` at the latest frames) corrected by ``fit``
    and moved by ``shift`` (dx, dy m) from that frame on. Returns the new ``kept``, the fit
    carried on from the placed pose, and the placed pose. ``shift`` None: nothing placed (the
    fit goes on as it was: a placement would cut its power-up exactness or its sums)."""
    if shift is None:
        return kept, fit, at
    dx, dy = shift
    now = fit.correct(FramePose(-1, odometry.x_m, odometry.y_m, odometry.heading_rad))
    odometry.place(now.x_m + dx, now.y_m + dy, now.heading_rad)
    moved = {}
    for k, raw in kept.items():
        pose = fit.correct(raw)
        moved[k] = pose if k < at.seq else pose._replace(x_m=pose.x_m + dx, y_m=pose.y_m + dy)
    return moved, fit.carried(at.x_m + dx, at.y_m + dy), at._replace(x_m=at.x_m + dx,
                                                                     y_m=at.y_m + dy)
