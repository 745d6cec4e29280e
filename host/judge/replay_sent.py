"""When the firmware sent its frames, as far as the log tells (``replay_lives``' silences; issue
#11).

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

from odocan.host.io.logs import FrameArrays
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
