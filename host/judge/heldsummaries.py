"""Which ODOM_STATUS summaries of a log the bus held back and say no reboot, and which
frames it held back are no power-up tick's evidence (``host.judge.livelatestatus``,
``host.judge.liveheldpose``), for ``host.judge.reboots`` and ``host.judge.stream_lives``."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.bootticks import pose_rows, status_rows
from odocan.host.judge.liveheldpose import PoseOrder
from odocan.host.judge.livelatestatus import StatusOrder, held_back
from odocan.host.protocol.decode import BulkDecoder

Flags = npt.NDArray[np.bool_]

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


def pose_zeros_held(order: PoseOrder, latest: bool, frames: FrameArrays, decoder: BulkDecoder,
                    positions: npt.NDArray[np.int64]
                    ) -> tuple[npt.NDArray[np.bool_], bool, npt.NDArray[np.bool_]]:
    """Per frame at ``positions`` (in order): whether the latest ODOM_POSE_X of COUNTER 0 heard
    before it (CRC holding, whatever its sequence) was held back behind later poses of its
    sender within a sequence unbroken since, ``order`` (``liveheldpose``; the live
    ``SourceWatch.hear_pose``'s) hearing every such pose of ``frames`` in bus order; and that
    of the last of them all (``latest``: of the poses before ``frames``, a stream's earlier
    chunks). Its break of the pose sequence is no power-up tick's evidence
    (``SourceWatch.observe``). And per ODOM_POSE_X row (``bootticks.pose_rows``) whether it
    was held back (``aheadticks``)."""
    where, times, counters = pose_rows(frames, decoder)
    held = np.array([order.hear(c, t) for c, t in zip(counters.tolist(), times.tolist(),
                                                      strict=True)], dtype=bool)
    zeros = np.flatnonzero(counters == 0)
    k = np.searchsorted(where[zeros], positions) - 1  # the latest strictly before each
    found = held[zeros][np.maximum(k, 0)] if len(zeros) else np.zeros(len(positions), bool)
    return (np.where(k >= 0, found, latest), bool(held[zeros[-1]]) if len(zeros) else latest,
            held)


def statuses_held(order: StatusOrder, latest: bool, frames: FrameArrays, decoder: BulkDecoder,
                  summaries: tuple[npt.NDArray[np.int64], list[tuple[int, str]]]
                  ) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_], tuple[bool, bool]]:
    """Per summary at ``summaries``' positions (its UPTIME and STATE; its CRC holding), every
    ODOM_STATUS frame of ``frames`` heard on ``order`` in bus order (the live
    ``SourceWatch.hear_status``'s): whether it is passed over (``StatusOrder.passed_over``),
    and whether it or the frame heard before it was held back (``latest``: the last frame
    before ``frames``, a stream's earlier chunks): a step of their COUNTERs is no power-up
    tick's evidence (``SourceWatch.observe``); and whether the last two frames were (the
    watch's ``status_late``)."""
    where, _, counters = status_rows(frames, decoder)
    positions, said = summaries
    at = np.searchsorted(where, positions)
    told: dict[int, tuple[int, str]] = dict(zip(at.tolist(), said, strict=True))
    late, over = np.zeros(len(where) + 1, bool), np.zeros(len(where), bool)
    late[0] = latest
    for k, counter in enumerate(counters.tolist()):
        late[k + 1] = order.hear(counter)
        if k in told:
            over[k] = order.passed_over(*told[k])
    return over[at], late[at] | late[at + 1], (bool(late[-2]) if len(where) > 1 else latest,
                                               bool(late[-1]))


def held_evidence(frames: FrameArrays, decoder: BulkDecoder, positions: npt.NDArray[np.int64],
                  needed: bool) -> npt.NDArray[np.bool_]:
    """Per summary of a whole log at ``positions``: ``SourceWatch.observe``'s ``held`` (the
    pose of COUNTER 0 before it, the summary or the ODOM_STATUS frame before it held back),
    read only when ``needed`` (a summary may be a power-up tick), else none."""
    if not needed:
        return np.zeros((len(positions), 2), dtype=bool)
    poses = pose_zeros_held(PoseOrder(), False, frames, decoder, positions)[0]
    said = [(0, "")] * len(positions)  # (passing over is ``summaries_held_back``'s)
    statuses = statuses_held(StatusOrder(), False, frames, decoder, (positions, said))[1]
    return np.stack((poses, statuses), axis=1)


def heard_in_chunk(watch: SourceWatch, chunk: FrameArrays, decoder: BulkDecoder,
                   positions: npt.NDArray[np.int64], said: list[tuple[int, str]],
                   keep: npt.NDArray[np.bool_] | None = None
                   ) -> tuple[Flags, Flags, Flags]:
    """A stream's chunk heard on its ``watch``'s orders, as the live ``SourceWatch`` hears it,
    per summary at chunk ``positions`` whose CRC holds at ``keep`` (``said``: each one's UPTIME
    and STATE): passed over, and ``SourceWatch.observe``'s ``held`` (``pose_zeros_held``,
    ``statuses_held``; what the chunk's last frames were carried on ``watch``); and per pose
    row of the chunk whether it was held back (``aheadticks``)."""
    keep = np.ones(len(positions), bool) if keep is None else keep
    poses, watch.pose_late, rows = pose_zeros_held(watch.pose_order, watch.pose_late, chunk,
                                                   decoder, positions[keep])
    kept = [s for s, k in zip(said, keep.tolist(), strict=True) if k]
    over, statuses, watch.status_late = statuses_held(watch.order, watch.status_late[1], chunk,
                                                      decoder, (positions[keep], kept))
    return over, np.stack((poses, statuses), axis=1), rows
