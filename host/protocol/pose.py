"""The on-board pose as the bus carries it: ODOM_POSE_X and ODOM_POSE_Y of one encoder frame.

The pose does not fit one frame (dbc/README.md): ``ODOM_POSE_X`` = {X, HEADING} and ``ODOM_POSE_Y``
= {Y, TURNS}, each naming the WHEEL_ENCODERS frame it describes by ``ENC_COUNTER``. The firmware
sends X before Y in the same tick. A pose is an X and a Y frame naming the same encoder frame, X
heard first; the unwrapped heading is ``TURNS * 2 pi + HEADING``. Pairing by time (the latest X
with the latest Y) mixes two ticks' halves whenever a frame is lost; this is the one pairing every
consumer (the analysis, the live tracker, replay, the experiments, the pytest kit) uses.

The on-board pose is a plain ``sim.pose.Pose`` whose heading is cumulative. The heading
convention of every host output (reports, MQTT, the monitor's JSON): ``heading_rad`` is wrapped
to (-pi, pi] by the one wrap, ``sim.pose.wrap_angle``, and ``heading_unwrapped_rad`` is cumulative
(turns counted), both named (``heading_fields``). Only the firmware vectors keep the firmware's
integers.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from odocan.host.protocol.busfacts import POSE_ENC_COUNTER_LAP
from odocan.sim.pose import TURN_RAD, Pose, wrap_angle

__all__ = ["COUNTER_VALUES", "Pose", "PosePairer", "heading_fields", "latest_pose", "pose_of",
           "unwrap_near", "wrap_angle"]

COUNTER_VALUES = POSE_ENC_COUNTER_LAP  # ENC_COUNTER: the E2E counter of the encoder frame named


def unwrap_near(heading_rad: float, near_rad: float) -> float:
    """``heading_rad`` plus the whole turns that bring it nearest to ``near_rad`` (rad)."""
    return near_rad + math.remainder(heading_rad - near_rad, TURN_RAD)


def heading_fields(heading_unwrapped_rad: float) -> dict[str, float]:
    """Both named headings of one pose: ``heading_rad`` in (-pi, pi] and the cumulative
    ``heading_unwrapped_rad`` (rad)."""
    return {"heading_rad": wrap_angle(heading_unwrapped_rad),
            "heading_unwrapped_rad": heading_unwrapped_rad}


def pose_of(x_frame: Mapping[str, Any], y_frame: Mapping[str, Any]) -> Pose:
    """The pose of decoded (scaled) ODOM_POSE_X and ODOM_POSE_Y signals of one encoder frame."""
    heading_rad = float(y_frame["TURNS"]) * 2.0 * math.pi + float(x_frame["HEADING"])
    return Pose(float(x_frame["X"]), float(y_frame["Y"]), heading_rad)


class PosePairer:
    """Pairs decoded pose frames as they are heard: ``on_x`` keeps the X half of each encoder
    frame (one slot per ENC_COUNTER value), ``on_y`` completes it; a Y whose X was not heard, or
    was already used, gives nothing.

    ENC_COUNTER repeats every 16 encoder frames: a Y whose X was lost would find the X of the
    frame 16 (or 32, ...) earlier in its slot. A caller that follows the encoder frames passes
    ``frame_seq``, the encoder frame each half names (its ENC_COUNTER resolved against the
    latest encoder frame heard, as ``host.judge.analysis`` does); halves naming different
    frames are never paired."""

    def __init__(self) -> None:
        self._x: list[tuple[Mapping[str, Any], int | None] | None] = [None] * COUNTER_VALUES

    def on_x(self, x_frame: Mapping[str, Any], frame_seq: int | None = None) -> None:
        """An accepted ODOM_POSE_X (decoded signals), naming encoder frame ``frame_seq``."""
        self._x[int(x_frame["ENC_COUNTER"]) % COUNTER_VALUES] = (x_frame, frame_seq)

    def on_y(self, y_frame: Mapping[str, Any], frame_seq: int | None = None) -> Pose | None:
        """An accepted ODOM_POSE_Y: the pose it completes, None when its X half is missing (or
        names another encoder frame)."""
        slot = int(y_frame["ENC_COUNTER"]) % COUNTER_VALUES
        held, self._x[slot] = self._x[slot], None
        if held is None:
            return None
        x_frame, x_seq = held
        if x_seq is not None and frame_seq is not None and x_seq != frame_seq:
            return None
        return pose_of(x_frame, y_frame)

    def feed(self, name: str, signals: Mapping[str, Any]) -> Pose | None:
        """Either half by message name; other messages are ignored."""
        if name == "ODOM_POSE_X":
            self.on_x(signals)
        elif name == "ODOM_POSE_Y":
            return self.on_y(signals)
        return None


def latest_pose(frames: Iterable[tuple[str, Mapping[str, Any]]]) -> Pose | None:
    """The last complete pose of ``(message name, decoded signals)`` in the order heard."""
    pairer, latest = PosePairer(), None
    for name, signals in frames:
        latest = pairer.feed(name, signals) or latest
    return latest
