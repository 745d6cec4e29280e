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
it primed on one of the encoder frames after that last frame, up to the one its first pose
names: any on the bus, not only those the E2E check over the whole life took (a delay that
reordered a frame in the boot made that check refuse the frames after it until it resynced,
while the new firmware, booted later, took them afresh and primed on one: issue #11, kobuki
``--seed 1 --faults delay=0.1:15,reboot=10:0.3`` FAILed 3.10 mm, 6.72 mrad off). Each is judged
from its position in the life's frames on, the E2E check fresh there as the firmware's was.
The life starts at the first of them (``silent_start``) and is judged from the power-up pose
(0, 0, 0) on each (after the encoder frames' own silence when they had one: the
bus was off, a firmware primed before it would have its first pose placed across a gap, free to
absorb an offset; ``primed_in_silence``: ``primedon.judged_from_each``, PASS from
one, FAIL from all): power-up, its frame fitted, never a free start pose. The candidates are
tried in the order their reference agrees with the first pose heard (``MOST_TRIED`` of them:
the frame the firmware primed on agrees within its rounding; one that does not cannot pass).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapseen import crc_holds
from odocan.host.judge.primed import counted_start
from odocan.host.judge.primedon import FRAMES_KEY, WHY_KEY
from odocan.host.judge.reference import Geometry, integrate, wrap_delta
from odocan.host.judge.samples import WIRE_COUNTER_BITS, Encoders, Poses, contract_cycle_s
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK as MASK
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import RobotProfile

SILENCE_S = 0.25  # no pose nor summary of the firmware for this long: a silence (2.5 cycles)
MOST_TRIED = 8  # candidate frames judged, the best agreeing with the first pose first
KIND = "power_up_in_silence"
WHY = ("the firmware rebooted while its frames were not heard (no count page nor power-up "
       "pose names the frame it primed on): it primed on one of the life's encoder frames "
       "{frames} on the bus")


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


def primed_in_silence(frames: FrameArrays, decoder: BulkDecoder, enc: Encoders, onboard: Poses,
                      t_s: float, judged: tuple[RobotProfile, str]) -> list[dict[str, Any]]:
    """The event whose candidates (``FRAMES_KEY``) ``primedon.judged_from_each`` judges the
    life (``frames``, from its first) from: each of its encoder frames on the bus up to the one
    its first sample names, the best agreeing with that sample first. Each is [its place among
    the life's WHEEL_ENCODERS frames, (0, 0, 0), its position in ``frames``]: the life is judged
    again from that position on (``primedon.judged_from_each``), its E2E check fresh there as
    the new firmware's was. A reordered frame (a delay put one sent before the boot after a
    later one) made the check run over the whole life refuse frames the new firmware, booted
    after the reorder, took: it primed on one of them (issue #11, kobuki ``--seed 1 --faults
    delay=0.1:15,reboot=10:0.3``: 3.10 mm, 6.72 mrad off from every frame the check took)."""
    if not len(onboard.enc):
        return []
    robot, integrator = judged
    rows = decoder.decode(frames, "WHEEL_ENCODERS")
    named = int(enc.index[int(onboard.enc[0])])
    places = [k for k, at in enumerate(rows["index"].tolist()) if at <= named]
    bits = min(robot.counter_bits, WIRE_COUNTER_BITS)
    worst: list[tuple[float, int]] = []
    for k in places:
        at = int(rows["index"][k])
        fresh = taken_fresh(frames.select(np.arange(at, named + 1)), decoder)
        taken = np.flatnonzero(fresh[rows["index"][places[k:]] - at])
        if not len(taken) or taken[0] != 0 or not fresh[-1]:
            continue  # the frame refused, or the named frame not taken, from there
        rows_taken = np.asarray(places[k:])[taken]
        left, right = rows["LEFT_COUNT"][rows_taken], rows["RIGHT_COUNT"][rows_taken]
        moved = integrate(wrap_delta(np.diff(left.astype(np.int64)), bits),
                          wrap_delta(np.diff(right.astype(np.int64)), bits), Geometry.of(robot),
                          integrator)
        x, y, h = ((float(moved.x_m[-1]), float(moved.y_m[-1]), float(moved.heading_rad[-1]))
                   if len(moved.x_m) else (0.0, 0.0, 0.0))
        turn = math.remainder(h - float(onboard.heading_rad[0]), math.tau)
        worst.append((math.hypot(x - float(onboard.x_m[0]), y - float(onboard.y_m[0]))
                      + abs(turn) * robot.wheelbase_m, k))  # a heading error's reach
    order = [k for _, k in sorted(worst)[:MOST_TRIED]]
    return [{"kind": KIND, "t_s": t_s, WHY_KEY: WHY,
             FRAMES_KEY: [[k, [0.0, 0.0, 0.0], int(rows["index"][k])] for k in order]}]


