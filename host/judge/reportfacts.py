"""The facts of a drive's report that are not verdicts: the robot judged with, the bus time a
log covers, the real-time factor, the frames per DBC message (``host.judge.analysis``; the
streamed analysis gathers the same facts chunk by chunk, ``host.judge.stream_facts``)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec

def robot_dict(robot: RobotProfile) -> dict[str, Any]:
    return {
        "name": robot.name,
        "counts_per_rev": robot.counts_per_rev,
        "wheel_radius_left_m": robot.wheel_radius_left_m,
        "wheel_radius_right_m": robot.wheel_radius_right_m,
        "wheelbase_m": robot.wheelbase_m,
        "counter_bits": robot.counter_bits,
        "max_wheel_speed_m_s": robot.max_wheel_speed_m_s,  # the steps' and gaps' bound
    }


def covered_s(frames: FrameArrays, db: DatabaseSpec) -> float:
    """Seconds of bus time the log covers: its encoder periods (first to last encoder frame,
    plus one cycle), or the plain frame span when it has no encoder frame."""
    message = db.get_message_by_name("WHEEL_ENCODERS")
    is_encoder = frames.can_id == message.frame_id
    if not is_encoder.any() or not message.cycle_time:
        return span_s(frames)
    first = int(np.argmax(is_encoder))  # argmax stops at the first True: no gather of them all
    last = len(frames) - 1 - int(np.argmax(is_encoder[::-1]))
    stamps = frames.timestamp_s
    return float(stamps[last] - stamps[first]) + message.cycle_time / 1000.0


def span_s(frames: FrameArrays) -> float:
    """Seconds from the first to the last frame."""
    if len(frames) == 0:
        return 0.0
    return float(frames.timestamp_s[-1] - frames.timestamp_s[0])


def first_frame_s(frames: FrameArrays) -> float | None:
    """Bus time (s) of the log's first frame, None for no frame: the summary's times count from
    it (a capture's epoch seconds read as noise); the report's ``t_s`` stay bus times."""
    return float(frames.timestamp_s[0]) if len(frames) else None


def realtime(sim_s: float, wall_s: float | None) -> float | None:
    """Simulated seconds per wall-clock second."""
    if wall_s is None or wall_s <= 0:
        return None
    return sim_s / wall_s


def frame_counts(frames: FrameArrays, decoder: BulkDecoder) -> dict[str, int]:
    """Frames per DBC message in the log (whatever their E2E status)."""
    counts = {}
    for message in decoder.db.messages:
        n = len(decoder.select(frames, message.name))
        if n:
            counts[message.name] = n
    return counts


