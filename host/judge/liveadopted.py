"""The live reference's starts at the firmware's own pose, told beside an OK (issue #11: the
verdict is the product; ``host.judge.livestanding``).

After a reboot told late (its boot summary no longer says UPTIME 0, or the frame it primed on
was not heard), a config change or an integrator change the firmware applied, or a set-pose
applied at an encoder frame the judge did not hear, the live reference restarts at the next
on-board pose (``tracking.PoseTracker.restart_reference``): it adopts the firmware's own pose
there, so that pose is not checked independently (an offset the firmware took there stays
unseen; every step after it is judged). The monitor and the bridge showed OK with no word of it.
The caller that restarts the reference for such a cause owes it (``owe``); the start that
adopts a pose takes it (``started``), and the OK says it (``why``; the bridge's
``status.reference_adopted``) until the firmware's pose is set anew whole (a reboot, a set-pose
of X, Y and HEADING: ``new_life``), as an unseen restart's new start is said
(``livedark.DarkRestarts.life_new_starts``). A start at the power-up pose (0, 0, 0) adopts
nothing.
"""

from __future__ import annotations

from typing import Any, NamedTuple

from odocan.host.judge.livepose import FramePose

LATE_REBOOT = "a reboot told late (its boot summary said UPTIME {uptime_s} s)"
UNHEARD_BOOT = "a reboot whose priming encoder frame was not heard"
REBOOT_BEFORE_INTEGRATOR = "a reboot before the integrator was known"
CONFIG_CHANGE = "a config change"
INTEGRATOR_CHANGE = "an integrator change ({before} -> {after})"
INTEGRATOR_FIRST_HEARD = "the integrator ({after}) was first heard after the watch's first poses"
UNHEARD_SET_POSE = "a set-pose applied at an encoder frame not heard"
TWO_SENDERS_SET_POSE = "a set-pose of two senders' frames of one COUNTER (which taken not known)"
MERGED_SET_POSE = ("a set-pose keeping fields applied after a stall, hold or gap not placed yet "
                   "(where the firmware's merged steps put them)")


class Adoption(NamedTuple):
    """One start at the firmware's pose: why, its encoder frame (seq), bus time (s)."""

    cause: str
    enc_seq: int
    t_s: float


class AdoptedStarts:
    """The reference's starts at the firmware's own pose in the pose's current life (module
    docstring); owned by the tracker (``adopted``)."""

    def __init__(self) -> None:
        self.owed: str | None = None  # the cause of the next start, until it is made
        self.life: list[Adoption] = []  # the starts since the pose was last set anew whole

    def owe(self, cause: str) -> None:
        """The reference restarts at the next on-board pose for ``cause`` (the latest says)."""
        self.owed = cause

    def cancel(self) -> None:
        """The next start is not the firmware's pose (a set-pose's own, a power-up's)."""
        self.owed = None

    def started(self, pose: FramePose, exact: bool, t_s: float) -> None:
        """The reference started at ``pose`` (heard at bus time ``t_s``): an owed cause is an
        adoption unless the start is ``exact`` (the power-up pose)."""
        cause, self.owed = self.owed, None
        if cause is not None and not exact:
            self.life.append(Adoption(cause, pose.seq, t_s))

    def new_life(self) -> None:
        """The firmware's pose was set anew whole: no adopted pose carried any more."""
        self.life, self.owed = [], None

    def why(self) -> list[str]:
        """One line beside an OK while the reference carries an adopted pose ([] else)."""
        if not self.life:
            return []
        starts = "; ".join(f"at enc {a.enc_seq} ({a.t_s:.2f} s) after {a.cause}"
                           for a in self.life[-_SAID:])
        more = f" ({len(self.life) - _SAID} earlier)" if len(self.life) > _SAID else ""
        return [f"the reference restarted at the firmware's own pose {starts}{more}: that pose "
                "not checked independently (an offset the firmware took there not judged)"]

    def as_dict(self) -> list[dict[str, Any]]:
        """The bridge's ``status.reference_adopted``: the latest starts of this life."""
        return [a._asdict() for a in self.life[-_SAID:]]


_SAID = 4  # the latest adoptions said (a line, a status field of bounded size)
