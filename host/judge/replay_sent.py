"""When the firmware sent its frames, and which of its silences were a bus-off, as far as the log
tells (``replay_lives``' silences; issue #11).

A bus that delays frames logs some of a tick's frames late: the pose and twist frames of one
firmware tick share their E2E COUNTER and ENC_COUNTER, and a delay holds each back on its own.
The last frames before a stall were then logged after the halt began: kobuki random 404, 14 s,
``delay=0.25:30,reboot=6:0.3,stall=9:0.5``, ODOM_POSE_Y of the tick at 8.98 s on time, its
ODOM_POSE_X and ODOM_TWIST 30 ms late; the silence was read from 9.01 s, the replayed firmware
ran 2 ticks the recording one never did, took the frames its FIFO should have held, and
departed after the stall (FAIL). So each pose or twist frame is taken as sent when the first
frame of its tick (the same COUNTER and ENC_COUNTER, less than half a COUNTER lap earlier) was
logged; every other frame of the firmware when it was logged.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.firmware.errors import ErrorFlag
from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapseen import crc_holds
from odocan.host.judge.replay_track import EncoderTrack
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.sim import contract

TICK_GROUP = ("ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST")  # one tick's frames: one COUNTER
LAP_TICKS = 32  # a pose COUNTER comes round every 16 poses, one pose every 2 ticks


def sent_times_s(frames: FrameArrays, decoder: BulkDecoder,
                 ids: list[int]) -> npt.NDArray[np.float64]:
    """The bus times the firmware's frames (identifiers ``ids``) were sent at, sorted (module
    docstring)."""
    times = np.asarray(frames.timestamp_s, dtype=np.float64).copy()
    mine = np.isin(frames.can_id, ids)
    rows, keys = [], []
    for name in TICK_GROUP:
        try:
            d = decoder.decode(frames, name)
        except DecodeError:
            continue
        if "ENC_COUNTER" not in d or "COUNTER" not in d:
            continue
        rows.append(np.asarray(d["index"], dtype=np.int64))
        keys.append(np.asarray(d["COUNTER"], dtype=np.int64) * 256
                    + np.asarray(d["ENC_COUNTER"], dtype=np.int64))
    if rows:
        _take_earliest(times, np.concatenate(rows), np.concatenate(keys))
    return np.sort(times[mine])


def _take_earliest(times: npt.NDArray[np.float64], index: npt.NDArray[np.int64],
                   keys: npt.NDArray[np.int64]) -> None:
    """Each frame at ``index`` timed at the earliest frame of its key logged less than half a
    COUNTER lap before it (in place)."""
    window_s = LAP_TICKS // 2 * contract.cycle_time_s("WHEEL_ENCODERS")
    order = np.lexsort((times[index], keys))
    first_s: dict[int, float] = {}
    for k in order.tolist():
        key, at = int(keys[k]), int(index[k])
        earliest = first_s.get(key)
        if earliest is None or times[at] - earliest >= window_s:
            first_s[key] = earliest = float(times[at])
        times[at] = earliest


def bus_off_silences(frames: FrameArrays, decoder: BulkDecoder, track: EncoderTrack,
                     silences: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The silences ([first, end) ticks of ``track``) that were the firmware's bus-off, not a
    stall: its first ODOM_STATUS summary after the silence (CRC holding) reports BUS_OFF and no
    TIME_LOST that the last one before it did not. A bus-off leaves the MCU running: it ticks on,
    its controller hears nothing (``FirmwareBoard.run_tick``'s status interrupt). Replayed as a
    halt, the firmware took the frames after the recovery as a stalled MCU takes its backlog:
    pmir circle 5, 15 s, ``delay=0.3:50,busoff=5:1,reboot=12,dup=0.1``, a step of (474, 641)
    counts at 6.02 s where the recording firmware's E2E window, widened by 100 frame-less ticks,
    refused frames until 6.10 s."""
    return [silence for silence, new in zip(silences, new_error_bits(
        frames, decoder, track, silences), strict=True)
            if new & ErrorFlag.BUS_OFF and not new & ErrorFlag.TIME_LOST]


def new_error_bits(frames: FrameArrays, decoder: BulkDecoder, track: EncoderTrack,
                   silences: list[tuple[int, int]]) -> list[int]:
    """Per silence ([first, end) ticks of ``track``): the ERROR_MASK bits its first ODOM_STATUS
    summary after it (CRC holding) reports that the last one before it did not (0: no summary
    after it, or none decodable)."""
    none = [0] * len(silences)
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", 0)
    except DecodeError:
        return none
    if "ERROR_MASK" not in page or not len(track.tick):
        return none
    good = crc_holds(frames, decoder, page["index"])
    at, masks = page["index"][good], page["ERROR_MASK"][good].astype(np.int64)
    times = np.asarray(frames.timestamp_s, dtype=np.float64)[at]
    found = []
    for first, end in silences:
        before_s = float(track.timestamp_s[max(int(np.searchsorted(track.tick, first)) - 1, 0)])
        after = int(np.searchsorted(track.tick, end))
        after_s = float(track.timestamp_s[min(after, len(track.tick) - 1)])
        k_before = int(np.searchsorted(times, before_s, "right")) - 1
        k_after = int(np.searchsorted(times, after_s))
        if k_after >= len(times):
            found.append(0)
            continue
        was = int(masks[k_before]) if k_before >= 0 else 0
        found.append(int(masks[k_after]) & ~was)
    return found
