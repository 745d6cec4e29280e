"""The motor controller's restarts as the firmware tells them from CTRL_UPTIME (firmware/
encoders.py ``_controller_restarted``), from a log: a frame whose CTRL_UPTIME is below what the
last accepted frame's aged to, both reported, and whose counts are young enough for that age,
when the next frame confirms it (``confirmed_holds``), and only between two frames the
firmware's E2E window lets follow each other (``window_periods``: a pair beyond it means the host
took a frame the firmware never had). Used by the reference's step walk
(``reference_path.firmware_steps``); the live reference's per-frame rule (``livepose``) takes
``in_window``."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.firmware.encoders import CTRL_UPTIME_MAX, RESTART_SLACK_PERIODS
from odocan.host.judge.reference import wrap_delta
from odocan.host.judge.samples import FloatArray, IntArray
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK as MASK
from odocan.host.protocol.busfacts import ENC_PERIODS_PER_S as PERIODS_PER_S


def ctrl_restarts(uptime: IntArray, young: npt.NDArray[np.bool_], elapsed_s: FloatArray,
                  cycle_s: float | None, counter: IntArray) -> npt.NDArray[np.bool_]:
    """Per step (into frame k + 1 of ``uptime``, CTRL_UPTIME of consecutive accepted frames,
    ``elapsed_s`` bus time apart, ``counter`` their COUNTERs): the motor controller restarted,
    its age below what the frame before's aged to (``aged_uptime``), both reported (non-zero),
    and the frame's counts ``young`` (``young_counts``)."""
    before, after = uptime[:-1], uptime[1:]
    aged = aged_uptime(before, elapsed_s, cycle_s, successors(counter[:-1], counter[1:]))
    restarted: npt.NDArray[np.bool_] = (after != 0) & (before != 0) & (after < aged)
    if cycle_s is not None:
        restarted &= (((counter[1:] - counter[:-1] - 1) & MASK) + 1
                      <= window_periods(np.asarray(elapsed_s), cycle_s))
    return restarted & young[1:]


def window_periods(elapsed_s: FloatArray, cycle_s: float) -> IntArray:
    """The widest E2E window (periods) the firmware's receiver can have reached ``elapsed_s``
    (bus time) after taking a frame: one period a tick from 0 (Profile 2, WHEEL_ENCODERS), its
    ticks following the frames' arrival, plus one for the bus-to-tick rounding. A pair of
    accepted frames whose COUNTER step (1..16) lies beyond it never followed each other in the
    firmware: the host took a frame between that the firmware did not have (issue #11: pmir
    square 645, ``busoff=2.7:0.2,stall=4.7:0.3,delay=0.3:55``: the host took a frame sent while
    the MCU was halted, CTRL_UPTIME 6, then one held 55 ms on the bus, CTRL_UPTIME 5, 11
    COUNTERs on 5 ms later, which the firmware resumed on after the stall; told a controller
    restart there, the reference re-primed where the firmware did not: 19.3 mm off it).
    Saturated at a lap (16)."""
    return np.minimum(np.ceil(elapsed_s / cycle_s).astype(np.int64) + 1, MASK + 1)


def in_window(counter_step: int, elapsed_s: float, cycle_s: float) -> bool:
    """``window_periods`` for one pair (the live reference, per frame): whether a COUNTER step
    (mod 16, 0 a lap) ``elapsed_s`` after the frame before fits the firmware's window."""
    return ((counter_step - 1) & MASK) + 1 <= min(math.ceil(elapsed_s / cycle_s) + 1, MASK + 1)


def successors(before: IntArray, after: IntArray) -> npt.NDArray[np.bool_]:
    """Per pair: ``after`` (a COUNTER) is the E2E successor of ``before`` (+ 1 mod 16)."""
    found: npt.NDArray[np.bool_] = ((np.asarray(after) - np.asarray(before)) & MASK) == 1
    return found


def aged_uptime(before: IntArray, elapsed_s: FloatArray, cycle_s: float | None,
                successor: npt.NDArray[np.bool_]) -> IntArray:
    """The least CTRL_UPTIME a controller that did not restart reports ``elapsed_s`` (bus time)
    after a frame of CTRL_UPTIME ``before`` (firmware/encoders.py ``_aged_uptime``): ``before``
    plus the whole seconds of the periods between them less ``RESTART_SLACK_PERIODS``, saturated
    at ``CTRL_UPTIME_MAX``; ``before`` without bus times. The bus's clock, not the firmware's:
    the two may differ by a period, so at an elapsed time within a period of a whole second
    (plus the slack) the firmware may have decided the other way (a known limit, docs/bus.md);
    the firmware's exceptions (a tick that lost time, a mailbox that dropped frames) are not
    seen here either. ``before`` where the frame is the E2E successor of the one before
    (``successor``: it may have waited behind a silence of the bus, sampled as old; the proof and
    what it gives up: ``_aged_uptime``)."""
    if cycle_s is None:
        return before
    periods = np.rint(np.asarray(elapsed_s) / cycle_s).astype(np.int64) - RESTART_SLACK_PERIODS
    periods = np.where(successor, 0, np.maximum(0, periods))
    aged: IntArray = np.minimum(CTRL_UPTIME_MAX, before + periods // PERIODS_PER_S)
    return aged


def young_counts(left: IntArray, right: IntArray, uptime: IntArray, bits: int,
                 bound: tuple[int, int]) -> npt.NDArray[np.bool_]:
    """Per frame: each wheel's count (read signed in ``bits``) within what a controller
    ``uptime`` seconds old can have run from 0, ``uptime * PERIODS_PER_S`` periods of
    ``bound`` (firmware/encoders.py ``_young_counts``)."""
    periods = uptime * PERIODS_PER_S
    young: npt.NDArray[np.bool_] = ((np.abs(wrap_delta(left, bits)) <= periods * bound[0])
                                    & (np.abs(wrap_delta(right, bits)) <= periods * bound[1]))
    return young


def confirmed_holds(enc: tuple[IntArray, IntArray, IntArray, IntArray],
                    young: npt.NDArray[np.bool_], foreign: npt.NDArray[np.bool_], bits: int,
                    bound: tuple[int, int] | None) -> npt.NDArray[np.bool_]:
    """Per frame of ``enc`` (left, right counts, CTRL_UPTIME and COUNTER of consecutive frames):
    the next frame not ``foreign`` (refused outright before the hold is looked at) confirms it
    as the first of a controller restart (firmware/restarthold.py ``RestartHold.confirms``):
    a COUNTER advance n of 1..15, CTRL_UPTIME the same or one more, its counts ``young`` and
    within n periods' ``bound`` of this frame's (read in ``bits``; None: the bound is unknown,
    the counts are not looked at). False for the last frame (no next one: the firmware holds it)."""
    left, right, uptime, counter = enc
    n = len(left)
    kept = np.flatnonzero(~foreign)
    at = np.searchsorted(kept, np.arange(n), side="right")
    has_next = at < len(kept)
    nxt = kept[np.minimum(at, len(kept) - 1)] if len(kept) else np.zeros(n, dtype=np.intp)
    periods = (counter[nxt] - counter) & MASK
    ok = has_next & (periods != 0) & (uptime[nxt] >= uptime) & (uptime[nxt] <= uptime + 1)
    if bound is not None:
        ok &= young[nxt]
        ok &= np.abs(wrap_delta(left[nxt] - left, bits)) <= periods * bound[0]
        ok &= np.abs(wrap_delta(right[nxt] - right, bits)) <= periods * bound[1]
    confirmed: npt.NDArray[np.bool_] = ok
    return confirmed
