"""The judges' plausibility periods round a tie as the firmware does (issue #11, rule 5).

``host.judge.step_periods.widened_periods`` (the whole-log and the streamed reference) adds the
whole COUNTER cycles nearest to the periods the bus times show beyond the sender's step, as the
firmware's ``EncoderInput._step_periods`` adds them from its clock. At exactly half a cycle (8
periods beyond) the firmware rounds up (``(budget - advance) >> 4`` with ``budget`` 8 more) and
the judge rounded half to even (``np.rint(0.5) == 0``): a frame 9 periods after the last accepted
one with a COUNTER advance of 1 was allowed 17 periods of travel on board and 1 by the judges, so
a step between the two bounds, integrated by the firmware, was refused by the judges' copy of its
rule. Not reached by frames held up to 40 ms (at most 4 periods beyond), but by a sender that
stalls 80 ms.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

from odocan.firmware.encoders import EncoderInput
from odocan.host.judge.step_periods import widened_periods

CYCLE_S = 0.01


def _firmware_periods(since_periods: int, advance: int) -> int:
    """The firmware's own ``_step_periods`` on a frame taken ``since_periods`` ticks after the
    last accepted one, in a tick on time (the method reads only these two fields)."""
    state: Any = SimpleNamespace(_periods_since_sample=since_periods, _tick_late=0)
    return int(EncoderInput._step_periods(state, advance))


def test_the_judges_round_half_a_cycle_up_as_the_firmware() -> None:
    since = np.repeat(np.arange(0, 70), 16)
    advance = np.tile(np.arange(1, 17), 70)
    judged = widened_periods(advance, since.astype(np.float64) * CYCLE_S, CYCLE_S)
    firmware = np.array([_firmware_periods(int(s), int(a)) for s, a in zip(since, advance,
                                                                               strict=True)])
    wrong = np.flatnonzero(judged != firmware)
    assert len(wrong) == 0, [(int(since[k]), int(advance[k]), int(judged[k]), int(firmware[k]))
                             for k in wrong[:5]]
