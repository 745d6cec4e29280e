"""The encoder frames the host refused that the firmware may have taken, for the DISTANCE judge's
``skipped`` spans (``losses.ok_count_spans``; issue #11, rule 5: a FAIL never blames a correct
firmware).

A span's n (the firmware's ENC_E2E_OK grew by n less than the host's accepted frames) is net: a
frame the firmware took that the host refused hides one more of the host's frames it skipped
(``losses.ok_count_spans``). Under a ``delay`` fault both receivers refuse late frames, but not the
same ones: after a 50 ms stall (pmir, random, seed 5, ``stall=2:0.05,delay=0.1:30``) the host took
the late frame 0xE (sent at 2.06 s, heard at 2.09 s) for the next lap's (a step back, then 44
counts on) and refused the late 0xD, while the firmware took 0xD and 0xE in their order and refused
0xF and 0x0: net n = 1, but two of the host's frames skipped, its path 3.77 mm (4 counts) below the
reference's, where the window of n = 1 allowed 0.942 mm (DISTANCE FAILed 2.294 mm beyond,
``tests/test_trial36.py``). Each such late frame (``late``: its COUNTER behind the host's latest;
CRC right: the sender's, whatever the host's E2E window said) inside a span may be one taken in
place of another, so the span's n grows by one per frame: n + k frames skipped at most, each merged
step shorter by the defect ``skipdefect`` bounds (taking a frame only adds path: |a| + |b| >= |a +
b|). The defect is 0 unless the midpoint reverses, so a span on a steady drive gains nothing; past
``skipdefect.MAX_RUN`` the span's fine path bounds it, as before. Spans whose net n is 0 or less
are not widened (a swap there is not modelled).

The frames are placed by the accepted encoder frame after each (its position among the accepted
ones): the step into that frame is the one a frame taken before it splits. Whole
(``refused_places``) and streamed (``StreamLosses``, chunk by chunk with an offset) give the
same places."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.samples import IntArray
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e_rows import crc_right

LATE_BEHIND = 7  # COUNTER periods behind: late, not the next lap's (under half the 16)


def refused_places(frames: FrameArrays, accepted: npt.NDArray[np.bool_], decoder: BulkDecoder,
                   enc_index: IntArray, enc_counter: IntArray, index_offset: int = 0,
                   counter_before: int | None = None) -> IntArray:
    """Per WHEEL_ENCODERS frame of ``frames`` the host refused as late (``late``: its COUNTER
    behind the latest accepted frame's) whose CRC holds: the position (among the accepted
    encoder frames, their log rows ``enc_index`` and COUNTERs ``enc_counter``) of the first
    accepted one after it. ``index_offset``: the rows of ``frames`` before it in the log (a
    chunk's); ``counter_before``: the COUNTER of the latest accepted frame before it (None:
    none)."""
    try:
        rows = decoder.select(frames, "WHEEL_ENCODERS")
    except DecodeError:
        return np.zeros(0, dtype=np.int64)
    refused = rows[~accepted[rows]]
    good = crc_right(frames, decoder, refused, "WHEEL_ENCODERS", unprotected=False)
    data = frames.data[refused]
    places: IntArray = np.searchsorted(enc_index, refused + index_offset).astype(np.int64)
    before = np.concatenate(([-1 if counter_before is None else counter_before],
                             np.asarray(enc_counter, dtype=np.int64)))[places]
    keep = good & late(before, data[:, 1].astype(np.int64) & ENC_COUNTER_MASK)
    kept: IntArray = places[keep]
    return kept


def late(counter_before: IntArray, counter: IntArray) -> npt.NDArray[np.bool_]:
    """Whether each frame's COUNTER is 1 .. ``LATE_BEHIND`` behind the latest accepted frame's
    before it (``counter_before``, -1: none): a frame the bus let out late, which a receiver
    may take in its order where the other took the frames after it. A frame the host refused
    on its window's periods (a jittered capture: ahead, not behind) was no late one: the
    firmware may have taken it too, but in its place, no swap (a DISTANCE 2 mm low after a
    lock-out PASSed when those counted, ``tests/test_twist_jitter_distance.py``)."""
    behind = (counter_before - counter) & ENC_COUNTER_MASK
    out: npt.NDArray[np.bool_] = (counter_before >= 0) & (behind >= 1) & (behind <= LATE_BEHIND)
    return out


def widened(spans: list[tuple[int, int, int]], places: IntArray
            ) -> list[tuple[int, int, int]]:
    """``spans`` (first, last, n) with n grown by the ``places`` (sorted) in (first, last + 1]:
    the steps of the span a frame the host refused may have split."""
    if len(places) == 0:
        return spans
    out = []
    for a, z, n in spans:
        k = int(np.searchsorted(places, z + 1, side="right") - np.searchsorted(places, a,
                                                                                 side="right"))
        out.append((a, z, n + k))
    return out
