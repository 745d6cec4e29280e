"""The encoder frame a rebooted firmware primed on, named by its power-up pose: not by stamps.

A firmware that primes in its first tick sends its power-up pose first (firmware/ecu.py step 5):
an ODOM_POSE_X of E2E COUNTER 0 (its counters start at 0) reading X 0 and HEADING 0, whose
ENC_COUNTER names the encoder frame it primed on (the latest of the last ``NAMED_SPAN`` heard
before the pose with that COUNTER). Its summary (UPTIME 0) and its first page of encoder E2E
counts follow; the other rules (``host.judge.reboots``: the latest encoder frame before the
summary, the count page's frames counted back from the latest before the page) read where
those ODOM_STATUS frames were stamped. A recorder or gateway that stamps every ODOM_STATUS frame
15..50 ms late (a common capture) moved those starts 1..5 encoder frames late: a correct
firmware FAILed by 6..25 mm (issue #11, rule 5). The pose frames are not delayed with them, and
the pose's name is the firmware's own word on where it primed.

The power-up pose is the latest ODOM_POSE_X of COUNTER 0 whose CRC holds before the reboot's
summary, heard less than ``BOOT_WINDOW_S`` (80 ms) before the summary (``bootticks``: a summary
held back further is not told as its tick's either), when it reads X 0 and HEADING 0. When that
latest one reads anything else, the pose has no word on where the firmware primed, even if an
earlier pose of COUNTER 0 read (0, 0, 0): that earlier one is the old life's (its COUNTER wraps
to 0 every 16 poses; a robot standing at its origin reads (0, 0, 0)), and the new one, its sequence
restarted after it, came up off (0, 0, 0) -- a wrong firmware, judged from (0, 0, 0) at the
frame the other rules name. Taking the old pose's frame started the life frames before the one
it primed on, so its page of E2E counts no longer proved the power-up and its start was fitted
(issue #11: a firmware 3 LSB off after its reboot had its start fitted to its offset). A pose of
the old life reading (0, 0, 0) that is the latest (the new firmware's first pose lost) would
name a frame the robot had not left since the power-up pose's: the same start.

Nor has it a word when a pose of COUNTER 0 follows the summary less than ``BOOT_WINDOW_S``
after it (``restarted_after``): the pose sequence restarted there, so the one before the summary
was the old firmware's, which went on after it (a COUNTER wraps to 0 after 16 poses, 320 ms,
longer than the 160 ms between the two), and the new one came up after its summary (STATE INIT:
it boots 5 ms before the tick it primes in). Before the summary the two cannot be told apart
(an old pose at (0, 0, 0) followed by its COUNTER 1 and 2 reads as a power-up pose whose summary
was stamped 45 ms late); naming the old pose's frame started the life 5 frames early, its page
of counts no longer proved the power-up and its start was fitted (issue #11: a fitted start
can absorb a constant offset).

Nor has it a word when the first pose heard after the summary (its CRC holding, less than
``BOOT_WINDOW_S`` after it) does not count on from it (``counts_on``): a life's pose of COUNTER c
names a frame at most ``ENC_FRAMES_PER_POSE`` x c encoder COUNTER steps after its power-up
pose's (one pose every other encoder frame; a frame it lost makes it fewer), or none comes.
The bus lost the new firmware's first pose frames and the latest pose of COUNTER 0 at (0, 0, 0)
was the old firmware's, 2..6 frames before the new one primed: a robot standing at its origin,
set moving, its MCU reset (a brown-out at motor start). Naming the old pose's frame put the
robot's first steps into the reference, never into the firmware's pose: a correct firmware
FAILed by 8..24 mm (issue #11, ``tests/test_reboot_lost_powerup.py``); the other rules name the
frame then. Unless that first pose came later than its COUNTER's poses explain by
``BOOT_WINDOW_S`` (``halted_after``): the firmware halted right after its first tick, and its
first pose after the halt names a frame of its mailbox's backlog (a held-back one: behind the
power-up pose's), which says nothing; its COUNTER counting on from the power-up pose is the
word then (``counts_on_after``). Refused, the summary held back 30 ms past two more frames
started the life there: pmir random 13 ``reboot=2.5:0.05,stall=2.56:0.3,delay=0.2:30``, 4.74 mm
(5 counts a wheel) and a DISTANCE 168.7 mm off, and random 15's start fitted 243.5 mm off
(``tests/test_reboot_halt_held.py``). Live (``LivePowerUp.halted``) the life then waits on as a
halted one's (``livebootstall``), on that frame (``livestart.Lives._halted_named``): taken at
once, its halt went untold, 1.48 mm beyond (seed 13; random 5, summary on time: 1.90 mm). Known
limit: the bus losing the power-up pose and the MCU
halting right after its first tick, both, name the old life's frame.

A summary the bus held back further (``--faults delay=0.2:150``: heard 150 ms after its tick)
leaves the power-up pose outside that window: it is taken up to one pose COUNTER lap
(``HELD_WINDOW_S``, 320 ms) before the summary when its life's poses ran on to the summary
(``ran_on_to``): the pose heard before it is not COUNTER 15 (the sequence restarted there, not an
old life's lap at (0, 0, 0)), at least one pose came between it and the summary, and each of
them counts on from it, its COUNTER rising; the first pose after the summary then counts on
from the last of them. Dated by the summary, the new life's poses of those 150 ms were judged
the old life's after a stall: a correct firmware FAILed by 4.47 mm (kobuki random 720) and
853.5 mm (pmir random 727; ``tests/test_boot_held.py``). One rule for the whole log
(``reboots``), the streamed (``stream_lives``) and the live judges
(``tracking.PoseTracker.power_up``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootticks import BOOT_WINDOW_S, POSE_MESSAGE
from odocan.host.judge.powerup import NAMED_SPAN
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, e2e_messages
from odocan.host.protocol.e2e_rows import crc_right

# (log positions, bus times s, ENC_COUNTERs) of the poses of COUNTER 0, ENC_COUNTER ``NO_WORD``
# for one that reads no power-up pose (module docstring)
NO_WORD = -1
PowerUpPoses = tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.int64]]
# (log positions, bus times s, E2E COUNTERs, ENC_COUNTERs) of every pose whose CRC holds
PoseRows = tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.int64],
                 npt.NDArray[np.int64]]
# (log positions, COUNTERs) of the encoder frames whose CRC holds (``heard_encoders``)
TICK_HEARD_S = busfacts.ENC_CYCLE_S / 2  # frames heard this close together: one tick's
Framed = tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64]]
ENCODER_MESSAGE = "WHEEL_ENCODERS"
# a held-back summary's power-up pose (``ran_on_to``): within one lap of the pose COUNTER
HELD_WINDOW_S = (busfacts.ENC_COUNTER_MASK + 1) * busfacts.POSE_PERIOD_S
POSES_KEPT = 2 * (busfacts.ENC_COUNTER_MASK + 1)  # a stream's carried poses: two laps
ENC_FRAMES_PER_POSE = (busfacts.POSE_CYCLE_MS // busfacts.POSE_FRAMES_PER_CYCLE
                       // busfacts.ENC_CYCLE_MS)  # 2: encoder frames from one pose to the next


def is_powerup_pose(counter: int, x_raw: float, heading_raw: float) -> bool:
    """Whether an ODOM_POSE_X (E2E ``counter``, X and HEADING raw or scaled) reads a firmware's
    power-up pose: COUNTER 0, X 0, HEADING 0."""
    return counter == 0 and x_raw == 0 and heading_raw == 0


def no_powerup_poses() -> PowerUpPoses:
    """No power-up pose (a stream's start)."""
    return np.zeros(0, np.int64), np.zeros(0, np.float64), np.zeros(0, np.int64)


def carried_on(kept: PowerUpPoses, heard: PowerUpPoses, keep: int = 4) -> PowerUpPoses:
    """The latest ``keep`` power-up poses of ``kept`` followed by those ``heard`` since (a
    stream's next chunk: ``stream_lives``; a summary follows its tick's within 80 ms)."""
    return (np.concatenate((kept[0][-keep:], heard[0])),
            np.concatenate((kept[1][-keep:], heard[1])),
            np.concatenate((kept[2][-keep:], heard[2])))


def powerup_poses(frames: FrameArrays, decoder: BulkDecoder, offset: int = 0) -> PowerUpPoses:
    """The ODOM_POSE_X frames of ``frames`` of COUNTER 0 whose CRC holds: their positions (plus
    ``offset``: a stream's chunk), bus times and ENC_COUNTERs, ``NO_WORD`` for those that read
    no power-up pose (``is_powerup_pose``: a later one of them voids an earlier power-up pose,
    module docstring); empty without them."""
    empty = no_powerup_poses()
    try:
        rows = decoder.decode(frames, POSE_MESSAGE)
    except (DecodeError, KeyError):
        return empty
    if not {"COUNTER", "X", "HEADING", "ENC_COUNTER"} <= rows.keys() or not len(rows["index"]):
        return empty
    index = rows["index"]
    keep = (rows["COUNTER"] == 0) & _crc_holds(frames, decoder, index)
    named = np.where((rows["X"] == 0) & (rows["HEADING"] == 0), rows["ENC_COUNTER"], NO_WORD)
    return (index[keep].astype(np.int64) + offset, rows["timestamp_s"][keep].astype(np.float64),
            named[keep].astype(np.int64))


def pose_enc_rows(frames: FrameArrays, decoder: BulkDecoder, offset: int = 0) -> PoseRows:
    """Every ODOM_POSE_X of ``frames`` whose CRC holds (whatever its sequence): positions (plus
    ``offset``), bus times, E2E COUNTERs and ENC_COUNTERs (``counts_on``); empty without them."""
    empty = (np.zeros(0, np.int64), np.zeros(0, np.float64), np.zeros(0, np.int64),
             np.zeros(0, np.int64))
    try:
        rows = decoder.decode(frames, POSE_MESSAGE)
    except (DecodeError, KeyError):
        return empty
    if not {"COUNTER", "ENC_COUNTER"} <= rows.keys() or not len(rows["index"]):
        return empty
    keep = _crc_holds(frames, decoder, rows["index"])
    return (rows["index"][keep].astype(np.int64) + offset,
            rows["timestamp_s"][keep].astype(np.float64), rows["COUNTER"][keep].astype(np.int64),
            rows["ENC_COUNTER"][keep].astype(np.int64))


def pose_rows_none() -> PoseRows:
    """No pose (a stream's start: ``carried_rows``)."""
    return (np.zeros(0, np.int64), np.zeros(0, np.float64), np.zeros(0, np.int64),
            np.zeros(0, np.int64))


def carried_rows(kept: PoseRows, heard: PoseRows) -> PoseRows:
    """The latest ``POSES_KEPT`` poses of ``kept`` followed by those ``heard`` since (a stream's
    next chunk: a held-back summary's run, ``ran_on_to``, is shorter than one lap)."""
    return (np.concatenate((kept[0][-POSES_KEPT:], heard[0])),
            np.concatenate((kept[1][-POSES_KEPT:], heard[1])),
            np.concatenate((kept[2][-POSES_KEPT:], heard[2])),
            np.concatenate((kept[3][-POSES_KEPT:], heard[3])))


def counts_on(counter: int, enc_steps: int) -> bool:
    """Whether a pose of E2E COUNTER ``counter`` naming a frame ``enc_steps`` ENC_COUNTER steps
    (mod 16) after the one a power-up pose named is of that pose's life (module docstring)."""
    most = ENC_FRAMES_PER_POSE * counter
    return counter > 0 and most <= busfacts.ENC_COUNTER_MASK and enc_steps <= most


def first_after(rows: PoseRows, position: int, t_s: float, named_enc: int,
                base_counter: int = 0) -> bool | None:
    """``counts_on`` of the first pose of ``rows`` after the summary at log ``position``, bus
    time ``t_s``, from a pose of COUNTER ``base_counter`` (0: the power-up pose; a held-back
    summary's, the last before it: ``ran_on_to``) that named ENC_COUNTER ``named_enc``: False
    when it came ``BOOT_WINDOW_S`` after the summary or later; None when ``rows`` end before
    it."""
    at, times, counters, encs = rows
    k = int(np.searchsorted(at, position, side="right"))
    if k == len(at):
        return None
    return counts_on_after(int(counters[k]) - base_counter,
                           (int(encs[k]) - named_enc) & busfacts.ENC_COUNTER_MASK,
                           float(times[k]) - t_s)


def counts_on_after(counter: int, enc_steps: int, since_s: float) -> bool:
    """``counts_on`` of the first pose after a boot summary, ``counter`` poses after the one it
    counts on from, naming a frame ``enc_steps`` after that one's, heard ``since_s`` after the
    summary: less than ``BOOT_WINDOW_S`` after it; or later than its COUNTER's poses (one every
    ``POSE_PERIOD_S``) can explain by ``BOOT_WINDOW_S`` (``halted_after``): the firmware sent
    nothing in between, halted right after its first tick, and its first pose after the halt
    names a frame of its mailbox's backlog (any, a held-back one too), which says nothing; its
    COUNTER still counts on from the power-up pose (module docstring)."""
    if 0.0 <= since_s < BOOT_WINDOW_S:
        return counts_on(counter, enc_steps)
    return halted_after(counter, since_s) and counts_on(counter, 0)


def halted_after(counter: int, since_s: float) -> bool:
    """Whether a pose ``counter`` poses after the one counted from, heard ``since_s`` after the
    boot summary, came later than those poses explain by ``BOOT_WINDOW_S``: the firmware was
    silent between (a halt), not lost on the bus (each lost pose counts its COUNTER on)."""
    return since_s >= BOOT_WINDOW_S + counter * busfacts.POSE_PERIOD_S


def pose_before(poses: PowerUpPoses, position: int, t_s: float,
                rows: PoseRows | None = None) -> tuple[int, int, tuple[int, int]] | None:
    """The power-up pose a summary at log ``position`` and bus time ``t_s`` follows: the latest
    of ``poses`` before it, heard less than ``BOOT_WINDOW_S`` before it, or (``rows``: every
    pose heard) less than ``HELD_WINDOW_S`` when its life's poses ran on to the summary
    (``ran_on_to``: the summary held back); its position, ENC_COUNTER and the (COUNTER,
    ENC_COUNTER) the first pose after the summary counts on from (``first_after``). None when
    none, or when that latest one reads no power-up pose."""
    at, times, named = poses
    k = int(np.searchsorted(at, position)) - 1
    if k < 0 or named[k] == NO_WORD:
        return None
    ago_s, base = t_s - float(times[k]), (0, int(named[k]))
    if not 0.0 <= ago_s < BOOT_WINDOW_S:
        held = (None if rows is None or not 0.0 <= ago_s < HELD_WINDOW_S
                else ran_on_to(rows, int(at[k]), position, int(named[k])))
        if held is None:
            return None
        base = held
    return int(at[k]), int(named[k]), base


def ran_on_to(rows: PoseRows, pose: int, position: int, named_enc: int) -> tuple[int, int] | None:
    """Whether the power-up pose at log ``pose`` (naming ENC_COUNTER ``named_enc``) began a
    life whose poses ran on to the summary at ``position`` (module docstring, a summary held
    back): the pose heard before it does not wrap to it (COUNTER not 15: its sequence
    restarted there, not an old life's lap at (0, 0, 0)), and at least one pose came between
    it and the summary, each counting on from it with its COUNTER rising (``counts_on``). The
    COUNTER and ENC_COUNTER of the last of them (the first pose after the summary counts on
    from it: ``first_after``); None when not."""
    at, _, counters, encs = rows
    k = int(np.searchsorted(at, pose))
    if k == 0 or k == len(at) or at[k] != pose:
        return None
    if int(counters[k - 1]) == busfacts.ENC_COUNTER_MASK:
        return None
    last = (0, named_enc)
    for j in range(k + 1, int(np.searchsorted(at, position))):
        counter, enc = int(counters[j]), int(encs[j])
        if counter <= last[0] or not counts_on(
                counter, (enc - named_enc) & busfacts.ENC_COUNTER_MASK):
            return None
        last = (counter, enc)
    return None if last[0] == 0 else last


def named_frame(encoders: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]], pose: int,
                enc_counter: int, heard: Framed | None = None) -> int | None:
    """The encoder frame a pose at log position ``pose`` names: the latest of the last
    ``NAMED_SPAN`` accepted before it (``encoders``: their positions and COUNTERs, in order)
    whose COUNTER is ``enc_counter``; None when the log lacks it. With ``heard``
    (``heard_encoders``: every encoder frame whose CRC holds), the last ``NAMED_SPAN`` of those
    before it (``heard_named``)."""
    if heard is not None:
        return heard_named(encoders[0], heard, pose, enc_counter)
    at, counters = encoders
    last = int(np.searchsorted(at, pose))
    tail = np.flatnonzero(counters[max(last - NAMED_SPAN, 0):last] == enc_counter)
    return int(at[max(last - NAMED_SPAN, 0) + int(tail[-1])]) if len(tail) else None


