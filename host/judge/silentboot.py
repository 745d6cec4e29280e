"""A reboot inside a silence of the firmware, with nothing on the log to name its power-up frame
(issue #11 item 5: "a FAIL must never blame a correct firmware", "a PASS must never hide a wrong
pose").

The firmware rebooted while its sends were not heard (a bus-off, a recorder that missed them);
the first summary heard after that silence tells the reboot (UPTIME going back), but neither a
count page (``reboots.page_counted_start``) nor a power-up pose (``bootnamed``) names the frame
it primed on. ``reboots.split_lives`` cut the life at that first summary: the new firmware's
poses heard between the silence's end and that summary fell in the old life (a correct firmware
FAILed, kobuki ``--seed 5 --faults busoff=4:1,reboot=4.3`` with its count pages and first
summaries gone from the log: 45.7 mm and 6.3 rad off the old life's reference), and a first
summary of UPTIME above 0 had the new life's start fitted, free to absorb an offset.

The new firmware sent nothing heard between the old one's last frame and the silence's end, so
it primed on one of the accepted encoder frames after that last frame, up to the one its first
pose names. The life starts at the first of them (``silent_start``) and is judged from the
power-up pose (0, 0, 0) on each (after the encoder frames' own silence when they had one: the
bus was off, a firmware primed before it would have its first pose placed across a gap, free to
absorb an offset; ``primed_in_silence``: ``primedon.judged_from_each``, PASS from
one, FAIL from all): power-up, its frame fitted, never a free start pose. The candidates are
tried in the order their reference agrees with the first pose heard (``MOST_TRIED`` of them:
the frame the firmware primed on agrees within its rounding; one that does not cannot pass).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapseen import crc_holds
from odocan.host.judge.primedon import FRAMES_KEY, WHY_KEY, start_pose_primed_on
from odocan.host.judge.reference import Geometry, integrate, wrap_delta
from odocan.host.judge.samples import WIRE_COUNTER_BITS, Encoders, Poses
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import RobotProfile

SILENCE_S = 0.25  # no pose nor summary of the firmware for this long: a silence (2.5 cycles)
MOST_TRIED = 8  # candidate frames judged, the best agreeing with the first pose first
KIND = "power_up_in_silence"
WHY = ("the firmware rebooted while its frames were not heard (no count page nor power-up "
       "pose names the frame it primed on): it primed on one of encoder frames {frames}")


def silent_start(frames: FrameArrays, decoder: BulkDecoder, encoders: npt.NDArray[np.intp],
                 position: int, after: int) -> int | None:
    """The position of the first accepted encoder frame (``encoders``) the firmware booted by
    the summary at ``position`` may have primed on after a silence (``quiet_start``; the life
    before starts at ``after``); None when no silence of ``SILENCE_S`` precedes it."""
    heard = firmware_frames(frames, decoder)
    return quiet_start((heard, frames.timestamp_s[heard]),
                       (encoders, frames.timestamp_s[encoders]), position, after)


def quiet_start(heard: tuple[npt.ArrayLike, npt.ArrayLike],
                encoders: tuple[npt.ArrayLike, npt.ArrayLike], position: int,
                after: int) -> int | None:
    """``silent_start`` on the positions and bus times of the firmware's frames (``heard``,
    ``firmware_frames``) and of the accepted encoder frames: the first encoder frame after the
    old firmware's last frame before the latest silence up to the summary at ``position`` (and
    after the encoders' own silence there, when they had one), None without such a silence."""
    at, at_s = np.asarray(heard[0], dtype=np.int64), np.asarray(heard[1], dtype=np.float64)
    enc, enc_s = np.asarray(encoders[0], dtype=np.int64), np.asarray(encoders[1], dtype=np.float64)
    mine = (at > after) & (at <= position)
    at, at_s = at[mine], at_s[mine]
    loud = np.flatnonzero(np.diff(at_s) > SILENCE_S)
    if not len(loud):
        return None
    between = (enc > at[loud[-1]]) & (enc < at[loud[-1] + 1])  # the old one's last frame, the
    later, later_s = enc[between], enc_s[between]  # new one's first heard
    if not len(later):
        return None
    went = np.flatnonzero(np.diff(later_s) > SILENCE_S)  # the bus was off
    return int(later[went[-1] + 1]) if len(went) else int(later[0])


def primed_in_silence(enc: Encoders, onboard: Poses, t_s: float, robot: RobotProfile,
                      integrator: str) -> list[dict[str, Any]]:
    """The event whose candidates (``FRAMES_KEY``) ``primedon.judged_from_each`` judges the
    life from: encoder frames 0 .. its first sample's, the best agreeing with it first."""
    if not len(onboard.enc):
        return []
    lo = int(onboard.enc[0])
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    moved = integrate(wrap_delta(np.diff(enc.left[: lo + 1]), bits),
                      wrap_delta(np.diff(enc.right[: lo + 1]), bits), Geometry.of(robot),
                      integrator)
    x = np.concatenate(([0.0], moved.x_m))
    y = np.concatenate(([0.0], moved.y_m))
    h = np.concatenate(([0.0], moved.heading_rad))
    cos_h, sin_h = np.cos(-h), np.sin(-h)  # the motion from frame p to lo, in p's frame
    dx, dy = x[-1] - x, y[-1] - y
    off = np.hypot(cos_h * dx - sin_h * dy - onboard.x_m[0],
                   sin_h * dx + cos_h * dy - onboard.y_m[0])
    turn = np.angle(np.exp(1j * ((h[-1] - h) - onboard.heading_rad[0])))
    worst = off + np.abs(turn) * robot.wheelbase_m  # a heading error's reach at the wheels
    order = [int(p) for p in np.argsort(worst, kind="stable")[:MOST_TRIED]]
    return [{"kind": KIND, "t_s": t_s, WHY_KEY: WHY,
             FRAMES_KEY: [[p, list(start_pose_primed_on(enc, p, robot, integrator))]
                          for p in order]}]


def firmware_frames(frames: FrameArrays, decoder: BulkDecoder) -> npt.NDArray[np.intp]:
    """Positions of the firmware's ODOM_POSE_Y frames and its ODOM_STATUS frames whose CRC
    holds, in bus order."""
    ys = decoder.select(frames, "ODOM_POSE_Y")
    status = decoder.select(frames, "ODOM_STATUS")
    return np.sort(np.concatenate((ys, status[crc_holds(frames, decoder, status)])))

