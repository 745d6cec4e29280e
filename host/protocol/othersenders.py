"""Another sender on a command's message while the command is in flight (issue #11: two tools
commanding one robot; ``host.judge.twosenders`` tells the judges' side).

A ``CommandSession`` (the pytest kit, the experiments) waits for the ODOM_ACK whose
REQUEST_ID and REQUEST_COUNTER are its committing frame's. A second tool with its own COUNTER
sequence on the same message breaks that: the firmware drops the second of two frames of one
COUNTER unanswered (E2E REPEATED), so the other tool's ACK answers the session's key, and both
tools' staged writes share one staged set. Found by the trial: a session whose config the
firmware never took (the other tool's frames of the same COUNTERs came first) returned its
ACK, as done.

``foreign_frame`` reads the frames heard since the command's first frame went out: a CRC-right
frame of the command's message that is none of the command's own frames is another sender's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from odocan.host.io.frames import FLAG_ERROR, FLAG_EXTENDED, FLAG_REMOTE, FrameArrays
from odocan.host.protocol.e2e import E2EMessage
from odocan.host.protocol.e2e_crc import crc8h2f_p02_one

COUNTER_MASK = 0x0F  # the E2E Profile 2 COUNTER (byte 1, low nibble)
NOT_A_STANDARD_DATA_FRAME = FLAG_EXTENDED | FLAG_REMOTE | FLAG_ERROR


def foreign_frame(heard: FrameArrays, since: int, message: E2EMessage,
                  own: Sequence[bytes]) -> bytes | None:
    """The first CRC-right 8-byte frame of ``message`` among ``heard[since:]`` that is not one
    of ``own`` (the command's frames); None when there is none (or ``message`` is not
    protected: no CRC tells a frame from noise)."""
    if message.data_ids is None:
        return None
    rows = np.flatnonzero((heard.can_id == message.key) & (heard.dlc == 8)
                          & ((heard.flags & NOT_A_STANDARD_DATA_FRAME) == 0))
    mine = set(own)
    for row in rows[rows >= since].tolist():
        data = bytes(heard.data[row])
        crc_right = crc8h2f_p02_one(data, message.data_ids[data[1] & COUNTER_MASK]) == data[0]
        if crc_right and data not in mine:
            return data
    return None


def contested_reason(message: str, data: bytes) -> str:
    """``CommandNotAcked``'s reason when another sender's ``data`` was heard."""
    return (f"contested: another sender's {message} frame (COUNTER {data[1] & COUNTER_MASK}) "
            "heard while this command was in flight: the firmware's ODOM_ACK names only a "
            "COUNTER, a second frame of one COUNTER is dropped unanswered and both senders' "
            "writes share one staged set, so it is not known to be applied as sent")
