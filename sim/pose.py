"""The plain planar pose every layer above the firmware shares, and the one angle wrap.

``Pose`` is a value: x and y in metres in the start frame (x forward at start, y to the left) and
the heading in radians, counter-clockwise positive. Whoever makes one says which heading it
holds: the ground truth's ``TruthPose.pose`` wraps it to (-pi, pi], the on-board pose the host
pairs from ODOM_POSE_X/Y (``host.protocol.pose``) and the float64 reference keep it cumulative
(turns counted). Types that carry more are named for what they carry: ``sim.truth.TruthPose``
(time and distance travelled), ``host.judge.livepose.FramePose`` (the encoder frame it is of).

``wrap_angle`` is the one wrap of an angle to (-pi, pi] (the host's outputs, the truth, the
trackers): IEEE ``remainder`` by a full turn is exact, so the only rounding is the turn's own
(2 pi as a float), and -pi, which ``remainder`` may return, is moved to +pi.
"""

from __future__ import annotations

import math
from typing import NamedTuple

TURN_RAD = 2.0 * math.pi


class Pose(NamedTuple):
    """A pose in SI units: ``x_m``, ``y_m`` (m) and ``heading_rad`` (rad, counter-clockwise)."""

    x_m: float
    y_m: float
    heading_rad: float


def wrap_angle(angle_rad: float) -> float:
    """``angle_rad`` wrapped to (-pi, pi] (rad)."""
    wrapped = math.remainder(angle_rad, TURN_RAD)  # [-pi, pi], exact
    return math.pi if wrapped <= -math.pi else wrapped
