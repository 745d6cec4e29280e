"""The late-naming rule (``host.judge.latenames``) over a life given chunk by chunk: whether a
pose or twist frame the host's E2E took was held back on the bus, so that the whole log's judge
names it where it was sent (issue #11: a late frame named where it was heard FAILed a correct
firmware under ``delay=0.5:150``).

The scan is the whole log's, ``latenames.LateScan``, fed each chunk's CRC-right frames of the
message in bus order: it reads every frame as the whole log's scan does (it looks back only,
and carries what it looks back at). The stream does not move a named frame back across its
chunks (``stream.StreamPoses``, ``stream_twist.StreamTwist`` and the distance judge resolve a
name where the frame was heard): a life with a late frame taken is refused
(``stream_first.FirstPass.refuse``: ``NotStreamable``) and judged whole, by the rule. On a life
without one the rule moves nothing, and both judges read the same names."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.latenames import LateScan, crc_right_positions
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, POSE_PERIOD_S
from odocan.host.protocol.decode import BulkDecoder

LATE_MESSAGES = ("ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST")  # named where sent (latenames)
REFUSAL = ("a pose or twist frame held back on the bus (latenames: the whole log's judge names "
           "it where it was sent)")


class StreamLate:
    """Per message of ``LATE_MESSAGES``, ``LateScan`` over the chunks; ``found``: a frame the
    host's E2E took was late (``latenames.sent_places`` would move it)."""

    def __init__(self, decoder: BulkDecoder) -> None:
        self.decoder = decoder
        self.scans = {name: LateScan(POSE_PERIOD_S) for name in LATE_MESSAGES}
        self.found = False

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> None:
        """A chunk (bus order) and the host's E2E verdicts on its frames."""
        for name, scan in self.scans.items():
            good = crc_right_positions(chunk, self.decoder, name)
            counter = (chunk.data[good, 1] & ENC_COUNTER_MASK).astype(np.int64)
            late, _ = scan.feed(chunk.timestamp_s[good].tolist(), counter.tolist())
            self.found |= bool(np.any(np.asarray(late, dtype=bool) & accepted[good]))
