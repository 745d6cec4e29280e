"""Whole COUNTER cycles between two frames of one message, from their bus times: the host's E2E
check (``host.protocol.e2e.SequenceState``, the messages checked per period) and the sender's
sequence numbers (``host.judge.samples.sender_seq``) count them alike.

A frame of the COUNTER of the last valid frame is a repeat when it comes within a period of it;
when it comes ``NEW_CYCLE_PERIODS`` (half a COUNTER cycle) or more after it, it is the sender's
frame 16 * k periods on, k the whole cycles nearest the time between (half a cycle rounds up):
the frames between were lost to whoever made the log (a recorder's kernel buffer dropping a
chunk), not necessarily to the firmware, which had them and took it (issue #11, rule 5)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP

if TYPE_CHECKING:
    from odocan.host.protocol.e2e import E2EMessage

COUNTER_CYCLE = ENC_COUNTER_LAP  # 16 COUNTER values: a frame 16 periods on carries the same COUNTER
NEW_CYCLE_PERIODS = COUNTER_CYCLE // 2  # from here a same-COUNTER frame is the next cycle's


def new_cycles(dt_s: float, cycle_s: float) -> int:
    """Whole COUNTER cycles (>= 0) nearest ``dt_s`` (s) of periods ``cycle_s`` (s), half up: the
    float64 operations of ``sender_seq`` for a COUNTER step of 0; 0 for a NaN or infinite gap."""
    if not math.isfinite(dt_s):
        return 0
    return max(0, math.floor(dt_s / cycle_s / COUNTER_CYCLE + 0.5))


def new_cycles_array(dt_s: npt.NDArray[np.float64], cycle_s: float) -> npt.NDArray[np.int64]:
    """``new_cycles`` of each element."""
    cycles = np.floor(dt_s / cycle_s / COUNTER_CYCLE + 0.5)
    np.maximum(cycles, 0.0, out=cycles)
    result: npt.NDArray[np.int64] = cycles.astype(np.int64)
    return result


def new_cycle_s(config: E2EMessage) -> float | None:
    """``e2e.SequenceState.cycle_s`` of a message: its receive period when it is checked per
    period (``e2e.PER_PERIOD_WINDOW``: no frame adds periods within half a period, so a burst
    of repeats cannot open the rule to itself), else None (the rule off)."""
    return config.cycle_s if config.min_periods == 0 else None


def new_cycle_frames(steps: npt.NDArray[np.int64], t_s: npt.NDArray[np.float64],
                     cycle_s: float) -> int:
    """The frames (16 a COUNTER cycle) of the accepted COUNTER steps of 0 (``steps``: mod 16;
    the sender's frame 16 * k periods on), from the bus times ``t_s`` of the accepted frames:
    what ``e2e.check_frames`` adds to its ``lost`` count for them."""
    zero = np.flatnonzero(steps == 0)
    if len(zero) == 0:
        return 0
    return COUNTER_CYCLE * int(np.sum(new_cycles_array(t_s[zero + 1] - t_s[zero], cycle_s)))
