"""Telemetry values decoded from DBC signals, rounded to what their LSB carries.

cantools decodes ``raw * scale``, so a pose X of -9 LSB goes out as ``-0.0009000000000000001``:
float noise, not information. Each field is rounded to the decimals its signal's LSB has (0.0001 m:
4, so ``-0.0009``), or, for an LSB with no finite decimal form (HEADING, 2 pi / 65536 rad), to the
decimals that move a value by at most 1e-5 LSB. Either way a consumer recovers the firmware's
raw integer exactly, ``round(value / scale)`` (``tests/test_mqtt_lsb_round.py`` decodes with
cantools and compares); the DBC is where the scales come from."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from cantools.database.can import Database

EXACT_DECIMALS = 9  # a decimal LSB has at most this many decimals
EXACT_BELOW = 2**40  # ``rounded``'s bound on a value in units of its last decimal
LSB_FRACTION = 1e-5  # otherwise rounding moves a value by at most this much of an LSB (both
# headings of a pose stay 2 pi k apart to 1e-10 rad: tests/test_conventions.py)

# payload field -> (message, signal) whose LSB it carries
POSE_FIELDS = {
    "x_m": ("ODOM_POSE_X", "X"), "y_m": ("ODOM_POSE_Y", "Y"),
    "heading_rad": ("ODOM_POSE_X", "HEADING"), "heading_unwrapped_rad": ("ODOM_POSE_X", "HEADING"),
    "linear_vel_m_s": ("ODOM_TWIST", "LINEAR_VEL"),
    "angular_vel_rad_s": ("ODOM_TWIST", "ANGULAR_VEL"), "distance_m": ("ODOM_TWIST", "DISTANCE"),
}
TRUTH_FIELDS = {
    "x_m": ("SIM_TRUTH", "X"), "y_m": ("SIM_TRUTH", "Y"),
    "heading_rad": ("SIM_TRUTH", "HEADING"), "heading_unwrapped_rad": ("SIM_TRUTH", "HEADING"),
}


def lsb_decimals(scale: float) -> int:
    """Decimals that keep every value ``raw * scale`` exact to its raw integer."""
    for decimals in range(EXACT_DECIMALS + 1):
        shifted = scale * 10**decimals
        if abs(shifted - round(shifted)) < 1e-6 * max(shifted, 1.0):
            return decimals
    return math.ceil(-math.log10(scale * LSB_FRACTION))


class LsbRounding:
    """Round the fields of ``fields`` (payload key -> DBC message and signal) in a payload."""

    def __init__(self, db: Database, fields: Mapping[str, tuple[str, str]]) -> None:
        self.decimals = {
            key: lsb_decimals(float(db.get_message_by_name(message)
                                    .get_signal_by_name(signal).scale))
            for key, (message, signal) in fields.items()
        }
        # each field with its decimals and 10 ** decimals (``rounded``)
        self._fields = tuple((key, decimals, 10**decimals)
                             for key, decimals in self.decimals.items())

    def __call__(self, payload: dict[str, Any]) -> dict[str, Any]:
        """``payload`` with its known float fields rounded (in place; returned)."""
        for key, decimals, power in self._fields:
            value = payload.get(key)
            if isinstance(value, float) and math.isfinite(value):
                payload[key] = rounded(value, decimals, power)
        return payload


def rounded(value: float, decimals: int, power: int) -> float:
    """``round(value, decimals)`` (``power``: ``10 ** decimals``), the same float, without its
    decimal conversion where it is not needed (per field of every publication): ``value *
    power`` within 1/4 of a nonzero integer ``n`` below 2 ** 40 (its float error at most 2 **
    -13) makes ``n`` the correctly rounded ``value`` in units of ``10 ** -decimals``, no tie,
    and ``n / power`` (two ints below 2 ** 53: one correctly rounded float division) the float
    nearest ``n * 10 ** -decimals``: ``round``'s result. Else (a zero keeps its sign, a value
    near a tie or too large) ``round`` itself."""
    shifted = value * power
    if -EXACT_BELOW < shifted < EXACT_BELOW:  # (an infinity, a NaN: ``round``'s)
        n = round(shifted)
        if n and -0.25 < shifted - n < 0.25:
            return n / power
    return round(value, decimals)

