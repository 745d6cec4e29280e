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
