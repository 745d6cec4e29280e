"""``stallfirst`` for the streamed judge: the first pose after a silence, judged by its
neighbours as the whole log's judge does it (issue #11: ``--stream always`` PASSed +10 m on the
first pose after a stall).

The life's frames are read once more, keeping only what the rule reads (the encoder frames, the
pose halves and ODOM_STATUS), and only when a silence of the poses is there: the whole log's
steps (``check_frames`` .. ``after_stalls``) then run over those frames, so the two judges
cannot disagree on which poses were left out. A first read keeps only the ODOM_POSE_Y times;
a life without a silence is not read again."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.io.frames import FrameArrays, concat_frames
from odocan.host.judge import floodnames
from odocan.host.judge.holepages import page_numbered
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import (
    SILENCE_CYCLES,
    encoder_frames,
    flood_named,
    onboard_samples,
)
from odocan.host.judge.stallfirst import FirstVerdict, judge_left_out
from odocan.host.judge.stalls import after_stalls, signs_of_life
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec
    from odocan.sim.robot import RobotProfile

READ = ("WHEEL_ENCODERS", "ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_STATUS")


def stream_first(
    frames: Callable[[], Iterable[FrameArrays]], db: DatabaseSpec, robot: RobotProfile,
    integrator: str, bits: int, tolerance: tuple[float, float], resume: bool = True,
) -> FirstVerdict:
    """``stallfirst.judge_left_out`` of one life's frames (module docstring); ``resume``: the
    stalls' resume rule too (``stallfirst.resume_across``), as the whole log's judge runs it
    (without it, +10 mm on every pose from the first after a 1 s stall PASSed ``--stream
    always`` and FAILed ``never``: kobuki seed 269, ``delay=0.1:15,busoff=2:0.5,stall=5:1``)."""
    messages = {name: db.get_message_by_name(name) for name in READ}
    ids = np.array([m.frame_id for m in messages.values()], dtype=np.uint32)
    pose_y = messages["ODOM_POSE_Y"].frame_id
    cycle_ms = messages["WHEEL_ENCODERS"].cycle_time
    if cycle_ms is None:
        return FirstVerdict()  # no silence is found without a cycle (``stalls.after_stalls``)
    pose_t = [chunk.timestamp_s[chunk.can_id == pose_y] for chunk in frames()]
    times = np.sort(np.concatenate(pose_t)) if pose_t else np.zeros(0)
    if not bool(np.any(np.diff(times) >= (SILENCE_CYCLES - 0.5) * cycle_ms / 1000.0)):
        return FirstVerdict()
    log = concat_frames([chunk.select(np.isin(chunk.can_id, ids)) for chunk in frames()])
    decoder = BulkDecoder(db)
    _, accepted = check_frames(log, db)
    enc = page_numbered(log, decoder, encoder_frames(log, accepted, decoder))
    enc, halves = flood_named(log, accepted, decoder, enc, floodnames.of_robot(robot))
    onboard, _, sent_s = onboard_samples(log, accepted, decoder, enc, halves)
    pose_sent_s, alive_s = signs_of_life(log, accepted, decoder)  # poses: CRC right too
    kept, breaks = after_stalls(onboard, sent_s, enc, pose_sent_s, alive_s, halves)
    return judge_left_out(halves, kept, enc, Geometry.of(robot), integrator, bits, tolerance,
                          pose_sent_s, breaks if resume else None)


def logged_first_wrong(frames: FrameArrays, robot: RobotProfile, integrator: str,
                       tolerance: tuple[float, float]) -> str | None:
    """``replay``'s word on the log's own poses sent first after a silence: the replayed
    firmware is compared with the log at the frames the log's poses name, which such a pose
    may not resolve (it is then never compared); judged here by the poses around it. Why it
    FAILs, None when it does not. Only the neighbours' rule: the resume rule (``stallresume``)
    is the whole log's here, across reboots a replay does not cut (a new life's first pose is
    no resume of the old: a correct reboot FAILed, test_faults_mcu), and the replay compares
    every later pose itself."""
    from odocan.firmware.encoders import WIRE_COUNTER_BITS
    from odocan.host.protocol.dbcplan import default_plan

    verdict = stream_first(lambda: [frames], default_plan(), robot, integrator,
                           min(robot.counter_bits, WIRE_COUNTER_BITS), tolerance,
                           resume=False)
    if max(verdict.worst_position_m, verdict.worst_heading_rad) <= 0:
        return None
    return (f"the log's pose sent first after a silence at {verdict.worst_at_s:.3f} s lies "
            f"{max(verdict.worst_position_m, 0.0) * 1e3:.4g} mm, "
            f"{max(verdict.worst_heading_rad, 0.0) * 1e3:.4g} mrad beyond the poses around it "
            "(host.judge.stallfirst)")