def heard_named(accepted: npt.NDArray[np.int64], heard: Framed, pose: int,
                enc_counter: int) -> int | None:
    """The encoder frame a power-up pose at log position ``pose`` names among the last
    ``NAMED_SPAN`` frames heard before it whose CRC holds (``heard``: their positions and
    COUNTERs), whatever the whole log's E2E check said of them: the latest of COUNTER
    ``enc_counter`` that check took (``accepted``: positions), else the latest of them all;
    None when none of them has it.

    A new firmware's E2E receiver starts afresh and takes the first frame it drains whatever
    its sequence, so it may prime on a frame the whole log's check refused: a delay (or a
    burst) before the boot left that check refusing the frames after a late one until their
    COUNTER came round, and the last ``NAMED_SPAN`` frames it took reached back before the boot
    (issue #11: kobuki figure8 ``--seed 115 --faults delay=0.1:15,reboot=6:0.5`` primed on
    COUNTER 10 at 6.50 s, refused; the COUNTER 10 taken at 6.355 s, while the MCU booted, was
    named: 43 mm and 85 mrad off, DISTANCE 63.5 mm; pmir random ``--seed 304 --faults
    burst=0.01:12,delay=0.1:15,reboot=6:0.5``: 33.4 mm). A taken one first: a frame refused
    as a lap-old late copy of its COUNTER is no new firmware's first frame, unless it came in
    the pose's own tick (less than ``TICK_HEARD_S`` before the latest frame heard before the
    pose) and the taken one before it: the firmware drains its frames in the tick it sends its
    pose in, and took nothing in its boot time (kobuki random 908,
    ``reboot=1.5:0.3,delay=0.1:200``: primed at 1.80 s on a COUNTER 0 sent at 1.60 s, held
    back 200 ms; the on-time COUNTER 0 of 1.76 s, heard in the boot, was named, its start
    fitted and the correct firmware FAILed)."""
    at, counters, times = heard
    last = int(np.searchsorted(at, pose))
    lo = max(last - NAMED_SPAN, 0)
    same = counters[lo:last] == enc_counter
    tail = at[lo:last][same]
    if not len(tail):
        return None
    in_tick = times[lo:last][same] > times[last - 1] - TICK_HEARD_S
    tail = tail[in_tick] if in_tick.any() else tail
    taken = tail[np.isin(tail, accepted)]
    return int((taken if len(taken) else tail)[-1])


