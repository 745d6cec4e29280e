"""Encoder frames after the firmware's MCU halted, whose verdict a live judge holds for the
firmware's evidence (issue #11, one judge; rule 3: a FAIL must never blame a correct firmware;
``host.judge.livesettle``).

A halted MCU (a debugger, a hung main loop: ``stall``) hears no frame: its mailbox keeps them,
and the tick it resumes in drains them at once. Its E2E window (one period a tick) then counts
from the drain, not from the bus times of the frames drained, and trails the stamps by the
periods of the halt for up to a lock-out: it refused on-time frames the stamps take, and took
a frame held back on the bus that every reading of the stamps refuses. ``analyze`` settles such
frames by the firmware's poses (``e2e_evidence``: a frame a pose names taken, the frames it
skipped refused). The live receiver judged them at once by the stamps. On the slow16 robot
(``tests/test_trial37.py``: 2^24 counts per revolution, 16-bit counters) random seed 43 under
``stall=3:0.05,delay=0.1:30`` the COUNTER 1 held back from 3.05 to 3.08 s was the firmware's
next frame (its poses name it from 3.091 s) and the 12 on time after it were refused; the live
judges refused it and took those 12, the firmware's re-prime at 3.22 s unseen, and said POSE
WRONG by 5.05 mm beyond a correct firmware.

The firmware's own sends (``SENDS``, one every ``busfacts.POSE_PERIOD_S``) tell a halt live:
none heard for ``HALT_PERIODS`` periods while the motor controller's encoder frames went on
(two or more: not a silent bus), then one whose E2E COUNTER is the next of its message's
latest sent (the firmware halted, it did not reboot: a rebooted one counts from 0, and its
fresh receiver, which ``analyze`` judges as a life of its own, is no lagging window). From that
one, for a lock-out's 16
periods (``LOCKOUT_S``), an encoder frame other than the last one taken's successor is held
(``E2EMonitor.check``: ``"held"``) and judged with the frames after it by the whole log's rule,
its evidence read (``check_frames(..., settle_all=True)``). Bounded: the holds' own; a halt
shorter than ``HALT_PERIODS`` is not told (as before).
"""

from __future__ import annotations

import math

from odocan.host.protocol import busfacts

SENDS = ("ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST")  # the firmware's sends every pose period
# periods of the firmware's sends none of which was heard: a halt (two of its sends missing,
# plus half a period: a send held back on the bus, one of three, seldom leaves such a hole)
HALT_PERIODS = 2.5
LOCKOUT_S = busfacts.ENC_COUNTER_LAP * busfacts.ENC_CYCLE_S  # its window trails the stamps (s)


class HaltWatch:
    """The firmware's sends heard (``seen``), and whether a frame comes within a lock-out of
    its resuming from a halt (``after``)."""

    __slots__ = ("_counters", "_enc_key", "_encoders", "_halt_s", "_keys", "_last_s",
                 "_resumed_s")

    def __init__(self, keys: frozenset[int], enc_key: int) -> None:
        """``keys``: the firmware's sends' message keys (``decode.frame_key``); ``enc_key``:
        the encoder frames'."""
        self._keys, self._enc_key = keys, enc_key
        self._halt_s = HALT_PERIODS * busfacts.POSE_PERIOD_S
        self._last_s = math.nan  # the latest of them heard (s; nan: none yet)
        self._resumed_s = -math.inf  # the first heard after a halt (s)
        self._encoders = 0  # encoder frames heard since the latest of them
        self._counters: dict[int, int] = {}  # per send: the COUNTER of its latest sent

    def seen(self, key: int, timestamp_s: float, counter: int) -> None:
        """A frame of message ``key`` (its E2E COUNTER ``counter``) heard at ``timestamp_s``."""
        if key == self._enc_key:
            self._encoders += 1
            return
        if key not in self._keys:
            return
        last = self._counters.get(key)
        step = -1 if last is None else (counter - last) & busfacts.ENC_COUNTER_MASK
        if (timestamp_s - self._last_s >= self._halt_s and self._encoders >= 2
                and step == 1):  # (nan: the first, never)
            self._resumed_s = timestamp_s
        if 0 < step < busfacts.ENC_COUNTER_LAP // 2 or last is None:  # sent after it
            self._counters[key] = counter
        if not timestamp_s <= self._last_s:
            self._last_s, self._encoders = timestamp_s, 0

    def after(self, timestamp_s: float) -> bool:
        """Whether ``timestamp_s`` lies within ``LOCKOUT_S`` after the firmware resumed."""
        return 0.0 <= timestamp_s - self._resumed_s <= LOCKOUT_S
