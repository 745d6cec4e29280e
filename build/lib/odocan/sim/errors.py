"""Odometry error model: Borenstein's systematic errors E_d and E_b, and random wheel slip.

Systematic errors (Borenstein & Feng, UMBmark):

* ``ed`` (E_d): right/left ratio of the *actual* effective wheel diameters, with the mean diameter
  kept: actual r_R = r_R,nom * 2*E_d/(E_d+1), actual r_L = r_L,nom * 2/(E_d+1). For the usual
  profile with equal nominal radii r this is exactly r_R = r*2*E_d/(E_d+1), r_L = r*2/(E_d+1), so
  r_R/r_L = E_d and (r_R+r_L)/2 = r; with E_d = 1 every wheel is exactly its nominal radius.
* ``eb`` (E_b): actual/nominal wheelbase.

Random (non-systematic) error: ``slip``, the standard deviation (a fraction, e.g. 0.01 = 1 %) of
a multiplicative Gaussian noise applied, independently per substep and per wheel, to each wheel's
ground travel: ds_ground = ds_wheel * (1 + slip * N(0, 1)). The encoders, on the wheel shafts, do
not see it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import RobotProfile

_ED_RANGE = (0.5, 2.0)
_EB_RANGE = (0.5, 2.0)
_SLIP_RANGE = (0.0, 0.5)


class ErrorModelError(ConfigurationError):
    """An error-model specification is invalid (one-line message)."""


@dataclass(frozen=True)
class ErrorModel:
    """Systematic and random odometry errors of the simulated robot.

    Attributes:
        ed: E_d, actual right/left effective diameter ratio, 0.5 .. 2 (1 = none).
        eb: E_b, actual/nominal wheelbase, 0.5 .. 2 (1 = none).
        slip: std of the per-substep multiplicative ground-travel noise, 0 .. 0.5 (0 = none).
    """

    ed: float = 1.0
    eb: float = 1.0
    slip: float = 0.0

    def __post_init__(self) -> None:
        """Validate the ranges."""
        for key, (lo, hi) in (("ed", _ED_RANGE), ("eb", _EB_RANGE), ("slip", _SLIP_RANGE)):
            value = getattr(self, key)
            if not (math.isfinite(value) and lo <= value <= hi):
                raise ErrorModelError(f"error model: {key}={value} is outside {lo}..{hi}")

    def actual_radii_m(self, profile: RobotProfile) -> tuple[float, float]:
        """Actual (left, right) effective wheel radii in metres, E_d applied, mean kept."""
        left = profile.wheel_radius_left_m * 2.0 / (self.ed + 1.0)
        right = profile.wheel_radius_right_m * 2.0 * self.ed / (self.ed + 1.0)
        return left, right

    def actual_wheelbase_m(self, profile: RobotProfile) -> float:
        """Actual wheelbase in metres, E_b applied."""
        return profile.wheelbase_m * self.eb

    def apply_slip(
        self, ds_m: npt.NDArray[np.float64], rng: np.random.Generator
    ) -> npt.NDArray[np.float64]:
        """Ground travel from wheel travel ``ds_m`` (shape (n, 2): left, right per substep).

        Draws ``ds_m.size`` normals from ``rng`` in row order (substep by substep, left then
        right), so the stream does not depend on how the substeps are batched. With ``slip == 0``
        nothing is drawn and ``ds_m`` is returned unchanged.
        """
        if self.slip == 0.0:
            return ds_m
        noise = rng.standard_normal(ds_m.shape)
        result: npt.NDArray[np.float64] = ds_m * (1.0 + self.slip * noise)
        return result


def parse(text: str) -> ErrorModel:
    """Parse ``"ed=1.002,eb=1.01,slip=0.01"`` (any subset, any order; empty = no error).

    Raises ``ErrorModelError`` for an unknown or repeated key, a malformed item, a value that is
    not a finite number, or a value out of range.
    """
    values: dict[str, float] = {}
    for item in (part.strip() for part in text.split(",")):
        if not item:
            continue
        key, sep, raw = (s.strip() for s in item.partition("="))
        if not sep:
            raise ErrorModelError(f"error model: expected key=value, got {item!r}")
        if key not in ("ed", "eb", "slip"):
            raise ErrorModelError(f"error model: unknown key {key!r} (known: ed, eb, slip)")
        if key in values:
            raise ErrorModelError(f"error model: key {key!r} given twice")
        try:
            values[key] = float(raw)
        except ValueError:
            raise ErrorModelError(f"error model: {key}={raw!r} is not a number") from None
    return ErrorModel(**values)