def heard_encoders(every: tuple[FrameArrays, npt.NDArray[np.int64]], decoder: BulkDecoder
                   ) -> Framed:
    """The positions, COUNTERs and bus times of the encoder frames ``every`` (the frames, their
    positions in the log) whose CRC holds, whatever their sequence (``heard_named``)."""
    frames, at = every
    data = frames.data
    config = e2e_messages(decoder.db).get(decoder.message(ENCODER_MESSAGE).frame_id)
    good = np.ones(len(at), dtype=bool)
    if config is not None and config.data_ids is not None and len(at):
        ids = np.array(config.data_ids, dtype=np.uint8)[data[:, 1] & busfacts.ENC_COUNTER_MASK]
        good = crc8h2f_p02(data, ids) == data[:, 0]
    return (at[good].astype(np.int64),
            (data[good, 1] & busfacts.ENC_COUNTER_MASK).astype(np.int64),
            frames.timestamp_s[good].astype(np.float64))


def named_start(poses: PowerUpPoses, encoders: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]],
                position: int, t_s: float, after: PoseRows | None = None,
                heard: Framed | None = None, run: PoseRows | None = None
                ) -> tuple[int, int, int] | None:
    """The encoder frame the firmware whose boot summary (UPTIME 0) is at log ``position``, bus
    time ``t_s``, primed on, as its power-up pose names it, and the ENC_COUNTER and COUNTER the
    first pose after the summary counts on from (that pose's and 0, or a held-back summary's
    last run pose's: ``ran_on_to``; module docstring); None when no power-up pose precedes it in
    the window, the log lacks the frame it names, or (``after``: the log's poses) the first pose
    after the summary does not count on from it (``first_after``; a stream tells that later,
    its poses so far in ``run``). ``heard``: ``named_frame``'s."""
    pose = pose_before(poses, position, t_s, after if run is None else run)
    if pose is None or restarted_after(poses, position, t_s):
        return None
    base_counter, base_enc = pose[2]
    if after is not None and not first_after(after, position, t_s, base_enc, base_counter):
        return None
    frame = named_frame(encoders, pose[0], pose[1], heard)
    return None if frame is None else (frame, base_enc, base_counter)


