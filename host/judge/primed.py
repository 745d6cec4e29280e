"""The encoder frame a rebooted firmware primed on, from its first page of WHEEL_ENCODERS E2E
counts (``host.judge.reboots`` module docstring): one rule for the whole-log, the streamed and
the live judge."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_MASK as MASK


def counted_start(encoders: tuple[npt.NDArray[np.intp], npt.NDArray[np.int64]], page: int,
                  ok: int, lost: int) -> int | None:
    """The encoder frame a firmware primed on, from its first page of WHEEL_ENCODERS E2E counts
    (at log position ``page``): it took every frame from that one on, accepted (``ok``,
    ENC_E2E_OK) or lost (``lost``, ENC_E2E_LOST: its mailbox dropped them, or the bus did), so
    it primed ok + lost - 1 COUNTER steps back from the latest accepted encoder frame before the
    page (``encoders``: their positions and COUNTERs). Counting ``ok`` frames of the log back
    instead lands as many frames late as the firmware lost frames the bus carried (issue #11,
    rule 3: a correct firmware FAILed by their travel; ``tests/test_reboot_first_page_losses``).
    None when ``ok`` is 0 or the log lacks that frame. Shared by ``reboots``, ``stream_lives``
    and the live judge (``livewindow.primed_at``)."""
    at, counter = encoders
    last = int(np.searchsorted(at, page)) - 1
    back = ok + lost - 1  # COUNTER steps from the primed frame
    if ok <= 0 or last < 0:
        return None
    first = max(last - back, 0)  # every step at least 1: the frame lies at or after it
    steps = np.cumsum(((counter[first + 1 : last + 1] - counter[first:last]) & MASK)[::-1])
    found = np.flatnonzero(steps == back)
    if back and not len(found):
        return None
    return int(at[last - (int(found[0]) + 1 if back else 0)])


def within_named(encoders: tuple[npt.NDArray[np.intp], npt.NDArray[np.int64]], at: int,
                 named: int) -> int:
    """``counted_start``'s frame ``at`` no later than ``named``, the frame the life's power-up
    pose named (the latest the firmware had taken at its first tick: it primed there or
    before). A count landing after it is short by whole COUNTER laps: frames lost in a run of
    16 or more (a halt right after the boot, its mailbox full) count as that many less a
    multiple of 16 in ENC_E2E_LOST, the 4-bit COUNTER's jump being all the firmware sees. A
    reset halted 0.4 s after its first tick was primed 2 laps (32 frames) late, its reference
    180 mm and 597 mrad off the correct firmware (issue #11). The frame is stepped back whole
    laps to at or before ``named`` when the log holds one there of the same COUNTER, else
    ``at`` as counted (``encoders``: the frames' positions and COUNTERs)."""
    positions, counter = encoders
    if at <= named:
        return at
    i = int(np.searchsorted(positions, at))
    if i >= len(positions) or positions[i] != at:
        return at
    lap = MASK + 1
    back = np.flatnonzero((positions <= named) & (positions >= named - lap + 1)
                          & ((counter - counter[i]) & MASK == 0))
    return int(positions[back[-1]]) if len(back) else at
