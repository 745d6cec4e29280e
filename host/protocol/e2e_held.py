"""Encoder frames whose E2E verdict a live judge holds until the firmware's evidence comes (issue
#11, one judge; rule 5: a FAIL never blames a correct firmware).

``host.protocol.e2e_evidence`` reads a capture's stamps three ways (strict, the first frame
stamped late: wide, the second: narrow) and, where they give a frame different verdicts, lets
the firmware's poses and ENC_E2E_OK pages settle it over the whole log. The live receiver
(``e2e_live.E2EMonitor``) judged such a frame at once, by one reading: after a frame late on
the bus had locked the firmware's window out, a starved recorder's release read wide took
the frame after it, and from there the receiver followed the sender's order (kobuki, seed 3,
``delay=0.1:15,seed=7``, recorder seed 1: 373 frames taken where the firmware took 262).

``readings_differ`` tells such a frame live (off the on-time path only: a frame on time is
one period by every reading); ``forced`` gives the receiver's state and counts the verdict the
whole log's rule gave it over the frames held (``host.judge.livesettle``).
"""

from __future__ import annotations

import math

from odocan.host.protocol.e2e import (
    COUNTER_MASK,
    MAX_DELTA_COUNTER,
    OK,
    OKSOMELOST,
    REPEATED,
    WRONG_SEQUENCE,
    SequenceState,
)
from odocan.host.protocol.e2e_cycles import new_cycles
from odocan.host.protocol.e2e_evidence import CAPTURE_HOLD_CYCLES
from odocan.host.protocol.e2e_periods import (
    CAPTURE_TOLERANCE_CYCLES,
    COUNTER_MODULO,
    RECEIVE_LAG_CYCLES,
    receive_period_count,
)
from odocan.host.protocol.e2e_silence import add_silence, is_silence

HELD = "held"  # ``E2EMonitor.check``'s status of a frame whose verdict waits
# the state's fields ``forced`` restores: counts, window, last valid COUNTER, waiting, last OK s
Before = tuple[dict[str, int], int, int, bool, float | None]


def narrow_period_count(dt_s: float, step: int, cycle_s: float,
                        hold_cycles: float = CAPTURE_HOLD_CYCLES) -> int:
    """``e2e_evidence.narrow_periods`` for one pair of frames, without numpy."""
    x = dt_s / cycle_s
    s = step + COUNTER_MODULO * math.floor((x - step + COUNTER_MODULO // 2) / COUNTER_MODULO)
    e = x - s
    if e > 0:
        e = max(e - hold_cycles, 0.0)
    late = max(math.ceil(abs(e) - RECEIVE_LAG_CYCLES), 0)
    return max(int(s + (late if e > 0 else -late if e < 0 else 0)), 0)


def readings_differ(state: SequenceState, dt_s: float, step: int, counter: int,
                    cycle_s: float | None) -> bool:
    """Whether the strict, wide and narrow readings give a frame (COUNTER ``counter``, ``dt_s``
    s and ``step`` COUNTERs after the message's frame before it, both with a right CRC)
    different verdicts against ``state`` (``e2e_evidence.readings``)."""
    delta = (counter - state.last_valid) & COUNTER_MASK
    if cycle_s is None or state.waiting or delta <= 1 or not math.isfinite(dt_s):
        return False  # the first, the usual, a repeat: every reading's verdict is one
    counts = (receive_period_count(dt_s, step, cycle_s, CAPTURE_TOLERANCE_CYCLES),
              receive_period_count(dt_s, step, cycle_s, CAPTURE_HOLD_CYCLES),
              narrow_period_count(dt_s, step, cycle_s))
    verdicts = {delta <= min(state.window + p, MAX_DELTA_COUNTER) for p in counts}
    return len(verdicts) > 1


def new_cycle_pending(state: SequenceState, counter: int, timestamp_s: float) -> bool:
    """Whether the frame (COUNTER ``counter``, bus time ``timestamp_s``) is one the stamps
    take as the sender's frame a COUNTER cycle or more on (``SequenceState``'s new-cycle
    rule), which the firmware may have counted a repeat: its ENC_E2E page after it says
    (``e2e_repeats``; kobuki figure8 446 after a bus-off): held for it."""
    last_s, cycle_s = state.last_valid_s, state.cycle_s
    return (not state.waiting and (counter - state.last_valid) & COUNTER_MASK == 0
            and last_s is not None and cycle_s is not None
            and new_cycles(timestamp_s - last_s, cycle_s) > 0)


def forced(state: SequenceState, before: Before, checked: tuple[str, int], counter: int,
           t_s: float, accepted: bool) -> str:
    """The status of a frame held, ``checked`` (status, receive periods) by the stamps against
    ``state`` (``before``: its fields before that check), given the whole log's verdict
    ``accepted``: where the two differ, ``state`` and its counts as that verdict leaves them."""
    status, periods = checked
    if (status in (OK, OKSOMELOST)) == accepted:
        return status
    counts, window, last_valid, waiting, last_ok_s = before
    state.counts = counts
    if not accepted:  # taken by the stamps, refused by the rule: the window kept and widened
        state.window = min(window + periods, MAX_DELTA_COUNTER)
        state.last_valid, state.waiting, state.last_ok_s = last_valid, waiting, last_ok_s
        state.last_valid_s = None  # a frame between: no new COUNTER cycle till the next taken
        repeat = (counter - last_valid) & COUNTER_MASK == 0  # a new cycle counted a repeat
        counts["repeated" if repeat else "wrong_sequence"] += 1
        return REPEATED if repeat else WRONG_SEQUENCE
    delta = (counter - last_valid) & COUNTER_MASK or COUNTER_MODULO
    counts["ok"] += 1
    counts["lost"] += 0 if waiting else delta - 1
    if last_ok_s is not None and is_silence(t_s - last_ok_s, state.period_s):
        add_silence(counts, t_s - last_ok_s)
    state.waiting, state.last_valid, state.window = False, counter, state.max_delta_init
    state.last_valid_s = state.last_ok_s = t_s
    return OK if delta == 1 or waiting else OKSOMELOST
