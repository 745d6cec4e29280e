"""``odocan calibrate --report``: the calibration as JSON (README, "UMBmark and calibration")."""

from __future__ import annotations

import math

from odocan.host.experiments.umbmark import (
    Calibration,
    Correction,
    Refusal,
    UmbmarkResult,
    umbmark_report,
)
from odocan.sim.errors import ErrorModel


def calibration_report(cal: Calibration, errors: ErrorModel) -> dict[str, object]:
    """The ``odocan calibrate --report`` JSON contract (README, "UMBmark and calibration")."""
    return _report(cal, cal.estimated, errors, cal.after)


def refused_report(refusal: Refusal, errors: ErrorModel) -> dict[str, object]:
    """``calibration_report``'s keys for a calibration whose correction the firmware refused
    (``umbmark.CorrectionRefused``): no benchmark after ran, so ``after``, ``emax_after_m`` and
    ``improvement`` are null."""
    return _report(refusal, refusal.estimated, errors, None)


def _report(cal: Calibration | Refusal, estimated: tuple[float, float], errors: ErrorModel,
            after: UmbmarkResult | None) -> dict[str, object]:
    ed, eb = estimated
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
        "emax_after_m": None if after is None else after.emax_m,
        "improvement": (cal.before.emax_m / after.emax_m
                        if after is not None and after.emax_m else None),
        "before": umbmark_report(cal.before),
        "after": None if after is None else umbmark_report(after),
    }


def _geometry(c: Correction) -> dict[str, float]:
    return {"wheel_radius_left_m": c.wheel_radius_left_m,
            "wheel_radius_right_m": c.wheel_radius_right_m, "wheelbase_m": c.wheelbase_m}
