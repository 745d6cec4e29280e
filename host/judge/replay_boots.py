"""Where a log's rebooted firmware primed, and which encoder frames it took from there, as a
lockstep replay must feed them (``host.judge.replay``; issue #11).

A reboot's new firmware starts its E2E receiver afresh on the frame it primes on. The host's
check run over the whole log does not: a delay that reordered encoder frames around the boot
left it out of step (refusing the frames after a reorder until it resynchronised) while the new
firmware, booted in the middle of that run, took them. The replay fed only what the whole log's
check took, so it could neither reset its board on the frame the firmware primed on (a refused
one) nor feed what the firmware took after it:

* ``reboots.split_lives`` names that frame by the power-up pose's ENC_COUNTER among the frames
  the whole log's check took: with the frame itself refused, it named the last taken frame of
  that COUNTER, a lap (16 frames, 0.145 s) before the boot, and the replay reset its board
  there (kobuki ``--seed 6 --scenario random --duration 14 --faults
  delay=0.1:15,reboot=6:0.5``: the correct firmware FAILed, 99.8 mrad off; seed 7: none of
  life 1's 74 poses paired, UNJUDGED). ``boot_starts`` names it among every encoder frame on
  the bus (``bootnamed.named_start``, the same rule), as a fresh receiver sees them; and when
  the delay put the power-up pose just after the boot summary (where ``named_start`` has no
  word) and the count page names a frame two late (kobuki seed 10, figure8, 11 s: 7.9 mm,
  10.8 mrad off), by that pose when it names the summary's own frame or one of its tick
  (``_named_after``);
* ``fresh_accepted``: from each such start to the next, the WHEEL_ENCODERS verdicts are those
  of an E2E check fresh there (``silentboot.taken_fresh``), the firmware's own; every other
  frame keeps the whole log's verdict;
* ``fresh_ticks``: the step into each start counted by bus time, not COUNTER.

A boot summary is found as the first ODOM_STATUS at its life's time (``Life.t_s``): the first
frame of any kind at that time was the power-up pose sent in the same tick, which the power-up
pose rules then took for the summary and found no pose before.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootnamed import (
    NO_WORD,
    PowerUpPoses,
    named_frame,
    named_start,
    pose_enc_rows,
    powerup_poses,
)
from odocan.host.judge.bootticks import BOOT_WINDOW_S
from odocan.host.judge.reboots import split_lives
from odocan.host.judge.replay_track import MAX_GAP_TICKS, EncoderTrack
from odocan.host.judge.silentboot import taken_fresh
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP as LAP
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames
from odocan.sim import contract

IntArray = npt.NDArray[np.int64]


def boot_starts(frames: FrameArrays, decoder: BulkDecoder) -> list[tuple[int, int]]:
    """(log position of the encoder frame each reboot's firmware primed on, of its boot
    summary), in log order: ``split_lives``' start, unless the power-up pose names a frame the
    whole log's check refused (module docstring), which it then is."""
    lives = [life for life in split_lives(frames, decoder)[1:]
             if len(life.index) and life.set_pose is None and life.config is None]
    if not lives:
        return []
    _, accepted = check_frames(frames, decoder.db)
    rows = decoder.decode(frames, "WHEEL_ENCODERS")
    every = (rows["index"].astype(np.int64), rows["COUNTER"].astype(np.int64))
    keep = accepted[rows["index"]]
    taken = (every[0][keep], every[1][keep])
    poses, after = powerup_poses(frames, decoder), pose_enc_rows(frames, decoder)
    status = frames.can_id == decoder.message("ODOM_STATUS").frame_id
    starts = []
    for life in lives:  # its summary: the first ODOM_STATUS of its time (its poses share it)
        summary = int(np.flatnonzero((frames.timestamp_s == life.t_s) & status)[0])
        t_s = float(frames.timestamp_s[summary])
        start = int(life.index[0])
        fresh = named_start(poses, every, summary, t_s, after)
        whole = named_start(poses, taken, summary, t_s, after)
        if fresh is not None and (whole is None or not _same_frame(frames, whole[0], fresh[0])):
            start = fresh[0]
        elif fresh is None:
            start = _named_after(frames, decoder, (poses, every), summary) or start
        starts.append((start, summary))
    return starts


def _same_frame(frames: FrameArrays, one: int, other: int) -> bool:
    """Whether log positions ``one`` and ``other`` hold one frame: the same position, or a
    duplicate of it (the same payload, a bus's ``dup``; the firmware took the first, which the
    whole log's check took too: pmir seed 5, circle, 15 s, ``delay=0.3:50,busoff=5:1,
    reboot=12,dup=0.1``, its priming frame's duplicate named, both fed, every tick after one
    late, and the replayed bus's analysis FAILed DISTANCE by 5.9 m)."""
    return one == other or bytes(frames.data[one]) == bytes(frames.data[other])


