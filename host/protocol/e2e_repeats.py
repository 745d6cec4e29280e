"""Encoder frames the host took as a COUNTER cycle on (``e2e_cycles``) that the firmware counted
as repeats, told by its ENC_E2E pages (issue #11: a FAIL must never blame a correct firmware).

A WHEEL_ENCODERS frame of the last valid COUNTER half a cycle or more after it is no repeat to
the host but the sender's frame 16 * k periods on (``SequenceState``): a recorder that dropped
the frames between lost them, not the firmware, which had them and took this one. After a
silence of the whole bus (a bus-off) no one had them: the firmware's E2E check (Profile 2, no
such rule) refuses the frame as REPEATED and keeps its last frame, of the same COUNTER, 16 * k
periods older. On kobuki figure8, seed 446, ``busoff=2:0.3,delay=0.3:55``: COUNTER 7 of 1.99 s,
then the bus off for 0.3 s, then COUNTER 7 of 2.31 s, two cycles on: the firmware refused it
(ENC_E2E_REPEATED 0 -> 1 between its pages at 1.9 s and 2.5 s) and its poses went on naming
the COUNTER 7 of 1.99 s, which the host paired with the one of 2.31 s: the pose 121.6 mm and
169.9 mrad off a right firmware.

The firmware counts its repeats: ENC_E2E_REPEATED (u8) on the ENC_E2E page. Between two such
pages, where it grew by more than the frames the host refused as repeats there (give or take
``RACE_FRAMES`` before each page: a frame on the bus just before a page may be drained after
it), the host's frames of a new cycle there are its repeats too, when there are no more of
them than the repeats the host lacks (else which ones is not known: none changes). Refusing
such a frame changes no later verdict: a new cycle keeps the window and the last COUNTER (the
same) as a repeat does. Pages after a reboot or a wrapped count prove nothing.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.e2e_evidence import RACE_FRAMES, S_LOST, S_OK, S_REPEATED
from odocan.host.protocol.e2e_pages import OkPages

U8_MASK = 0xFF
IntArray = npt.NDArray[np.int64]


def new_cycles_taken(status: npt.NDArray[np.int8], counter: IntArray) -> npt.NDArray[np.bool_]:
    """Per frame (bus order, ``status`` of one message's frames, ``counter`` their COUNTERs):
    taken with the COUNTER of the frame taken before it (a new cycle: ``e2e_cycles``)."""
    taken = np.flatnonzero((status == S_OK) | (status == S_LOST))
    found = np.zeros(len(status), dtype=bool)
    if len(taken) > 1:
        same = (counter[taken[1:]] & 0x0F) == (counter[taken[:-1]] & 0x0F)
        found[taken[1:][same]] = True
    return found


def repeats_by_pages(status: npt.NDArray[np.int8], counter: IntArray,
                     enc_pos: npt.NDArray[np.intp], pages: OkPages | None
                     ) -> npt.NDArray[np.int8]:
    """``status`` (the encoder frames at bus positions ``enc_pos``, COUNTERs ``counter``) with
    the new cycles the firmware's pages prove it counted as repeats refused (module
    docstring)."""
    if pages is None or pages.repeated is None or len(pages.at) < 2:
        return status
    fresh = new_cycles_taken(status, counter)
    if not fresh.any():
        return status
    bounds = np.searchsorted(enc_pos, pages.at)
    repeated = status == S_REPEATED
    out = status
    for span in range(len(pages.at) - 1):
        lo, hi = int(bounds[span]), int(bounds[span + 1])
        inside = np.flatnonzero(fresh[lo : max(hi - RACE_FRAMES, lo)]) + lo
        if len(inside) == 0:
            continue
        firmware = (int(pages.repeated[span + 1]) - int(pages.repeated[span])) & U8_MASK
        if firmware > hi - lo + RACE_FRAMES:  # a reboot, a wrapped count
            continue
        most = int(np.count_nonzero(repeated[max(lo - RACE_FRAMES, 0) : hi + RACE_FRAMES]))
        if 0 < len(inside) <= firmware - most:
            out = out.copy() if out is status else out
            out[inside] = S_REPEATED
    return out
