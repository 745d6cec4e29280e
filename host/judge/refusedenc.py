"""The WHEEL_ENCODERS frames the host's E2E refused whose Profile 2 CRC is right: frames the
firmware may have taken (its E2E state is its own), their counts the log's own
(``aheadnamed``: a pose naming one is judged at its counts, not only by the reach of its
accepted neighbours)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.latenames import crc_right_positions
from odocan.host.protocol.decode import BulkDecoder

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Refused:
    """The refused CRC-right encoder frames, in bus order: stamp, COUNTER, LEFT/RIGHT_COUNT."""

    t_s: FloatArray
    counter: IntArray
    left: IntArray
    right: IntArray


def refused_encoders(frames: FrameArrays, accepted: npt.NDArray[np.bool_],
                     decoder: BulkDecoder) -> Refused:
    """``Refused`` of ``frames`` (``accepted``: the host's E2E verdicts)."""
    rows = decoder.decode(frames, "WHEEL_ENCODERS")
    index = rows["index"].astype(np.int64)
    keep = ~accepted[index] & np.isin(index, crc_right_positions(frames, decoder,
                                                                 "WHEEL_ENCODERS"))
    return Refused(rows["timestamp_s"][keep].astype(np.float64),
                   rows["COUNTER"][keep].astype(np.int64),
                   rows["LEFT_COUNT"][keep].astype(np.int64),
                   rows["RIGHT_COUNT"][keep].astype(np.int64))
