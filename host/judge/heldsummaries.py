"""Which ODOM_STATUS summaries of a whole log the bus held back and say no reboot
(``host.judge.livelatestatus``), for ``host.judge.reboots``."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootticks import status_rows
from odocan.host.judge.livelatestatus import StatusOrder, held_back
from odocan.host.protocol.decode import BulkDecoder


def summaries_held_back(frames: FrameArrays, decoder: BulkDecoder,
                        summaries: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64],
                                         npt.NDArray[np.object_]]) -> npt.NDArray[np.bool_]:
    """Which ``summaries`` (positions, UPTIMEs, STATE names; their CRC holding) the bus held
    back behind later ODOM_STATUS frames and say no reboot (``livelatestatus``)."""
    positions, uptimes_s, states = summaries
    where, _, counters = status_rows(frames, decoder)
    said: list[tuple[int, str] | None] = [None] * len(where)
    for at, uptime_s, state in zip(np.searchsorted(where, positions).tolist(),
                                   uptimes_s.tolist(), states.tolist(), strict=True):
        said[at] = (int(uptime_s), str(state))
    over = np.array(held_back(counters.tolist(), said), dtype=bool)
    return over[np.searchsorted(where, positions)] if len(where) else np.zeros(len(positions),
                                                                               bool)


def held_back_heard(order: StatusOrder, chunk: FrameArrays, decoder: BulkDecoder,
                    positions: npt.NDArray[np.int64], said: list[tuple[int, str]]
                    ) -> npt.NDArray[np.bool_]:
    """A stream's ``summaries_held_back``: which summaries at chunk ``positions`` (``said``:
    their UPTIME and STATE) the bus held back behind later ODOM_STATUS frames and say no
    reboot, every status frame of the chunk whose CRC holds heard on ``order`` (the watch's:
    ``hear_all``)."""
    where, _, counters = status_rows(chunk, decoder)
    at = np.searchsorted(where, positions)
    found = at < len(where)
    found[found] = where[at[found]] == positions[found]
    summaries: list[tuple[int, str] | None] = [None] * len(where)
    for k, summary in zip(at[found].tolist(), np.array(said, dtype=object)[found].tolist()
                          if said else [], strict=True):
        summaries[k] = (int(summary[0]), str(summary[1]))
    over = np.array(order.hear_all(counters.tolist(), summaries), dtype=bool)
    return found & over[np.minimum(at, max(len(where) - 1, 0))] if len(where) else found
