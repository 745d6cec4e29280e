"""Which logged frames carry their sender's Profile 2 CRC, whatever the host's E2E window said of
their COUNTER: the one test the judges read as "the sender sent it" (a page, pose or encoder
frame refused by sequence is still evidence)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import crc8h2f_p02, e2e_messages


def crc_right(frames: FrameArrays, decoder: BulkDecoder, rows: npt.NDArray[np.int64], name: str,
              *, unprotected: bool) -> npt.NDArray[np.bool_]:
    """Per row of ``rows`` (frames of message ``name``): whether its CRC is right;
    ``unprotected``: the answer for every row when the DBC gives ``name`` no E2E protection."""
    config = e2e_messages(decoder.db).get(decoder.message(name).frame_id)
    if config is None or config.data_ids is None:
        return np.full(len(rows), unprotected, dtype=bool)
    data = frames.data[rows]
    ids = np.array(config.data_ids, dtype=np.uint8)[data[:, 1] & ENC_COUNTER_MASK]
    good: npt.NDArray[np.bool_] = crc8h2f_p02(data, ids) == data[:, 0]
    return good
