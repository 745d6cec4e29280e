"""The live half of ``host.judge.unseenrestart`` (issue #11, one judge; rule 5: a FAIL must never
blame a correct firmware): a controller restart after the live judge's input went dark.

When no frame of any message was heard for ``gapseen.DARK_CYCLES`` encoder cycles since the
encoder frame before (the recorder, or the link to the monitor or the bridge, lost frames:
``gapseen.Seen.holes``' rule on the frames heard) and the encoder frame that ends that dark gap
of the sender's sequence is a controller restart the live reference re-primes on
(``livepose.StepGate``: CTRL_UPTIME went back), the firmware may have taken frames the host never
heard, and across the restarted counters their counts (the heading's too) are unknowable. Unless
the firmware's pages heard so far prove it took exactly the frames heard across it
(``livegapseen.LiveSeen``: ``Seen.took_across``), the reference restarts there from the next
on-board pose (``tracking.PoseTracker.restart_reference``: the pose adopted, its heading and
position fitted within their rounding by ``livefit``, the new life's samples held until that fit
is made of a second of them: ``livenewstart``), and the restart's event says why
(``unseenrestart.DETAIL``), as ``analyze`` restarts it. What the new start hides is one pose
jump at the restart; every step after it is judged exactly (a firmware that drifts after it is
POSE WRONG). Without a dark gap (the whole log: the firmware's frames heard across the
controller's silence) the exact rule stays: the reference goes on across the restart.

Known limit: a proof that only comes after the restart (pages made after it) does not undo the
new start live (``analyze`` would keep the exact rule there).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from odocan.host.judge.gapseen import DARK_CYCLES
from odocan.host.judge.livegapseen import LiveSeen
from odocan.host.judge.livewindow import CYCLE_S

NO_FRAME_S = -math.inf  # ``last_s`` before any frame


class DarkRestarts:
    """Dark gaps of the frames heard and the controller restarts that end one (module
    docstring); owned by the tracker's ``liveplace.StallPlacer`` (its ``seen``)."""

    def __init__(self, cycle_s: float = CYCLE_S) -> None:
        self.dark_s = DARK_CYCLES * cycle_s  # no frame this long (s): the input went dark
        # bus time of the latest frame heard (s), and whether a dark gap came since the latest
        # encoder frame: public, ``PoseTracker.advance`` runs ``heard`` in line (per frame)
        self.last_s = NO_FRAME_S
        self.dark = False
        self._hole = -1  # the latest encoder frame (seq) that ended a dark gap of the sequence
        self._pending = -1  # a new start owed from this encoder frame on (-1: none)
        self.new_starts = 0  # restarts after a dark gap the reference restarted at (the watch's)
        self.life_new_starts = 0  # ... whose adopted pose the reference still carries (new_life)

    def heard(self, t_s: float) -> float:
        """Any frame heard at bus time ``t_s`` (returned: the tracker's bus time)."""
        last_s = self.last_s  # (per frame of every robot: no max(), no math.inf looked up)
        if t_s - last_s > self.dark_s and last_s != NO_FRAME_S:
            self.dark = True
        if t_s > last_s:  # (a NaN never)
            self.last_s = t_s
        return t_s

    def on_encoders(self, seq: int, periods: int) -> None:
        """An accepted encoder frame ``seq``, ``periods`` of the sender's sequence after the
        frame heard before: a hole when the input went dark since that one and frames of the
        sequence are missing."""
        if self.dark and periods > 1:
            self._hole = seq
        self.dark = False

    def restarted(self, seq: int, by_uptime: bool, seen: LiveSeen) -> bool:
        """The reference re-primed on encoder frame ``seq`` (``by_uptime``: the controller
        restarted): True when that is a new start (a hole, no page proves the firmware took
        exactly the frames heard across it); the reference restarts at the next sample."""
        if not by_uptime or seq != self._hole or seen.proven().took_across(seq):
            return False
        self._pending = seq
        return True

    def owe(self, seq: int) -> None:
        """A new start owed at encoder frame ``seq`` whatever the pages say: a step within a
        period of the ambiguity threshold (``host.judge.nearthreshold``), which the live judge
        cannot know the firmware's decision on when it steps."""
        self._pending = seq if self._pending < 0 else min(self._pending, seq)

    def due(self, seq: int, restart: Callable[[], None]) -> None:
        """A sample of encoder frame ``seq`` is to be judged: ``restart`` the reference first
        when a new start is owed at or before that frame (the sample is then its start), then
        count it (``new_life`` alone forgets it: a restart of the reference does not)."""
        if 0 <= self._pending <= seq:
            self._pending = -1
            restart()
            self.new_starts += 1
            self.life_new_starts += 1

    def new_life(self) -> None:
        """The firmware's pose was set anew whole (a reboot, a set-pose of X, Y and HEADING):
        the reference no longer carries a pose adopted at a new start before it, which the
        live OK then no longer names (``livestanding.placed_why``); ``new_starts`` stays the
        watch's count (``analyze``'s ``unseen_restarts``). A set-pose that keeps a field from
        the reference keeps its new starts too: the field kept is the one adopted."""
        self.life_new_starts = 0
