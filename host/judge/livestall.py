"""The live judge's stall and hold rule (``host.judge.tracking``): ``host.judge.stalls``' rules
(``after_stalls``, ``_frozen``) sample by sample, on the tracker's window of recent frames.

Once the reference runs, an on-board sample not let out in a burst (not ``queued``) is judged by:

- silence (``stalls.after_stalls``; ``livewindow.silent_since``, its exact bounds): its
  ODOM_POSE_Y came ``SILENCE_CYCLES`` encoder cycles or more after the previous sample's and the
  last ODOM_POSE_Y sent, with encoder frames on time meanwhile: the firmware was stalled. The
  sample names a frame of its backlog, which ENC_COUNTER cannot resolve: it is left out (not
  compared). The firmware took the frames it missed as one step: the reference's position is
  placed again at the next sample compared (its heading, a function of the counts, goes on);
- hold (``stalls._frozen``; ``livewindow.held_on_time``): it names a frame ``SILENCE_CYCLES`` or
  more after the last sample compared, with as many frames on time between: the firmware held its
  pose that long, then took the frames since as one step: the sample is compared, the position
  placed again first, with a stall's allowance (also where a gap opened it), unless a stall or
  hold already waits for its placement, and only where the firmware shows it held
  (``liveholdevidence``: the frame named again, or its poses quiet, those refused with their
  CRC right counted: ``pose_refused``), as ``stalls.hold_evidence`` asks.

Each counts in ``stalls`` and owes a placement: ``place_at_next``, and the placer's ``stalled``
(its allowance: ``liveplace.StallPlacer.shift``, which clears it). ``place_at_next`` is also owed
by a gap (``PoseTracker.on_encoders``) and kept by ``liveplacing`` while gaps wait. A sample counts
as compared (``last_compared``) once recorded or held for a later comparison (``livechoice``,
``livenewstart``). The rule starts again with the reference (``restart``); ``stalls`` goes on.
A reference restarted at the next pose after a set-pose whose kept fields a stall left unplaced
(``livesetpose.unplaced``) carries the silence it was in (``carry_silence``): the first sample
after it is left out, not adopted (it may name a backlog frame). The first sample since the rule
started, after a silence from the firmware's ODOM_STATUS (a stall before its first pose), is
``livefirst``'s: left out, its placement owed from the frame the firmware could have primed on
(``owe_from``).
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING

from odocan.host.judge.liveholdevidence import hold_shown
from odocan.host.judge.livewindow import held_on_time, silent_since
from odocan.host.judge.samples import SILENCE_CYCLES

if TYPE_CHECKING:
    from odocan.host.judge.liveplace import StallPlacer
    from odocan.host.judge.livewindow import Columns


REFUSED_KEPT = 256  # ODOM_POSE_Y frames refused with their CRC right kept (their times)


class StallRule:
    """The tracker's stall and hold rule and its state (module docstring)."""

    def __init__(self, placer: StallPlacer, window: Columns, ys: Columns) -> None:
        """``placer``: the tracker's placements; ``window``: its latest encoder frames; ``ys``:
        its latest ODOM_POSE_Y halves (the silence is measured from the last one sent)."""
        self._placer, self._window, self._ys = placer, window, ys
        self.stalls = 0  # stalls and holds after which the reference's position was placed again
        self.last_compared = -1  # the encoder frame of the last sample compared (-1: none)
        self.place_at_next = False  # a placement owed at the next sample compared
        self._last_t_s: float | None = None  # bus time of the last sample's ODOM_POSE_Y (s)
        self._carried = False  # a silence carried into an unstarted reference (module docstring)
        self.compared_t_s: float | None = None  # ODOM_POSE_Y time of the last sample compared
        self._refused_ys: deque[float] = deque(maxlen=REFUSED_KEPT)  # (pose_refused)

    @property
    def last_t_s(self) -> float | None:
        """Bus time of the last sample's ODOM_POSE_Y (s), None since the reference's start."""
        return self._last_t_s

    @property
    def carried(self) -> bool:
        """A silence carried into the next sample (``carry_silence``)."""
        return self._carried

    def heard_first(self, t_s: float) -> None:
        """A life's first sample, left out after a silence (``livefirst``), heard at ``t_s``."""
        self._last_t_s = t_s

    def owe_from(self, primed: int) -> None:
        """A stall before the first sample (``livefirst``): a placement owed at the next
        sample, its allowance from encoder frame ``primed`` (where the firmware could first
        have primed), as if the last compared."""
        self._owe()
        self.last_compared = primed

    def carry_silence(self, last_t_s: float | None) -> None:
        """After ``restart``: the reference restarts at the next pose, the silence since the
        sample at ``last_t_s`` carried (module docstring)."""
        self._last_t_s, self._carried = last_t_s, True

    def pose_refused(self, t_s: float) -> None:
        """An ODOM_POSE_Y frame refused by the host's E2E check with its CRC right, heard at bus
        time ``t_s``: the firmware sent it (the hold evidence's quiet)."""
        self._refused_ys.append(t_s)

    def left_out(self, seq: int, t_s: float, queued: bool, started: bool) -> bool:
        """The rule (module docstring) on the sample of encoder frame ``seq`` whose ODOM_POSE_Y
        came at bus time ``t_s`` (``queued``: in a burst; ``started``: the reference runs):
        True when it is left out (the first sample after a stall)."""
        last, self._last_t_s = self._last_t_s, t_s
        carried, self._carried = self._carried, False
        if not started or queued:
            return carried and not queued and silent_since(last, t_s, self._ys, self._window)
        if silent_since(last, t_s, self._ys, self._window):
            self._owe()
            return True
        last_seq = self.last_compared
        if (0 <= last_seq <= seq - SILENCE_CYCLES and not self._placer.stalled
                and held_on_time(self._window, last_seq, seq) and (
                    self.compared_t_s is None or hold_shown(
                        self._window, (self._placer.halves, self._ys), self._refused_ys,
                        last_seq, (self.compared_t_s, t_s)))):
            self._owe()
        return False

    def _owe(self) -> None:
        """A stall or hold: counted, its placement owed."""
        self.stalls += 1
        self.place_at_next = self._placer.stalled = True

    def restart(self) -> None:
        """A new reference: no sample compared or heard yet, no placement owed."""
        self.last_compared = -1
        self._last_t_s = self.compared_t_s = None
        self.place_at_next = self._carried = False
