"""A motor controller restart told by CTRL_UPTIME is taken on TWO frames, not one.

``EncoderInput._controller_restarted`` tells a restart from one frame: CTRL_UPTIME below what the
last accepted frame's aged to, its counts young for that age. On a robot with 32-bit counters the
wire's 24 count bits are all used, so a forged payload that passes Profile 2's CRC (1 in 256 under
a flood on the encoder ID) meets that test often: on a fine encoder (65 536 counts/rev at 4 m/s:
5 563 counts a period, 8.3 M at 15 s of age) nearly every such frame with a lower CTRL_UPTIME is
"young", and the firmware re-primed on it (``odocan run --robot <65536 cpr, 32-bit> --faults
babble=4000:0x100``: a COUNTER_RESET every few seconds, the judges 3-38 mm off the on-board pose).

So the frame is held, not taken (``RestartHold``): the restart is taken when the next frame the E2E
check passes confirms it: its CTRL_UPTIME the held one's or one more, its counts young for it and
within the bound of the held frame's over their COUNTER advance (1..15 periods; read in the wire's
bits: a frame lost between does not undo a genuine restart). Then the odometry re-primes on the held
frame and the confirming frame is handled as the frame after a re-prime always was (one period from
it): a genuine restart loses no more motion than with the one-frame rule. Any other next frame
refuses the held one (IMPLAUSIBLE_STEP, counted in ``frames_implausible``, no part of a counter
resync) and is itself judged against the last accepted frame, as if the held one had been lost. A
forged frame now re-primes only if the next frame passing E2E is a second forged one consistent with
it (about 1 in 256 of those that pass E2E, young, as old and within a few periods' travel of it).

C: a bool, two u32 and two u8 in ``struct odom_ecu`` (firmware/c/ecu.c ``hold_restart``,
``restart_confirmed``).
"""

from __future__ import annotations

from odocan.firmware.e2e import COUNTER_MASK
from odocan.firmware.fixmath import wrap_signed

Counts = tuple[int, int]  # (left, right) counter values


class RestartHold:
    """The frame that may start a controller restart, held until the next one (C: a struct)."""

    __slots__ = ("counter", "held", "uptime", "wire")

    def __init__(self) -> None:
        self.held = False
        self.counter = 0  # u8: its COUNTER
        self.wire: Counts = (0, 0)  # u32: its wire counts (24 bits)
        self.uptime = 0  # u8: its CTRL_UPTIME

    def hold(self, counter: int, wire: Counts, uptime: int) -> None:
        """Hold a frame that says its controller restarted (``_controller_restarted``)."""
        self.held = True
        self.counter = counter
        self.wire = wire
        self.uptime = uptime

    def confirms(self, counter: int, wire: Counts, uptime: int, bits: int,
                 bound: Counts) -> bool:
        """True when a frame (``counter``, ``wire`` counts, ``uptime``) confirms the held one:
        a COUNTER advance of n = 1..15 from it, CTRL_UPTIME the held one's or one more, each
        wheel within n periods' ``bound`` (counts, u64: at most 15 * 2^44) of the held frame's,
        read signed in ``bits`` (the wire's, at most 24). Its youth is the caller's test
        (``_young_counts``)."""
        periods = (counter - self.counter) & COUNTER_MASK  # u8
        if periods == 0 or uptime < self.uptime or uptime > self.uptime + 1:
            return False
        d_left = wrap_signed(wire[0] - self.wire[0], bits)
        d_right = wrap_signed(wire[1] - self.wire[1], bits)
        return abs(d_left) <= periods * bound[0] and abs(d_right) <= periods * bound[1]
