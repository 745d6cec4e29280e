"""Which ODOM_STATUS summaries of a whole log the bus held back and say no reboot, and which
power-up ticks' poses it held back with them (``host.judge.livelatestatus``), for
``host.judge.reboots`` and ``host.judge.stream_lives``."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootticks import pose_rows, status_rows
from odocan.host.judge.livelatestatus import StatusOrder, held_back
from odocan.host.protocol.decode import BulkDecoder

if TYPE_CHECKING:
    from odocan.host.judge.sources import SourceWatch


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


def pose_zeros_held(order: StatusOrder, latest: bool, frames: FrameArrays, decoder: BulkDecoder,
                    positions: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.bool_], bool]:
    """Per frame at ``positions`` (in order): whether the latest ODOM_POSE_X of COUNTER 0 heard
    before it (CRC holding, whatever its sequence) was held back behind later poses of its
    sender, ``order`` (``livelatestatus``; the live ``SourceWatch.hear_pose``'s) hearing every
    such pose of ``frames`` in bus order; and that of the last of them all (``latest``: of the
    poses before ``frames``, a stream's earlier chunks). A power-up tick whose pose and summary
    were both held back is an old life's, no reboot (``SourceWatch.observe``)."""
    where, _, counters = pose_rows(frames, decoder)
    held = np.array([order.hear(c) for c in counters.tolist()], dtype=bool)
    zeros = np.flatnonzero(counters == 0)
    k = np.searchsorted(where[zeros], positions) - 1  # the latest strictly before each
    found = held[zeros][np.maximum(k, 0)] if len(zeros) else np.zeros(len(positions), bool)
    return np.where(k >= 0, found, latest), bool(held[zeros[-1]]) if len(zeros) else latest


def zero_poses_held_back(frames: FrameArrays, decoder: BulkDecoder,
                         positions: npt.NDArray[np.int64],
                         late: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """``pose_zeros_held`` of a whole log's summaries at ``positions``, read only when one of
    them was held back (``late``: ``summaries_held_back``; none: it cannot matter)."""
    if not late.any():
        return np.zeros(len(positions), dtype=bool)
    return pose_zeros_held(StatusOrder(), False, frames, decoder, positions)[0]


def heard_in_chunk(watch: SourceWatch, chunk: FrameArrays, decoder: BulkDecoder,
                   positions: npt.NDArray[np.int64], said: list[tuple[int, str]],
                   keep: npt.NDArray[np.bool_] | None = None
                   ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """A stream's chunk heard on its ``watch``'s orders, as the live ``SourceWatch`` hears it:
    per summary at chunk ``positions`` (``said``: their UPTIME and STATE), ``held_back_heard``
    (its ODOM_STATUS frames on ``watch.order``) and ``pose_zeros_held`` (its ODOM_POSE_X on
    ``watch.pose_order``; ``watch.pose_late`` carried to the next chunk); those at ``keep``
    (None: all)."""
    late = held_back_heard(watch.order, chunk, decoder, positions, said)
    zeros, watch.pose_late = pose_zeros_held(watch.pose_order, watch.pose_late, chunk, decoder,
                                             positions)
    return (late, zeros) if keep is None else (late[keep], zeros[keep])
