"""Whether a hole of the log lies between two sends of a pose that its own COUNTER chains
(``samples._queued``): a recorder's chunk of 32 k periods takes 16 k poses (one every other
period) and brings their 4-bit COUNTER round, so the first pose of the burst after it follows
the last before it (COUNTER + 1) as if it were the next send (issue #11, rule 5:
``tests/test_recorder_gap16.py``, a pose paired 32 periods back, 73 mm off a correct
firmware). The encoder frames the log holds span the hole with evidence of their own: their
sender sequence (``senderseq.sender_seq``, widened by the time stamps and ``burst_laps``)
steps by the periods lost. A step of a whole COUNTER lap (16 periods) or more between the two
poses says the log lost at least 8 sends of the poses there, so their COUNTER step of 1 is no
proof of consecutive sends: the chain is not told, and the queued pose names no frame (left
out, not guessed)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP

LAP_PERIODS = ENC_COUNTER_LAP  # the encoder COUNTER's lap: a step this long is a hole of the log

IntArray = npt.NDArray[np.int64]


def hole_between(enc_index: IntArray, enc_seq: IntArray, before: int, after: int) -> bool:
    """Whether the accepted encoder frames (log positions ``enc_index``, sender sequence
    ``enc_seq``) step by ``LAP_PERIODS`` or more anywhere from the latest one before log
    position ``before`` to the latest one before log position ``after``."""
    lo = max(int(np.searchsorted(enc_index, before)) - 1, 0)
    hi = int(np.searchsorted(enc_index, after))
    if hi - lo < 2:
        return False
    return bool(np.any(np.diff(enc_seq[lo:hi]) >= LAP_PERIODS))
