"""Whether a WHEEL_ENCODERS frame comes from a restarted motor controller: its age (CTRL_UPTIME).

No rule on the counts alone tells a restart whose jump fits the bound (a controller silent long
enough) from motion, so the controller says its age: a frame whose CTRL_UPTIME is below the last
accepted frame's (both reported, non-zero) comes from a restarted controller, its counters from 0:
COUNTER_RESET, the odometry re-primed on that frame, if its counts are ones such a young controller
can hold (each wheel within CTRL_UPTIME seconds of its per-period bound of 0: a forged frame that
passes E2E is refused as before, not taken for a restart) and the next frame confirms it
(``firmware.restarthold``: held until then; on a 32-bit robot a forged frame is often "young"). A
controller that reports 0 (an old one) is judged by the counts alone, as before. After a silence of
S s the last frame's CTRL_UPTIME has aged by at least floor(S) (``_aged_uptime``): a frame below
that is a restart too, one that came during the silence and has been up longer than the controller
was before it. The firmware needs this rule, not only the judges: without it such a restart's jump
fits the time-widened bound, is integrated as motion, and the firmware recovers to OK with a phantom
jump in its pose.

C: ``aged_uptime`` and ``young_counts`` in firmware/c/ecu.c.
"""

from __future__ import annotations

from odocan.firmware.fixmath import wrap_signed

PERIODS_PER_S = 100  # encoder periods in one second (1 s / ENCODER_PERIOD_US)
CTRL_UPTIME_MAX = 15  # CTRL_UPTIME saturates here (u4)
RESTART_SLACK_PERIODS = 16  # periods two frames' queueing may shorten the gap between samples


def aged_uptime(prev: int, since: int, tick_late: int, unknown: bool) -> int:
    """The least CTRL_UPTIME (u4) a controller that did not restart can report now, ``prev``
    at the last accepted frame: ``prev`` plus the whole seconds of firmware time since that
    frame, less the periods this tick came late and ``RESTART_SLACK_PERIODS`` (the frames'
    queueing: the gap between their samples is at least that), saturated at
    ``CTRL_UPTIME_MAX``; ``prev`` after a tick that lost time or frames the mailbox dropped
    (a backlog's frames were sampled at unknown times). A controller silent S s reports at
    least ``prev`` + floor(S) (1 + whole s of its age); less is a restart even when it is not
    below ``prev`` (it restarted during the silence and has been up longer than before).

    ``prev`` too (``unknown``) when this frame's COUNTER is the E2E successor of the last
    accepted frame's (its COUNTER + 1 mod 16): the silence may be the bus's, not the
    controller's (a babbler held it; the frames waited in the controller's transmit buffer),
    and the first frame after it
    was then sampled right after the last accepted one, its CTRL_UPTIME as old. Proof that a
    controller that did not restart is never taken for one: it numbers its frames 0..15 in
    turn, so if none of them was lost this frame is the successor (this rule does not apply),
    and if some were lost (on the bus: ENC_E2E_LOST) their samples lie between, so
    the silence is the controller's own and it aged by it (the rule as before). What the rule
    gives up: a restarted controller numbers afresh (sim ``MotorController.restart``: COUNTER
    0 first), so a restart whose heard COUNTER happens to be the successor (1 in 16 over the
    silence's unheard frames) is not told by its age here; it is still told if its
    CTRL_UPTIME is below ``prev`` (it went back), else its jump is judged by the counts'
    plausibility bound (widened by the silence) as before this rule.

    ``since``: the firmware's periods since the last accepted frame (u16); ``tick_late``: the
    periods this tick came late (u32); ``unknown``: the successor, lost time or mailbox drops.
    """
    late = tick_late + RESTART_SLACK_PERIODS  # u32: < 2^19 + 16
    if since <= late or unknown:
        return prev
    aged = prev + (since - late) // PERIODS_PER_S  # u16: at most 15 + 655
    return aged if aged < CTRL_UPTIME_MAX else CTRL_UPTIME_MAX


def young_counts(wire: tuple[int, int], uptime: int, bits: int,
                 bounds: tuple[int, int]) -> bool:
    """True when each wheel's count, read signed in the wire's bits, is within the counts a
    controller ``uptime`` seconds old can have run from 0 (it powered up less than that
    long ago): ``uptime * PERIODS_PER_S`` periods of its per-period bound (u64: at most
    1500 * 2^44). ``bits``: the width the counts are read in (the counters', at
    most the wire's 24); ``bounds``: each wheel's most counts a period."""
    periods = uptime * PERIODS_PER_S
    left_max, right_max = bounds
    left, right = wrap_signed(wire[0], bits), wrap_signed(wire[1], bits)
    return abs(left) <= periods * left_max and abs(right) <= periods * right_max
