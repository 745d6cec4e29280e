"""An accepted encoder frame that a refused frame of its COUNTER came shortly before: a twist
naming that COUNTER may name either (issue #11: a FAIL must never blame a correct firmware).

kobuki circle 714, 9 s, ``drop=0.05,stall=1.5:0.3,delay=0.3:150``: the firmware stalled from 1.50
to 1.80 s; the encoder frame of COUNTER 6 sampled at 1.66 s (left 7999 counts), held back 150 ms,
was heard at 1.81 s, before the frames of 1.81 s (COUNTER 5, 8776) and 1.82 s (COUNTER 6 again,
8828). The host's E2E, two periods after COUNTER 3 of 1.79 s, refused it (a jump of 3); the
firmware, back from its stall with the window wide open (last valid COUNTER 5 of 1.49 s), took
it as the next frame, a step of 33 periods forward, and refused the two after it (WRONGSEQUENCE,
REPEATED). Its twist of 1.821 s (ENC_COUNTER 6, DISTANCE 764 mm) named that frame; resolved from
the latest accepted frame (``samples.match_encoder``) the name lands on the frame of 1.82 s, 829
counts (80 mm) on: the DISTANCE judge pinned the firmware 80 mm below the reference there and
76 mm above the next sample's room, 74.5 mm beyond its tolerance, though the firmware's steps
are the truth's (every count forward) and its pose is within 0.1 mm.

``samples.twinned_encoder_frames`` tells a refused frame of the same COUNTER logged AFTER an
accepted one (its twin); this is the mirror: a refused frame whose CRC is right, then, less than
half a COUNTER cycle (8 periods) later and before any other accepted frame of that COUNTER, an
accepted frame of the same COUNTER with other counts. A twist naming that frame is left out of
the DISTANCE judge (not guessed); the next one naming a later frame pins the firmware again, so
a wrong DISTANCE is still seen there (``tests/test_distance_late.py``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.samples import HALF_LAP, IntArray, contract_cycle_s
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK as MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, e2e_messages


def early_twins(rows: dict[str, np.ndarray], keep: npt.NDArray[np.bool_], data: np.ndarray,
                data_ids: tuple[int, ...], cycle_s: float | None) -> IntArray:
    """The accepted frames (their index among the accepted ones, ``keep``) of ``rows`` (the
    decoded WHEEL_ENCODERS frames in log order: COUNTER, LEFT_COUNT, RIGHT_COUNT, timestamp_s;
    ``data``: their bytes) that a refused frame of the same COUNTER and other counts, its
    Profile 2 CRC right (``data_ids``), came before, less than ``HALF_LAP`` cycles (``cycle_s``;
    None: any time) and no other accepted frame of that COUNTER between them."""
    none = np.zeros(0, dtype=np.int64)
    refused, kept = np.flatnonzero(~keep), np.flatnonzero(keep)
    if len(refused) == 0 or len(kept) == 0:
        return none
    counter = rows["COUNTER"].astype(np.int64)
    ids = np.asarray(data_ids, dtype=np.uint8)[counter[refused] & MASK]
    refused = refused[crc8h2f_p02(data[refused], ids) == data[refused, 0]]
    found = np.full(len(refused), -1, dtype=np.int64)  # index among the accepted frames
    first = np.searchsorted(kept, refused)  # the first accepted frame after each
    for step in range(HALF_LAP):  # a frame of the same COUNTER lies at most 8 accepted on
        j = first + step
        open_ = (found < 0) & (j < len(kept))
        at = kept[np.minimum(j, len(kept) - 1)]
        same = open_ & (counter[at] == counter[refused])
        found[same] = j[same]
    hit = found >= 0
    refused, at = refused[hit], kept[found[hit]]
    other = ((rows["LEFT_COUNT"][at] != rows["LEFT_COUNT"][refused])
             | (rows["RIGHT_COUNT"][at] != rows["RIGHT_COUNT"][refused]))
    if cycle_s is not None:
        other &= rows["timestamp_s"][at] - rows["timestamp_s"][refused] < HALF_LAP * cycle_s
    return np.unique(found[hit][other]).astype(np.int64)


def early_twins_of(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder
                   ) -> IntArray:
    """``early_twins`` of a log's (or a chunk's) WHEEL_ENCODERS frames (``accepted``: the E2E
    verdict of every frame)."""
    config = next((m for m in e2e_messages(decoder.db).values() if m.name == "WHEEL_ENCODERS"),
                  None)
    if config is None or config.data_ids is None:
        return np.zeros(0, dtype=np.int64)
    try:
        rows = decoder.decode(frames, "WHEEL_ENCODERS")
    except DecodeError:
        return np.zeros(0, dtype=np.int64)
    return early_twins(rows, accepted[rows["index"]], frames.data[rows["index"]],
                       tuple(config.data_ids), contract_cycle_s(decoder, "WHEEL_ENCODERS"))


TAIL_ROWS = 4 * HALF_LAP  # encoder frames carried from chunk to chunk: a pair spans fewer


class EarlyTwinScan:
    """Whether a log fed chunk by chunk holds an early twin (``early_twins_of``; the last
    ``TAIL_ROWS`` encoder frames of each chunk carried into the next): the streamed analyze
    names twists without them and refuses such a log (``stream_first``), as it refuses twins."""

    def __init__(self, decoder: BulkDecoder) -> None:
        self.decoder = decoder
        self.found = False
        self._tail: tuple[dict[str, np.ndarray], npt.NDArray[np.bool_], np.ndarray] | None = None
        config = next((m for m in e2e_messages(decoder.db).values()
                       if m.name == "WHEEL_ENCODERS"), None)
        self._ids = None if config is None or config.data_ids is None else tuple(config.data_ids)
        self._cycle_s = contract_cycle_s(decoder, "WHEEL_ENCODERS")

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> bool:
        """Scan one chunk (``accepted``: its frames' E2E verdicts); ``found`` so far."""
        if self.found or self._ids is None:
            return self.found
        try:
            rows = self.decoder.decode(chunk, "WHEEL_ENCODERS")
        except DecodeError:
            return self.found
        keep, data = accepted[rows["index"]], chunk.data[rows["index"]]
        if self._tail is not None:
            rows = {k: np.concatenate((self._tail[0][k], v)) for k, v in rows.items()}
            keep, data = (np.concatenate((self._tail[1], keep)),
                          np.concatenate((self._tail[2], data)))
        self._tail = ({k: v[-TAIL_ROWS:] for k, v in rows.items()}, keep[-TAIL_ROWS:],
                      data[-TAIL_ROWS:])
        self.found = len(early_twins(rows, keep, data, self._ids, self._cycle_s)) > 0
        return self.found
