"""A mailbox overflow after the last lost-frames page, behind a latched REASON.

``losses.overflow_reported_after`` counts every encoder frame after the last ODOM_STATUS page 2
(ENC_E2E_LOST) as possibly lost when a later summary says the firmware lost frames. It read
that from REASON == MAILBOX_OVERFLOW alone; but REASON keeps a latched cause (COUNTER_RESET, and
since issue #11 point 5 POSE_UNCERTAIN, which a mailbox overflow merging a long step raises in
the very same tick) and the overflow then shows only as the sticky ERROR_MASK bit. Such a summary
now counts too; a latched REASON without the bit, or any summary before the page, does not.

The frames are encoded here with cantools from the DBC (nothing of the judge's).
"""

from __future__ import annotations

import can
import numpy as np
import pytest

from odocan.firmware.errors import ErrorFlag
from odocan.host.io.logs import FrameCollector
from odocan.host.judge.losses import overflow_reported_after
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.contract import database

DB = database()
STATUS = DB.get_message_by_name("ODOM_STATUS")
SUMMARY_BASE = {"STATE": 1, "INTEGRATOR": 2, "UPTIME": 9}  # DEGRADED, EXACT, 9 s
PAGE2 = {"PAGE": 2, "ENC_E2E_OK": 500, "ENC_E2E_LOST": 3, "ENC_E2E_REPEATED": 0,
         "ENC_E2E_CRC_ERROR": 0, "ENC_E2E_WRONG_SEQ": 0}


def _status(t_s: float, signals: dict[str, int]) -> can.Message:
    full = {"COUNTER": 0, "CHECKSUM": 0, **signals}
    data = STATUS.encode(full, scaling=False, strict=False)
    return can.Message(timestamp=t_s, arbitration_id=STATUS.frame_id, data=data,
                       is_extended_id=False)


def _summary(t_s: float, reason: str, mask: int) -> can.Message:
    raw = next(int(v) for v, n in (STATUS.get_signal_by_name("REASON").choices or {}).items()
               if str(n) == reason)
    return _status(t_s, {"PAGE": 0, **SUMMARY_BASE, "REASON": raw, "ERROR_MASK": mask})


def _reported(frames: list[can.Message], after: int) -> bool:
    collector = FrameCollector()
    for msg in frames:
        collector.on_message_received(msg)
    arrays = collector.arrays()
    accepted = np.ones(len(arrays), dtype=bool)
    return overflow_reported_after(arrays, accepted, BulkDecoder(DB), after)


OVERFLOW = int(ErrorFlag.MAILBOX_OVERFLOW)
UNCERTAIN = int(ErrorFlag.POSE_UNCERTAIN)
RESET = int(ErrorFlag.COUNTER_RESET)


@pytest.mark.parametrize(("reason", "mask", "reported"), [
    ("MAILBOX_OVERFLOW", OVERFLOW, True),  # as before
    ("POSE_UNCERTAIN", UNCERTAIN | OVERFLOW, True),  # the overflow behind the latched reason
    ("COUNTER_RESET", RESET | OVERFLOW, True),
    ("POSE_UNCERTAIN", UNCERTAIN, False),  # latched, but no overflow ever: nothing lost
])
def test_a_summary_after_the_last_page_says_whether_frames_were_lost(
    reason: str, mask: int, reported: bool
) -> None:
    frames = [_status(1.0, PAGE2), _summary(1.1, reason, mask)]
    assert _reported(frames, after=0) is reported
    assert _reported(frames[::-1], after=1) is False  # the summary came before the page
