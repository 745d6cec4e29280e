"""A firmware reboot in its first second of uptime, told from its E2E COUNTERs: its power-up tick.

UPTIME (ODOM_STATUS, whole seconds) cannot tell a reset within the firmware's first second: the
new firmware says UPTIME 0 as the old one did, and when it primes on an encoder frame in its
first tick it says OK, not INIT (``host.judge.sources``). What tells it is what a firmware
speaking the DBC sends at power-up: its E2E COUNTERs start at 0 (E2E Profile 2: the sender's
counter starts at 0; ``powerup.holds_first_cycle`` relies on it too), and its first tick sends
its pose, then its summary (firmware/ecu.py step 5). The power-up tick's signature: a summary of
UPTIME 0 and COUNTER 0 whose tick's ODOM_POSE_X -- the latest heard before it, less than half a
pose cycle before it, its CRC holding, whatever its E2E sequence -- has COUNTER 0 too.

Within one firmware life the two COUNTERs read 0 in one tick again only once both wrapped
together: ODOM_POSE_X every 16 frames at one a 20 ms cycle (320 ms), ODOM_STATUS every 16 frames
at two a 100 ms cycle (800 ms): both every lcm = 1.6 s of sending (``JOINT_WRAP_MS``, from the
DBC's GenMsgCycleTime and E2EFramesPerCycle; the tests check them against the DBC). By then
UPTIME says 1 at least; a firmware that sent fewer frames (stalled, overrun) took longer still.
So within UPTIME 0 the signature is a new firmware. Lost frames cannot make it up: the COUNTERs
are read, not counted (a COUNTER that jumps to 0 is also what 16 k - j lost frames look like,
so a jump alone is no evidence, and one ID alone is not either: ODOM_STATUS wraps at 0.8 s). A
recorder's repeat of the boot summary is no second boot: the summary before it must be at least
``REPEAT_S`` older.

Why this rather than a finer UPTIME (a DBC change): a user's own firmware that speaks the DBC
gives it as it is (E2E counters from 0, the DBC's cycles), ours and the C port alike, and old
logs are judged the same. Known limit: a firmware whose first tick sends no pose is told only by
INIT after running (``sources``), one that sends no pose and is not INIT is not told this way.
One rule, for every judge: ``SourceWatch.observe`` (the live monitor, the bridge, the streamed
``analyze``) and ``boot_ticks`` (the whole log's quiet stretches, ``SourceWatch.observe_quiet``).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, crc8h2f_p02_one, e2e_messages

POSE_MESSAGE = busfacts.POSE_MESSAGE  # the pose frame the firmware's every tick sends first
# The DBC's (``host.protocol.busfacts``): 16, 20 ms, 1 a cycle; 16, 100 ms, 2 a cycle; 1 s
POSE_COUNTER_LAP, POSE_CYCLE_MS = busfacts.POSE_COUNTER_LAP, busfacts.POSE_CYCLE_MS
POSE_FRAMES_PER_CYCLE = busfacts.POSE_FRAMES_PER_CYCLE
STATUS_COUNTER_LAP, STATUS_CYCLE_MS = busfacts.STATUS_COUNTER_LAP, busfacts.STATUS_CYCLE_MS
STATUS_FRAMES_PER_CYCLE = busfacts.STATUS_FRAMES_PER_CYCLE
JOINT_WRAP_MS = math.lcm(POSE_COUNTER_LAP * POSE_CYCLE_MS // POSE_FRAMES_PER_CYCLE,
                         STATUS_COUNTER_LAP * STATUS_CYCLE_MS // STATUS_FRAMES_PER_CYCLE)
UPTIME_LSB_MS = busfacts.UPTIME_LSB_MS  # ODOM_STATUS UPTIME: 1 s per LSB
# The rule's ground (module docstring): 1600 ms >= 1000 ms. A DBC whose two COUNTERs wrap
# together within one UPTIME LSB cannot tell a reboot this way: then no summary is a boot tick.
RULE_HOLDS = JOINT_WRAP_MS >= UPTIME_LSB_MS
SAME_TICK_S = POSE_CYCLE_MS / 2000  # the pose of the summary's tick: less than half a cycle
REPEAT_S = POSE_CYCLE_MS / 4000  # a summary this close after the one before: a repeat of it


def boot_tick(uptime_s: int, counter: int, t_s: float, pose: tuple[float, int] | None,
              summary_before_s: float | None) -> bool:
    """The summary (UPTIME ``uptime_s``, E2E ``counter``, bus time ``t_s``) is a firmware's
    power-up tick (module docstring): ``pose``, (bus time, COUNTER) of the latest ODOM_POSE_X
    heard before it (None: none); ``summary_before_s``: the bus time of the summary before
    (None: none)."""
    if not RULE_HOLDS or uptime_s != 0 or counter != 0 or pose is None:
        return False
    if summary_before_s is not None and t_s - summary_before_s < REPEAT_S:
        return False
    return pose[1] == 0 and 0.0 <= t_s - pose[0] < SAME_TICK_S


def boot_ticks(uptime_s: npt.NDArray[np.int64], counters: npt.NDArray[np.int64],
               t_s: npt.NDArray[np.float64], poses: tuple[npt.NDArray[np.float64],
                                                          npt.NDArray[np.int64]],
               summary_before_s: float | None) -> npt.NDArray[np.bool_]:
    """``boot_tick`` of summaries in bus order (their UPTIMEs, COUNTERs, bus times) at once;
    ``poses``: each one's latest ODOM_POSE_X (``poses_before``: NaN, -1 where none);
    ``summary_before_s``: the bus time of the summary before the first."""
    before = np.concatenate(([-math.inf if summary_before_s is None else summary_before_s],
                             t_s[:-1]))
    pose_t, pose_counter = poses
    since = t_s - pose_t  # NaN where no pose: every comparison False
    found: npt.NDArray[np.bool_] = (RULE_HOLDS & (uptime_s == 0) & (counters == 0)
                                    & (pose_counter == 0) & (t_s - before >= REPEAT_S)
                                    & (since >= 0.0) & (since < SAME_TICK_S))
    return found


def poses_before(frames: FrameArrays, decoder: BulkDecoder, positions: npt.NDArray[np.int64],
                 carried: tuple[float, int] | None = None
                 ) -> tuple[tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]],
                            tuple[float, int] | None]:
    """For the frames at ``positions`` (in order) the latest ODOM_POSE_X before each whose CRC
    holds (bus time, COUNTER; NaN, -1 where none; ``carried``: the latest of the frames before
    ``frames``, a stream's earlier chunks), and the latest of all (the next chunk's
    ``carried``)."""
    where, t_pose, counter = _pose_rows(frames, decoder)
    if carried is not None:
        where = np.concatenate(([-1], where))
        t_pose = np.concatenate(([carried[0]], t_pose))
        counter = np.concatenate(([carried[1]], counter))
    if len(where) == 0:
        return (np.full(len(positions), math.nan), np.full(len(positions), -1, np.int64)), None
    k = np.searchsorted(where, positions) - 1  # the latest strictly before each
    found = k >= 0
    times = np.where(found, t_pose[np.maximum(k, 0)], math.nan).astype(np.float64)
    counters = np.where(found, counter[np.maximum(k, 0)], -1).astype(np.int64)
    return (times, counters), (float(t_pose[-1]), int(counter[-1]))


def _pose_rows(frames: FrameArrays, decoder: BulkDecoder
               ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Positions, bus times and E2E COUNTERs of the ODOM_POSE_X frames whose CRC holds
    (whatever their sequence: a rebooted firmware restarts it); empty without them."""
    try:
        message = decoder.message(POSE_MESSAGE)
        rows = decoder.select(frames, POSE_MESSAGE)
    except (DecodeError, KeyError):
        return np.zeros(0, np.int64), np.zeros(0, np.float64), np.zeros(0, np.int64)
    rows = np.asarray(rows, dtype=np.int64)
    data = frames.data[rows]
    config = e2e_messages(decoder.db).get(message.frame_id)
    good = np.ones(len(rows), dtype=bool)
    if config is not None and config.data_ids is not None:
        ids = np.array(config.data_ids, dtype=np.uint8)[data[:, 1] & 0xF]
        good = crc8h2f_p02(data, ids) == data[:, 0]
    return (rows[good], frames.timestamp_s[rows[good]].astype(np.float64),
            (data[good, 1] & 0xF).astype(np.int64))


def pose_heard(data: bytes, data_ids: tuple[int, ...] | None) -> int | None:
    """The E2E COUNTER of an ODOM_POSE_X frame heard live whose CRC holds, whatever its
    sequence (``data_ids``: the message's E2E DataIDs; None: no E2E); None otherwise."""
    if len(data) != 8:
        return None
    if data_ids and data[0] != crc8h2f_p02_one(data, data_ids[data[1] & 0xF]):
        return None
    return data[1] & 0xF
