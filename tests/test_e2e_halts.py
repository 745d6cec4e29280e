"""``host.protocol.e2e_halts.HaltWatch``: the firmware's sends tell its MCU's halt live, and the
encoder frames of a lock-out after it are the ones a live judge holds for the poses (the
drives: ``tests/test_trial37.py``, ``SLOW16_LIVE``, ``STALL_LIVE_HELD``, ``LIVE_LOSS_SPAN``)."""

from __future__ import annotations

import pytest

from odocan.host.protocol import busfacts
from odocan.host.protocol.e2e_halts import HALT_PERIODS, LOCKOUT_S, HaltWatch

POSE_ID, ENC_ID = 0x200, 0x100
PERIOD_S = busfacts.POSE_PERIOD_S
ENC_S = busfacts.ENC_CYCLE_S
HALT_S = (HALT_PERIODS + 0.5) * PERIOD_S  # a 60 ms hole of the firmware's sends


def _watch() -> HaltWatch:
    return HaltWatch(frozenset({POSE_ID}), ENC_ID)


def _drive(watch: HaltWatch, poses: list[tuple[float, int]], until_s: float) -> None:
    """The firmware's ``poses`` (bus time, COUNTER) heard among encoder frames every period
    from 0 to ``until_s`` (those of the hole too: the motor controller went on)."""
    frames = [(t, POSE_ID, c) for t, c in poses]
    frames += [(k * ENC_S, ENC_ID, k & 15) for k in range(round(until_s / ENC_S) + 1)]
    for t_s, key, counter in sorted(frames, key=lambda f: (f[0], f[1] != ENC_ID)):
        watch.seen(key, t_s, counter)


def test_sends_on_time_tell_no_halt() -> None:
    watch = _watch()
    _drive(watch, [(k * PERIOD_S, k & 15) for k in range(50)], 1.0)
    assert not any(watch.after(k * 0.001) for k in range(1000))


def test_a_halt_then_the_next_send_opens_a_lockout() -> None:
    watch = _watch()
    resumed_s = 0.04 + HALT_S
    _drive(watch, [(0.0, 0), (0.02, 1), (0.04, 2), (resumed_s, 3)], resumed_s)
    assert not watch.after(resumed_s - 0.001)
    assert watch.after(resumed_s)
    assert watch.after(resumed_s + LOCKOUT_S)
    assert not watch.after(resumed_s + LOCKOUT_S + 0.001)


def test_a_late_send_before_the_halt_is_not_the_latest_sent() -> None:
    """slow16's: the send before the halt heard after the one after it (COUNTER 4 after 5)."""
    watch = _watch()
    resumed_s = 0.04 + HALT_S
    _drive(watch, [(0.0, 3), (0.02, 5), (0.025, 4), (resumed_s, 6)], resumed_s)
    assert watch.after(resumed_s)


def test_a_reboot_is_no_halt() -> None:
    """A rebooted firmware's sends count from 0: its receiver is fresh, no window lags."""
    watch = _watch()
    resumed_s = 0.04 + HALT_S
    _drive(watch, [(0.0, 7), (0.02, 8), (0.04, 9), (resumed_s, 0)], resumed_s)
    assert not watch.after(resumed_s)


def test_a_silent_bus_is_no_halt() -> None:
    """No encoder frame in the hole: the bus was silent (a bus-off), not the firmware."""
    watch = _watch()
    for t_s, c in [(0.0, 0), (0.02, 1), (0.02 + HALT_S, 2)]:
        watch.seen(POSE_ID, t_s, c)
    assert not watch.after(0.02 + HALT_S)


@pytest.mark.parametrize("late_s", [0.005, 0.03])
def test_a_send_held_back_on_the_bus_is_no_halt(late_s: float) -> None:
    """A send heard late (a ``delay`` fault) leaves no hole: the ones on time go on."""
    watch = _watch()
    _drive(watch, [(0.0, 0), (0.02, 1), (0.06, 3), (0.04 + late_s, 2), (0.08, 4), (0.1, 5)],
           0.2)
    assert not any(watch.after(k * 0.001) for k in range(200))
