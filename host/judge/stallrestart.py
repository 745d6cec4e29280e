"""A motor controller's restart told by CTRL_UPTIME across a firmware stall: the judges follow the
firmware's own word where the log cannot prove it (issue #11, rule 3: a FAIL must never blame a
correct firmware; ``ctrlrestart``, ``nearthreshold``).

The firmware tells a restart by a frame's CTRL_UPTIME below what its last accepted frame's aged
to (``firmware.restartage``; after a tick that lost time, not aged: that frame's own). The
judges compare it with the log's frame before it. Across a stall the two are not the same frame:
the halted MCU's mailbox kept a backlog of what came first and dropped the rest, so the last
frame it took before the first one after the stall is one of the frames from the last it named
before the silence on (some of them refused by the host's E2E, whose window the stall did not
open), or that one. On pmir random, seed 12, ``delay=0.3:55,dup=0.1,stall=4:2``: halted from
4.0 s, the firmware took the late COUNTER 10 of 3.995 s (CTRL_UPTIME 4) from its backlog, then
the late COUNTER 3 of 6.005 s (6), no restart; the host's frame before that one was COUNTER 8 of
6.000 s (7), which never reached the firmware, and its reference re-primed there (6 < 7): the
heading 28.3 mrad and the pose 9.0 mm off a right firmware, to the end.

So across a stall (from the break after the last frame named before the silence up to the first
frame named after it: ``windows``) a restart is proven only when the frame's CTRL_UPTIME is below
that of every frame of the log the firmware may have taken last (``proven``). Where it is not
(the frame below the log's frame before it only), the judges cannot know which the firmware
took, and take its word as ``nearthreshold`` does: ERROR_MASK's sticky COUNTER_RESET, clear on
the last summary before the frame and on the first two periods after it, says it did not
re-prime (``Resets.told``); unheard, or set, the judge's decision stands. A restart the firmware
did not report and the log does not prove is thus not asked of it; one the log proves still is.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.judge.nearthreshold import Resets
from odocan.host.judge.samples import FloatArray, IntArray

Window = tuple[int, int]  # (b, r): the stall's break frame, the first frame named after it


def stall_windows(breaks: IntArray | None, named: IntArray) -> tuple[Window, ...]:
    """Per stall break ``b`` (``after_stalls``' frames: the one after the last named before the
    silence), ``(b, r)``: ``r`` the first frame a kept sample names (``named``, sorted or not)
    from ``b`` on; none past the last sample."""
    if breaks is None or len(named) == 0:
        return ()
    ordered = np.sort(named)
    windows = []
    for b in breaks.tolist():
        k = int(np.searchsorted(ordered, b, side="left"))
        if k < len(ordered):
            windows.append((int(b), int(ordered[k])))
    return tuple(windows)


def told_otherwise(restart: npt.NDArray[np.bool_], uptime: IntArray, stamps_s: FloatArray,
                   e0: int, windows: tuple[Window, ...], resets: Resets | None
                   ) -> npt.NDArray[np.bool_]:
    """``restart`` (per step k into frame ``e0 + k + 1``: a controller restart by CTRL_UPTIME,
    ``uptime`` and bus times ``stamps_s`` of the frames from ``e0``) less the restarts inside a
    stall's window that the log does not prove and the firmware's word denies (module
    docstring)."""
    if not windows or resets is None or not restart.any():
        return restart
    kept = restart.copy()
    for k in np.flatnonzero(restart).tolist():
        j = k + 1  # the frame, from e0
        window = next(((b, r) for b, r in windows if b < e0 + j <= r), None)
        if window is None or proven(uptime, window[0] - 1 - e0, j):
            continue
        if resets.told(float(stamps_s[j])) is False:
            kept[k] = False
    return kept


def proven(uptime: IntArray, first: int, j: int) -> bool:
    """Whether frame ``j``'s CTRL_UPTIME is below that of every frame from ``first`` (the last
    the firmware named before the stall) to ``j - 1`` that reports one (non-zero): below the
    one the firmware took last, whichever it was (a stall's last tick lost time: not aged)."""
    ages = uptime[max(first, 0) : j]
    ages = ages[ages != 0]
    return len(ages) == 0 or int(uptime[j]) < int(np.min(ages))


STREAM = ("a controller restart after a firmware stall that the firmware's word denies "
          "(its stalls' windows: stallrestart)")


def word_denies(restarts: list[int], times_s: dict[int, float], breaks: IntArray,
                resets: Resets) -> bool:
    """Whether the firmware's word denies a controller restart (``restarts``: the frames a
    reference re-primed on by CTRL_UPTIME, bus times ``times_s``) after a stall's break
    (``breaks``): the streamed reference steps without the stalls' windows, so it refuses such
    a life (``STREAM``) and the whole log's judge weighs them."""
    first = int(np.min(breaks)) if len(breaks) else None
    return first is not None and any(
        f > first and f in times_s and resets.told(times_s[f]) is False for f in restarts)
