"""The ODOM_ACK rows the set-pose and config cuts follow (``host.judge.setposes``, ``.configs``,
``.stream_cuts``), their E2E sequence judged afresh in each firmware life.

A rebooted firmware restarts its ODOM_ACK COUNTER at 0: checked over the whole log, its first
ACK is a repeat when the old firmware's last one had COUNTER 0 too (one field staged before the
reboot), and is dropped. The cuts forget the staging at each reboot (the firmware's RAM), so a
field staged again after the reboot and ACKed so went unseen: a correct firmware that applied
it FAILed. The live judges restart their E2E check at a reboot (``sources.start_new_life``);
here each firmware life's ACKs are checked on their own (Profile 2 judges each message's
sequence alone, so the ACK frames alone give the same verdicts as the whole life)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import check_frames

ACK = "ODOM_ACK"


def ack_positions(frames: FrameArrays, decoder: BulkDecoder) -> npt.NDArray[np.intp]:
    """The positions of ``frames``' ODOM_ACK frames (none when the DBC lacks it)."""
    try:
        return decoder.select(frames, ACK)
    except (DecodeError, KeyError):
        return np.zeros(0, dtype=np.intp)


def ack_rows(acks: FrameArrays, positions: npt.NDArray[np.int64], decoder: BulkDecoder,
             reboots: Sequence[int]) -> dict[str, np.ndarray]:
    """The accepted decoded rows of ``acks`` (ODOM_ACK frames at log ``positions``, in bus
    order), their E2E checked per firmware life (``reboots``: where the lives after the first
    start); ``index``: the log position, as ``setposes.optional_rows``."""
    accepted = np.zeros(len(acks), dtype=bool)
    bounds = np.searchsorted(positions, np.array([*reboots], dtype=np.int64)).tolist()
    for start, stop in zip([0, *bounds], [*bounds, len(acks)], strict=True):
        if stop > start:
            accepted[start:stop] = check_frames(acks.select(np.arange(start, stop)),
                                                decoder.db)[1]
    try:
        rows = decoder.decode(acks, ACK)
    except (DecodeError, KeyError):
        return {"index": np.zeros(0, dtype=np.int64)}
    keep = accepted[rows["index"]]
    rows = {key: value[keep] for key, value in rows.items()}
    rows["index"] = positions[rows["index"]].astype(np.int64)
    return rows


def acks_by_life(frames: FrameArrays, decoder: BulkDecoder,
                 reboots: Sequence[int]) -> dict[str, np.ndarray]:
    """``ack_rows`` of a whole log's ODOM_ACK frames."""
    positions = ack_positions(frames, decoder).astype(np.int64)
    return ack_rows(frames.select(positions), positions, BulkDecoder(decoder.db), reboots)
