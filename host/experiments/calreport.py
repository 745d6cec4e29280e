"""``odocan calibrate --report``: the calibration as JSON (README, "UMBmark and calibration")."""

from __future__ import annotations

import math

from odocan.host.experiments.umbmark import Calibration, Correction, umbmark_report
from odocan.sim.errors import ErrorModel


def calibration_report(cal: Calibration, errors: ErrorModel) -> dict[str, object]:
    """The ``odocan calibrate --report`` JSON contract (README, "UMBmark and calibration")."""
    ed, eb = cal.estimated
    b = cal.borenstein
    return {
        "injected": {"ed": errors.ed, "eb": errors.eb, "slip": errors.slip},
        "estimated": {"ed": ed, "eb": eb, "method": cal.method},
        "borenstein": {"alpha_deg": math.degrees(b.alpha_rad), "beta_deg": math.degrees(b.beta_rad),
                       "radius_m": b.radius_m if math.isfinite(b.radius_m) else None,
                       "ed": b.ed, "eb": b.eb},
        "model": {"ed": cal.model[0], "eb": cal.model[1],
                  "fit_residual_rms_m": cal.fit_residual_m},
        "nominal": _geometry(cal.nominal),
        "corrected": _geometry(cal.corrected),
        "emax_before_m": cal.before.emax_m,
        "emax_after_m": cal.after.emax_m,
        "improvement": cal.before.emax_m / cal.after.emax_m if cal.after.emax_m else None,
        "before": umbmark_report(cal.before),
        "after": umbmark_report(cal.after),
    }


def _geometry(c: Correction) -> dict[str, float]:
    return {"wheel_radius_left_m": c.wheel_radius_left_m,
            "wheel_radius_right_m": c.wheel_radius_right_m, "wheelbase_m": c.wheelbase_m}
