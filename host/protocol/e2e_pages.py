"""Encoder frames a starved recorder's stamps and the firmware's poses leave open, settled by the
firmware's own count of the frames it took (issue #11, rule 5: a FAIL never blames a correct
firmware; ``host.protocol.e2e_evidence``).

After a frame late on the bus the firmware's window (Profile 2, init 0, one period a tick)
trails the sender's COUNTER and refuses every frame on time for up to 15 periods (a lock-out);
its poses hold the late frame's name through it, which no longer tells that frame from the one
16 later, so ``pose_evidence`` proves nothing there, and a frame a starved recorder stamped late
in a release reads with a window periods too wide: the host took frames of the lock-out the
firmware refused (kobuki, seed 3, ``delay=0.1:15,seed=7``, recorder seed 2: 4 frames at its
end, and ODOM_TWIST's DISTANCE off the reference's path by 4.4 mm: FAIL).

The firmware says how many it took: ODOM_STATUS's ENC_E2E page carries ENC_E2E_OK (u16, frames
accepted since its boot). Between two such pages the host's accepted frames must number the
difference, give or take ``RACE_FRAMES`` before each page (a frame on the bus just before a
page may have been drained only after it). Where the host took more (``surplus``), and the
span holds frames of a recorder's release, those frames are judged again by the narrow reading
(their stamps late by up to ``CAPTURE_HOLD_CYCLES``: the window as narrow as the stamps allow;
the poses' proofs still first), and the new verdicts are kept where they bring every span that
changed to the firmware's count, and no span that agreed leaves it. A span the host took too few
in is left alone (a recorder that lost frames the firmware took says so too, and no reading of
the frames heard brings them back). Pages after a reboot or a wrapped count (a difference above
the frames heard in the span) prove nothing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.protocol.decode import frame_key, frame_keys
from odocan.host.protocol.e2e_evidence import RACE_FRAMES, S_LOST, S_OK

if TYPE_CHECKING:
    from odocan.host.protocol.dbcplan import DatabaseSpec, MessageSpec

PAGE_MESSAGE, PAGE_SIGNAL, OK_SIGNAL = "ODOM_STATUS", "PAGE", "ENC_E2E_OK"
REPEATED_SIGNAL = "ENC_E2E_REPEATED"  # u8 on the same page (``e2e_repeats``)
U16_MASK = 0xFFFF
NARROW = 2  # ``e2e_evidence.settle``'s reading numbers: 0 strict, 1 wide, 2 narrow; -1 none
IntArray = npt.NDArray[np.int64]
Settle = Callable[[npt.NDArray[np.int8] | None], npt.NDArray[np.int8]]


@dataclass(frozen=True)
class OkPages:
    """The ENC_E2E pages with a right CRC: their bus positions, ENC_E2E_OK (u16) and
    ENC_E2E_REPEATED (u8; None where the DBC lays it out otherwise)."""

    at: npt.NDArray[np.intp]
    ok: IntArray
    repeated: IntArray | None = None


def ok_pages(frames: FrameArrays, crc_ok: npt.NDArray[np.bool_],
             db: DatabaseSpec) -> OkPages | None:
    """The log's ENC_E2E pages (``crc_ok``: of every frame); None where the DBC has none or
    lays them out otherwise than little-endian unsigned."""
    try:
        message = db.get_message_by_name(PAGE_MESSAGE)
        page, ok = message.get_signal_by_name(PAGE_SIGNAL), message.get_signal_by_name(OK_SIGNAL)
    except KeyError:
        return None
    if (any(s.byte_order != "little_endian" or s.is_signed for s in (page, ok))
            or not ok.multiplexer_ids):
        return None
    key = frame_key(message.frame_id, message.is_extended_frame)
    at = np.flatnonzero((frame_keys(frames) == key) & (frames.dlc == message.length) & crc_ok)
    word = np.zeros(len(at), dtype=np.uint64)
    for byte in range(min(message.length, 8)):
        word |= frames.data[at, byte].astype(np.uint64) << np.uint64(8 * byte)
    page_no = (word >> np.uint64(page.start)) & np.uint64((1 << page.length) - 1)
    mine = page_no == np.uint64(ok.multiplexer_ids[0])
    count = (word[mine] >> np.uint64(ok.start)) & np.uint64((1 << ok.length) - 1)
    return OkPages(at[mine], count.astype(np.int64),
                   _repeated(message, word[mine], ok.multiplexer_ids[0]))


def _repeated(message: MessageSpec, word: npt.NDArray[np.uint64], page_id: int
              ) -> IntArray | None:
    """ENC_E2E_REPEATED of the pages' words (page ``page_id``), where the DBC lays it out as
    ENC_E2E_OK, on that page."""
    try:
        signal = message.get_signal_by_name(REPEATED_SIGNAL)
    except KeyError:
        return None
    if (signal.byte_order != "little_endian" or signal.is_signed
            or not signal.multiplexer_ids or signal.multiplexer_ids[0] != page_id):
        return None
    count = (word >> np.uint64(signal.start)) & np.uint64((1 << signal.length) - 1)
    return count.astype(np.int64)


def surplus(enc_pos: npt.NDArray[np.intp], status: npt.NDArray[np.int8],
            pages: OkPages) -> IntArray:
    """Per span between two consecutive pages: the encoder frames (at bus positions ``enc_pos``,
    judged ``status``) the host took beyond the firmware's count (negative: too few), 0 where
    the counts agree within the race of each page or the pages prove nothing."""
    if len(pages.at) < 2:
        return np.zeros(0, dtype=np.int64)
    taken = ((status == S_OK) | (status == S_LOST)).astype(np.int64)
    cum = np.concatenate([np.zeros(1, dtype=np.int64), np.cumsum(taken)])
    before = np.searchsorted(enc_pos, pages.at)  # encoder frames on the bus before each page
    host = cum[before]
    racing = host - cum[np.maximum(before - RACE_FRAMES, 0)]  # may be drained after the page
    firmware = np.diff(pages.ok) & U16_MASK
    least = host[1:] - racing[1:] - host[:-1]
    most = host[1:] - host[:-1] + racing[:-1]
    result = np.where(firmware < least, least - firmware,
                      np.where(firmware > most, most - firmware, 0))
    result[firmware > np.diff(before) + RACE_FRAMES] = 0  # a reboot, a wrapped count
    return result.astype(np.int64)


def by_pages(run: Settle, status: npt.NDArray[np.int8], enc_pos: npt.NDArray[np.intp],
             released: npt.NDArray[np.bool_], pages: OkPages | None) -> npt.NDArray[np.int8]:
    """``status`` (``run(None)``'s), with the released frames of each span the host took too
    many in judged by the narrow reading where that brings the spans to the firmware's count
    (module docstring); ``run``: ``settle`` with a per-frame reading."""
    if pages is None:
        return status
    before = surplus(enc_pos, status, pages)
    over = np.flatnonzero(before > 0)
    if len(over) == 0:
        return status
    bounds = np.searchsorted(enc_pos, pages.at)
    near = released | np.concatenate([[False], released[:-1]])  # its pair's first released
    for _ in range(2):  # all such spans at once; then without those it did not settle
        reading = np.full(len(status), -1, dtype=np.int8)
        for span in over.tolist():
            lo, hi = int(bounds[span]), int(bounds[span + 1])
            reading[lo:hi][near[lo:hi]] = NARROW
        trial = run(reading)
        after = surplus(enc_pos, trial, pages)
        changed = after != before
        if not (after[changed] != 0).any() and changed.any():
            return trial
        over = over[after[over] == 0]
        if len(over) == 0:
            return status
    return status
