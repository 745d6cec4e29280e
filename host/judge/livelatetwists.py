"""The live judges' ODOM_TWIST frames held back on the bus (issue #11: a FAIL must never blame a
correct firmware; the twist's half of ``host.judge.livelatehalves``).

Under ``delay=0.5:150,drop=0.1`` half the frames reach the bus 150 ms late (15 encoder
periods). ``analyze`` names a twist it reads late (``latenames.LateScan`` over every CRC-right
ODOM_TWIST frame) where it was sent (``latenames.sent_places``), and carries a repeated
ENC_COUNTER over consecutive sends by their send times (``samples._held``). The live judges read
no twist late: one held back 150 ms was named from the latest encoder frame where it was heard,
a frame 16 after its own, and a run of twists holding one ENC_COUNTER (the firmware refusing
frames) carried that lap-late name (pmir figure8 seed 7: a twist sent at 0.40 s naming the
COUNTER-7 frame of 0.39 s, DISTANCE 111 mm, named the COUNTER-7 frame of 0.55 s, 175.3 mm; the
live DISTANCE FAILed a correct firmware by 66.89 mm where ``analyze`` PASSed).

``TwistNames`` names each accepted twist as ``analyze`` does, one frame at a time: late
(``LateHalves``' scan of ODOM_TWIST, its refused CRC-right frames included), by
``livelatehalves.named_sent`` from the latest encoder frame heard before its send; held (its
ENC_COUNTER the previous accepted twist's, its own COUNTER one on, sent less than
``SILENCE_CYCLES`` cycles after it), the name that twist's run began with; else the tracker's
rule where heard. A held name a COUNTER lap or more behind the latest encoder frame (in the
sender's periods, not the frames heard: ``_periods_since``) is left out (``samples.lapped_out``).
State: the previous twist alone (bounded).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livelatehalves import named_sent
from odocan.host.judge.livewindow import CYCLE_S
from odocan.host.judge.samples import SILENCE_CYCLES
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

if TYPE_CHECKING:
    from collections.abc import Callable

    from odocan.host.judge.tracking import PoseTracker

TWIST = "twist"  # the tracker's ``LateHalves`` scan of ODOM_TWIST


class TwistNames:
    """The encoder frame each accepted ODOM_TWIST names (module docstring)."""

    __slots__ = ("_prev",)

    def __init__(self) -> None:
        # the previous accepted twist: ENC_COUNTER, own COUNTER, send time s, its run's name
        self._prev: tuple[int, int, float, int] | None = None

    def sent_s(self, tracker: PoseTracker, t_s: float, counter: int) -> float:
        """A twist heard at bus time ``t_s`` with E2E COUNTER ``counter``: its send time (its
        stamp unless read late)."""
        sent = tracker.late.heard(TWIST, t_s, counter)
        return t_s if sent is None else sent

    def name(self, tracker: PoseTracker, enc_counter: int, counter: int, t_s: float,
             sent_s: float, heard: Callable[[], int]) -> int:
        """The encoder frame (the tracker's seq, -1: none) the twist sent at ``sent_s`` (heard
        at ``t_s``) names; ``heard``: the tracker's rule where heard (called only for a twist
        neither late nor held)."""
        prev, late = self._prev, sent_s != t_s
        held = (prev is not None and prev[0] == enc_counter
                and (counter - prev[1]) & ENC_COUNTER_MASK == 1
                and sent_s - prev[2] < SILENCE_CYCLES * CYCLE_S)
        if held and prev is not None:
            run = prev[3]
        else:
            run = named_sent(tracker.window.rows, enc_counter, sent_s) if late else heard()
        self._prev = (enc_counter, counter, sent_s, run)
        if held and run >= 0 and _periods_since(tracker, run, sent_s) >= ENC_COUNTER_LAP:
            return -1  # carried over a lap or more of frames (samples.lapped_out)
        return run


def _periods_since(tracker: PoseTracker, seq: int, sent_s: float) -> int:
    """The sender's periods (the placer's numbering, ``samples.sender_seq``'s) from encoder
    frame ``seq`` to the latest heard before bus time ``sent_s``, among the window's latest rows
    (a frame older than those lies more rows back than a lap: a lap then). The tracker's seq
    counts frames heard: a lap of the sender's after a bus-off is a few of them (pmir random 4,
    halted 200 ms then 100 ms bus-off: 5 frames heard, 16 periods)."""
    total = 0
    for row in reversed(tracker.window.rows):
        if int(row[0]) <= seq:
            return total
        if row[3] < sent_s:
            total += int(row[6])
    return ENC_COUNTER_LAP
