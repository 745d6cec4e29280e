"""Who sends ODOM_STATUS: one firmware, a rebooted one, or two on one ID -- told from UPTIME.

The one detection of a firmware reboot, shared by the live monitor (``host.judge.monitor``) and
the log analysis (``host.judge.analysis``): a source's UPTIME (whole seconds) minus bus time stays
constant within ``UPTIME_MATCH_S``; a reboot moves that offset once, or sends an UPTIME below the
last one (even within ``UPTIME_MATCH_S``: a reboot a second or two after power-up), or says INIT
after running; two sources on one ID make two offsets interleave (two sources whose offsets
differ by less than ``UPTIME_MATCH_S`` look like reboots). A reboot within the first second
after the previous one that does not say INIT cannot be told from UPTIME (0 again).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

UPTIME_MATCH_S = 2.0  # one source's UPTIME (whole s) minus bus time stays within this
CONFLICT_HOLD_S = 2.0  # CONFLICT is shown this long after two sources last interleaved


@dataclass
class SourceWatch:
    """One node's UPTIME against bus time, summary after summary: a single source keeps
    UPTIME - t constant (to the second), a reboot moves it once, two sources on one ID make two
    offsets interleave."""

    offset_s: float | None = None  # UPTIME - bus time of the source followed
    other_s: float | None = None  # the offset before the last change
    last_uptime_s: int = 0
    last_state: str = ""
    conflict_until_s: float = -math.inf

    def observe(self, t_s: float, uptime_s: int, state: str) -> str | None:
        """One ODOM_STATUS summary; returns ``"reboot"``, ``"two sources"``, ``"uptime jump"``
        or None."""
        offset = uptime_s - t_s
        kind = None
        if self.offset_s is None:
            self.offset_s = offset
        elif abs(offset - self.offset_s) <= UPTIME_MATCH_S:
            if (state == "INIT" and self.last_state not in ("", "INIT")) or (
                uptime_s < self.last_uptime_s  # one source's UPTIME never goes back
            ):
                kind = "reboot"
                self.offset_s = offset
        elif self.other_s is not None and abs(offset - self.other_s) <= UPTIME_MATCH_S:
            kind = "two sources"
            self.conflict_until_s = t_s + CONFLICT_HOLD_S
            self.offset_s, self.other_s = self.other_s, self.offset_s
        else:
            kind = "reboot" if uptime_s < self.last_uptime_s or state == "INIT" else "uptime jump"
            self.offset_s, self.other_s = offset, self.offset_s
        self.last_uptime_s, self.last_state = uptime_s, state
        return kind

    def observe_quiet(
        self, t_s: npt.NDArray[np.float64], uptime_s: npt.NDArray[np.int64],
        states: npt.NDArray[np.object_],
    ) -> int:
        """``observe`` of the summaries given (bus times, UPTIMEs, STATE names, in order) up to
        the first one that ``observe`` would return something for or follow another offset at,
        which is left unobserved; returns how many were observed (all: ``len(t_s)``). The
        same state as ``observe`` one by one, vectorised (a log's summaries are mostly quiet).
        """
        if self.offset_s is None or len(t_s) == 0:
            return 0
        init = states == "INIT"
        idle = init | (states == "")  # a state after which INIT is no reboot
        before_uptime_s = np.concatenate(([self.last_uptime_s], uptime_s[:-1]))
        before_idle = np.concatenate(([self.last_state in ("", "INIT")], idle[:-1]))
        loud = (
            ~(np.abs((uptime_s - t_s) - self.offset_s) <= UPTIME_MATCH_S)
            | (init & ~before_idle)
            | (uptime_s < before_uptime_s)
        )
        count = int(np.argmax(loud)) if loud.any() else len(t_s)
        if count:
            self.last_uptime_s, self.last_state = int(uptime_s[count - 1]), str(states[count - 1])
        return count