def _named_after(frames: FrameArrays, decoder: BulkDecoder,
                 words: tuple[PowerUpPoses, tuple[IntArray, IntArray]], summary: int) -> int | None:
    """The frame the power-up pose heard just after the boot summary at ``summary`` (less than
    ``BOOT_WINDOW_S`` after it; delayed past it on the bus) names among every encoder frame
    (``words``: the power-up poses, every encoder frame's position and COUNTER), when it is the
    frame the summary's own rule names (UPTIME 0: the latest encoder frame before it, or in
    INIT the first after it) or one of that frame's tick, less than a cycle before it (a delay
    put two frames in the firmware's FIFO for its first tick; it primed on the first drained:
    kobuki ``--seed 7 --scenario figure8 --duration 8 --faults delay=0.1:15,reboot=6:0.5``,
    COUNTER 8 at 6.495 s, COUNTER 10 at 6.500 s): two words of the firmware on one frame.
    None otherwise."""
    (at, times, named), (enc, _) = words
    k = int(np.searchsorted(at, summary, side="right"))
    t_s = float(frames.timestamp_s[summary])
    if k == len(at) or not 0.0 <= float(times[k]) - t_s < BOOT_WINDOW_S or named[k] == NO_WORD:
        return None
    page = decoder.decode_page(frames, "ODOM_STATUS", 0)
    row = int(np.searchsorted(page["index"], summary))
    if row == len(page["index"]) or int(page["index"][row]) != summary \
            or int(page["UPTIME"][row]) != 0:
        return None
    state = decoder.message("ODOM_STATUS").get_signal_by_name("STATE").choices or {}
    init = str(dict(state).get(int(page["STATE"][row]), "")) == "INIT"
    side = int(np.searchsorted(enc, summary))
    expected = enc[side] if init else enc[side - 1]
    if (side == len(enc) if init else side == 0):
        return None
    frame = named_frame(words[1], int(at[k]), int(named[k]))
    if frame is None or frame > int(expected):
        return None
    tick_s = float(frames.timestamp_s[int(expected)]) - contract.cycle_time_s("WHEEL_ENCODERS")
    return frame if float(frames.timestamp_s[frame]) > tick_s else None


def fresh_accepted(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                   starts: list[int], decoder: BulkDecoder) -> npt.NDArray[np.bool_]:
    """``accepted`` (the whole log's E2E verdicts) with the WHEEL_ENCODERS frames' from each of
    ``starts`` (log positions, a rebooted firmware's priming frame) to the next those of a check
    fresh there (module docstring)."""
    try:
        encoder_id = decoder.message("WHEEL_ENCODERS").frame_id
    except DecodeError:
        return accepted
    result = accepted.copy()
    bounds = [*sorted(set(starts)), len(frames.can_id)]
    for first, end in itertools.pairwise(bounds):
        window = frames.select(slice(first, end))
        verdicts = taken_fresh(window, decoder)
        mine = np.asarray(window.can_id) == encoder_id
        result[first:end][mine] = verdicts[mine]
    return result


def fresh_ticks(track: EncoderTrack, starts: list[int]) -> EncoderTrack:
    """``track`` with the step into each of ``starts`` (log positions of a rebooted firmware's
    priming frame) whose COUNTER steps back from the frame before (sent before it, delayed past
    it) counted by the bus time from that frame, not as a COUNTER step forward nearly a lap
    long: the new firmware's sequence starts there (kobuki ``--seed 1 --scenario figure8
    --duration 9 --faults delay=0.3:55,reboot=4:0.5``: COUNTER 1 then 12, 5 ms apart, counted
    11 ticks; the replayed firmware's clock ran 110 ms late and none of life 1's 224 poses
    paired: UNJUDGED). A step forward stays a COUNTER step, the sender's period, as everywhere
    in the track."""
    wanted = np.asarray(sorted(set(starts)), dtype=np.int64)
    at = np.searchsorted(track.index, wanted)
    inside = (at > 0) & (at < len(track.index))
    at = at[inside][track.index[at[inside]] == wanted[inside]]
    if not len(at):
        return track
    back = ((track.counter[at] - track.counter[at - 1] + LAP // 2) & ENC_COUNTER_MASK) <= LAP // 2
    at = at[back]  # a COUNTER step back (or none): sent before the frame before it
    if not len(at):
        return track
    steps = np.diff(track.tick)
    period_s = contract.cycle_time_s("WHEEL_ENCODERS")
    spans = track.timestamp_s[at] - track.timestamp_s[at - 1]
    steps[at - 1] = np.minimum(np.maximum(1, np.rint(spans / period_s)), MAX_GAP_TICKS)
    ticks = np.concatenate(([0], np.cumsum(steps))).astype(np.int64)
    return replace(track, tick=ticks)
