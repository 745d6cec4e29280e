"""Where UMBmark's figures stop meaning what Borenstein's equations read in them, and why the
firmware refuses a corrected geometry (issue #11 point 2).

**Small-angle bound.** Borenstein & Feng's equations (``umbmark`` module docstring) are first
order in the turn error alpha and the side's heading drift beta: x_cw = -2L(alpha + beta) holds
while the angles are small, i.e. while the return errors are small against the side L. On a 1 cm
wheelbase robot E_d = 1.01 curls a 4 m side through about 4 rad: the return errors reach 4.7 m,
Borenstein's E_b reads 0.79 for 1.02 and the model fit starts from it. A benchmark whose
E_max,syst / L exceeds SMALL_ANGLE_BOUND (0.25: angles of about 0.06 rad, second-order terms of
a few % of the first) is outside the model: ``umbmark`` and ``calibrate --method borenstein``
say so (exit 1) and name a smaller square; the model fit needs no small angles (judged by its
residual and the improvement), so ``calibrate`` names the bound only beside another reason.
The shipped profiles at the default errors on the default 4 m square are inside it
(kobuki 0.15, pmir 0.12); pmir on a 16 m square is not (0.36: Borenstein's E_b 0.998 for 1.01).

**Refused correction.** The firmware answers an out-of-range ODOM_CONFIG with NACK OUT_OF_RANGE
and nothing else; ``refused_parameters`` names which of the corrected values lies outside the
firmware's own ranges (``firmware.config``), with the value and the range.
"""

from __future__ import annotations

from odocan.firmware.config import (
    NM_PER_M,
    WHEEL_RADIUS_MAX_NM,
    WHEEL_RADIUS_MIN_NM,
    WHEELBASE_MAX_NM,
    WHEELBASE_MIN_NM,
)

SMALL_ANGLE_BOUND = 0.25  # E_max,syst / L beyond which Borenstein's first-order model fails


def small_angle_faults(emax_m: float, side_m: float) -> list[str]:
    """The reason (one) a benchmark of E_max,syst ``emax_m`` on a square of side ``side_m`` is
    beyond Borenstein's small-angle model; empty when E_max,syst / L <= SMALL_ANGLE_BOUND."""
    ratio = emax_m / side_m
    if ratio <= SMALL_ANGLE_BOUND:
        return []
    side_within_m = side_m * SMALL_ANGLE_BOUND / ratio
    return [
        f"the return errors are beyond UMBmark's small-angle model: E_max,syst "
        f"{emax_m * 1e3:.1f} mm is {ratio:.3g} of the {side_m:g} m side (bound "
        f"{SMALL_ANGLE_BOUND:g}); Borenstein's E_d, E_b do not follow from them: run a smaller "
        f"square (--side of about {side_within_m:.2g} m or less)"
    ]


def refused_parameters(
    radius_left_m: float, radius_right_m: float, wheelbase_m: float
) -> list[str]:
    """Each corrected value outside the firmware's range: its name, value and the range (mm)."""
    values = (
        ("left wheel radius", radius_left_m, WHEEL_RADIUS_MIN_NM, WHEEL_RADIUS_MAX_NM),
        ("right wheel radius", radius_right_m, WHEEL_RADIUS_MIN_NM, WHEEL_RADIUS_MAX_NM),
        ("wheelbase", wheelbase_m, WHEELBASE_MIN_NM, WHEELBASE_MAX_NM),
    )
    mm_per_nm = 1e3 / NM_PER_M
    return [
        f"{name} {value_m * 1e3:.6g} mm is outside the firmware's range "
        f"{low_nm * mm_per_nm:g} .. {high_nm * mm_per_nm:g} mm"
        for name, value_m, low_nm, high_nm in values
        if not low_nm <= round(value_m * NM_PER_M) <= high_nm
    ]