def taken_fresh(window: FrameArrays, decoder: BulkDecoder) -> npt.NDArray[np.bool_]:
    """Which of ``window``'s frames a firmware whose E2E receiver starts fresh at its first
    frame accepts (the check run over ``window`` alone: a new firmware's, booted there)."""
    return check_frames(window, decoder.db)[1]


def fresh_counted_start(encoders: tuple[FrameArrays, npt.NDArray[np.int64]],
                        decoder: BulkDecoder, page: int, counts: tuple[int, int],
                        told: tuple[int | None, int, int]) -> int | None:
    """The encoder frame the firmware primed on from its first count page at ``page``
    (``counts``: ENC_E2E_OK, ENC_E2E_LOST): the frame its boot summary's rule names when the
    page, over the frames an E2E check fresh there takes (as the new firmware's was), counts
    back to it; else ``counted``. ``told``: (``counted``, ``primed.counted_start`` over the
    frames the whole log's check took; ``reboots.summary_start`` over every encoder frame, the
    first encoder frame at or after it taken; the life before's start); ``encoders``: the
    WHEEL_ENCODERS frames, each with its position in the log. The frames of that frame's tick
    are tried too, latest first (less than a cycle before it): a delay that let two frames
    reach the firmware in one tick made it prime on the first it drained (kobuki ``--seed 2
    --faults delay=0.1:15,reboot=10:0.5``: COUNTER 8 at 10.495 s, COUNTER 10 at 10.50 s
    refused, and every frame after till its first page, ENC_E2E_OK 1; 59.3 mm off from the
    frame the whole log's check named).

    A delay that reordered a frame of the boot made the whole log's check refuse the frames
    after it until it resynchronised, while the new firmware, booted after the reorder, took
    them and primed on one: counted back over the frames the check took, the page named a frame
    a COUNTER lap early, before the boot (a fresh check from there names it too), and the
    correct firmware FAILed 48.10 mm off (issue #11, kobuki ``--seed 1 --faults
    delay=0.1:15,reboot=10:0.5``). The summary's frame only: a recorder's late stamps move it
    by a few frames, which the counts then do not name, and a frame the counts name from a
    later one is no proof (after reorders a page of few counts names frames near it by chance:
    kobuki ``--seed 2 --faults delay=0.1:15,reboot=10:0.3``, ENC_E2E_OK 2 and ENC_E2E_LOST 4,
    named one the correct firmware FAILed from by 22.5 mm; ``silentboot`` judges that life)."""
    counted, summary, lo = told
    window, at = encoders[0].select(encoders[1] > lo), encoders[1][encoders[1] > lo]
    k, before = int(np.searchsorted(at, summary)), int(np.searchsorted(at, page))
    if counts[0] <= 0 or k >= before:
        return counted
    tick_s = window.timestamp_s[k] - (contract_cycle_s(decoder, "WHEEL_ENCODERS") or 0.0)
    counter = window.data[:before, 1].astype(np.int64) & MASK
    while k >= 0 and window.timestamp_s[k] > tick_s:  # its first tick's frames, latest first
        fresh = taken_fresh(window.select(slice(k, before)), decoder)
        named = counted_start((at[k:before][fresh], counter[k:][fresh]), page, *counts)
        if fresh[0] and named == int(at[k]):
            return int(at[k])
        k -= 1
    return counted


def firmware_frames(frames: FrameArrays, decoder: BulkDecoder) -> npt.NDArray[np.intp]:
    """Positions of the firmware's ODOM_POSE_Y frames and its ODOM_STATUS frames whose CRC
    holds, in bus order."""
    ys = decoder.select(frames, "ODOM_POSE_Y")
    status = decoder.select(frames, "ODOM_STATUS")
    return np.sort(np.concatenate((ys, status[crc_holds(frames, decoder, status)])))

