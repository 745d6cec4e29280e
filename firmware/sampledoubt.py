"""The encoder periods a WHEEL_ENCODERS step spans, and how far back the sample of the frame it
starts from may lie (``EncoderInput``'s step periods and plausibility bound).

A step's periods are its COUNTER advance n plus the whole counter cycles that bring it nearest
to the periods since the last accepted frame was taken (``step_periods``). That counts from the
tick the last frame was taken in, as if it was sampled in the period before: a frame that came
after a silence may have waited it out, though. A sender's frame a delay held back when its bus
went off goes out first at the recovery, a second old (the bus-off model: frames due in the
bus-off wait in the controller's transmit buffer). The firmware took it (the E2E window is wide
open after the silence, and its step was plausible over the silence), and the frames sampled at
the recovery were refused against it as if one was due a period after it: three of them, taken
for a counter restart (COUNTER_RESET, the second's motion never integrated: issue #11, pmir
figure8 ``--seed 80 --faults delay=0.3:55,busoff=1:1``, 767 mm off the truth, the judges 883 mm
off the firmware). Its sample was taken no earlier than the last accepted one's before it, so a
step from it spans at most the periods since that one (``doubted_periods``); a step the nearer
count refused is judged by those, so a regular stream's periods (and its twist) are unchanged.

The held frames go out back to back, so the firmware may take two or more of them in one tick:
the second was sampled no earlier than the first's sample, which may lie the whole silence back,
so it shares the first's doubt (``accepted_doubt``), not 0 (the periods between the two). With 0
the frames sampled at the recovery were refused against it as if due a period after it, and three
of them taken for a counter restart (issue #11, kobuki random ``--seed 444 --faults
reboot=2:0.4,delay=0.3:55,busoff=7:0.2``: COUNTER 9 and 10, sampled 6.97 and 6.98 s, heard at
7.2028 s; COUNTER 11, sampled 7.31 s, 33 periods after COUNTER 10 but counted 17 from its
acceptance; COUNTER_RESET, 148 mm and 964 mrad off the truth).

C: ``step_periods``, ``periods_nearest``, ``doubted_periods`` and ``accepted_doubt`` in
firmware/c/ecu.c.
"""

from __future__ import annotations

from odocan.firmware.fixmath import U16_MAX

COUNTER_VALUES = 16  # E2E COUNTER values (4 bits): one whole counter cycle
STEP_PERIODS_MAX = U16_MAX  # periods saturate here (655 s), as encoders.py's


def step_periods(advance: int, since: int, late: int) -> int:
    """The encoder periods between this frame's sample and the last accepted one's: the
    frames' advance n (``EncoderInput._counter_advance``; 0: none accepted yet, 1), plus the
    whole counter cycles that bring it nearest to ``since``, the periods since that frame was
    accepted (0 for a second frame in one tick; after a tick that lost time, since the last
    sample before it), less ``late``, the periods this tick came late (its frames waited in
    the mailbox meanwhile). Exact while the two frames' queueing, beyond that, differs by less
    than 8 periods (a frame held 15 ms lands two ticks late: the nearest cycle, not the one
    below); n in a regular stream (1)."""
    if advance == 0:
        return 1
    return periods_nearest(advance, since, late)


def periods_nearest(advance: int, since: int, late: int) -> int:
    """``advance`` (1..) plus the whole counter cycles nearest to ``since`` periods (u16) less
    ``late`` (``step_periods``)."""
    budget = (since - late if since > late else 0) + COUNTER_VALUES // 2  # <= U16_MAX + 8
    if budget <= advance:
        return advance
    return advance + (((budget - advance) >> 4) << 4)


def doubted_periods(advance: int, since: int, doubt: int, late: int) -> int:
    """The periods of a step counted from the last sample before the last accepted frame's
    (module docstring): ``periods_nearest`` over ``since`` plus ``doubt`` (``since`` when that
    frame was taken: u16 each); 0 when that frame came in the period after the one before it
    (nothing to doubt) or none was accepted (``advance`` 0)."""
    if doubt <= 1 or advance == 0:
        return 0
    total = since + doubt  # u32: < 2^17
    return periods_nearest(advance, total if total < STEP_PERIODS_MAX else STEP_PERIODS_MAX, late)


def accepted_doubt(since: int, doubt: int, time_lost: bool) -> int:
    """The doubt of a frame accepted now (``doubted_periods``' ``doubt``, u16): ``since``, the
    periods since the last accepted frame was taken (its sample is no earlier than that one's);
    that frame's ``doubt`` when it was taken in this same tick (``since`` 0: it came with this one
    out of one drain, after the same silence, and this one's sample is no earlier than its own,
    which may lie ``doubt`` periods back); 0 in a tick that lost time (its frames were sampled
    at unknown times during the stall, and the lost time bounds their steps instead)."""
    if time_lost:
        return 0
    return doubt if since == 0 else since