def restarted_after(poses: PowerUpPoses, position: int, t_s: float) -> bool:
    """Whether a pose of COUNTER 0 of ``poses`` follows the summary at log ``position``, bus
    time ``t_s``, less than ``BOOT_WINDOW_S`` after it: the pose sequence restarted after the
    summary, so no pose before it was the new firmware's power-up pose (module docstring)."""
    at, times, _ = poses
    k = int(np.searchsorted(at, position, side="right"))
    return k < len(at) and 0.0 <= float(times[k]) - t_s < BOOT_WINDOW_S


def _crc_holds(frames: FrameArrays, decoder: BulkDecoder, rows: npt.NDArray[np.int64]
               ) -> npt.NDArray[np.bool_]:
    """Which ODOM_POSE_X frames at ``rows`` carry a right CRC, whatever their sequence (a new
    firmware restarts it)."""
    return crc_right(frames, decoder, rows, POSE_MESSAGE, unprotected=True)


class LivePowerUp:
    """``named_start`` live (the monitor's and the bridge's tracker): the latest power-up pose
    heard, when and the encoder frame (the tracker's seq) it names among those heard before it;
    after a summary took it (``named_seq``), whether the first pose after counts on from it."""

    def __init__(self) -> None:
        self.latest: tuple[float, int | None, int] | None = None  # bus time s, named seq, ENC
        self.told: tuple[float, int] | None = None  # the summary that took it: bus time s, ENC
        self.told_counter = 0  # the COUNTER its first pose after counts on from (``first_after``)
        self.counted: bool | None = None  # its first pose after (``first_after``); None: none yet
        self.previous = -1  # the COUNTER of the pose heard before the latest (``ran_on_to``)
        self.last = -1  # the COUNTER of the latest pose heard
        self.chain: tuple[int, int] | None = None  # the latest power-up pose's run (``ran_on_to``)
        self.held_s: float | None = None  # a held-back summary's power-up pose: its bus time s
        # the first pose after the summary counted on from it only by its COUNTER, after a halt
        # (``counts_on_after``): the word holds, the life waits on as a halted one's
        self.halted = False
        # the latest power-up pose that restarted the sequence: its bus time s, named seq
        self.restarted_at: tuple[float, int] | None = None

    def heard(self, counter: int, x: float, heading: float, enc_counter: int, t_s: float,
              rows: Sequence[Sequence[float]]) -> None:
        """An ODOM_POSE_X accepted by the tracker (E2E ``counter``, ``x``, ``heading``, its
        ENC_COUNTER, bus time s); ``rows``: the encoder frames heard before it (seq, place,
        COUNTER, ...: ``livewindow.ENC_COLUMNS``). One of COUNTER 0 that reads no power-up pose
        voids the one before (module docstring)."""
        if self.told is not None and self.counted is None:  # the first pose after the summary
            summary_s, named_enc = self.told
            steps = (counter - self.told_counter,
                     (enc_counter - named_enc) & busfacts.ENC_COUNTER_MASK)
            self.counted = 0.0 <= t_s - summary_s < BOOT_WINDOW_S and counts_on(*steps)
            self.halted = not self.counted and counts_on_after(*steps, t_s - summary_s)
        self._run_on(counter, enc_counter)
        if counter != 0:
            return
        self.chain = None
        if not is_powerup_pose(counter, x, heading):
            self.latest = (t_s, None, enc_counter)
            return
        restarted = 0 <= self.previous != busfacts.ENC_COUNTER_MASK  # not wrapped
        if restarted:
            self.chain = (0, enc_counter)
        tail = [row for row in list(rows)[-NAMED_SPAN:] if int(row[2]) == enc_counter]
        self.latest = (t_s, int(tail[-1][0]) if tail else None, enc_counter)
        if restarted and tail:  # kept past the later poses of COUNTER 0 (``held_tick_word``)
            self.restarted_at = (t_s, int(tail[-1][0]))

    def _run_on(self, counter: int, enc_counter: int) -> None:
        """``ran_on_to`` live: a pose after the latest power-up pose counts on from it, or ends
        its run."""
        if self.chain is None or self.latest is None or counter == 0:
            return
        if counter <= self.chain[0] or not counts_on(
                counter, (enc_counter - self.latest[2]) & busfacts.ENC_COUNTER_MASK):
            self.chain = None
            return
        self.chain = (counter, enc_counter)

    def on_pose(self, counter: int, signals: Callable[[], dict[str, Any]], t_s: float,
                rows: Sequence[Sequence[float]]) -> None:
        """Every ODOM_POSE_X heard (its CRC holding, whatever its sequence) at bus time ``t_s``:
        its E2E ``counter`` (whether the next power-up pose restarts the sequence or wraps it:
        ``ran_on_to``), and ``heard_raw`` of its ``signals()`` when it is wanted: COUNTER 0,
        the first after a summary (``waits_next``) or one on a power-up pose's run."""
        self.previous, self.last = self.last, counter
        if counter == 0 or self.waits_next or self.chain is not None:
            self.heard_raw(signals(), t_s, rows)

    def life_from_s(self, told_s: float) -> float:
        """Where the life a reboot told from bus time ``told_s`` began: its power-up pose's bus
        time when its summary was held back (``named_seq`` took it by ``ran_on_to``)."""
        return told_s if self.held_s is None else min(told_s, self.held_s)

    def heard_raw(self, signals: dict[str, Any], t_s: float,
                  rows: Sequence[Sequence[float]]) -> None:
        """``heard`` of an ODOM_POSE_X's decoded ``signals`` (COUNTER, X, HEADING,
        ENC_COUNTER), whatever its E2E sequence (its CRC holding)."""
        self.heard(int(signals["COUNTER"]), signals["X"], signals["HEADING"],
                   int(signals["ENC_COUNTER"]), t_s, rows)

    def named_seq(self, summary_s: float) -> int | None:
        """The encoder frame (seq) the power-up pose heard less than ``BOOT_WINDOW_S`` before
        a boot summary heard at bus time ``summary_s`` names; None when none. Its word holds
        once the first pose after the summary counts on from it (``corroborated``)."""
        self.told, self.counted, self.told_counter, self.held_s = None, None, 0, None
        self.halted = False
        if self.latest is None:
            return None
        ago_s, base = summary_s - self.latest[0], (0, self.latest[2])
        if not 0.0 <= ago_s < BOOT_WINDOW_S:  # a held-back summary's (``ran_on_to``)
            if (self.chain is None or self.chain[0] == 0 or self.latest[1] is None
                    or not 0.0 <= ago_s < HELD_WINDOW_S):
                return None
            base, self.held_s = self.chain, self.latest[0]
        if self.latest[1] is not None:
            self.told, self.told_counter = (summary_s, base[1]), base[0]
        return self.latest[1]

    @property
    def waits_next(self) -> bool:
        """Whether the next pose heard is wanted whatever its COUNTER (``corroborated``)."""
        return self.told is not None and self.counted is None

    @property
    def corroborated(self) -> bool:
        """Whether the first pose after the summary that took the power-up pose counted on from
        it (``first_after``); False while none came."""
        return bool(self.counted)
