"""``host.protocol.e2e_halts.HaltWatch``: the firmware's sends tell its MCU's halt live, and the
encoder frames of a lock-out after it are the ones a live judge holds for the poses (the
drives: ``tests/test_trial37.py``, ``SLOW16_LIVE``, ``STALL_LIVE_HELD``, ``LIVE_LOSS_SPAN``)."""

from __future__ import annotations

import pytest

from odocan.host.protocol import busfacts
from odocan.host.protocol.e2e_halts import HALT_PERIODS, LOCKOUT_S, HaltWatch

POSE_ID, OTHER_ID = 0x200, 0x100
PERIOD_S = busfacts.POSE_PERIOD_S


def _sends(watch: HaltWatch, times_s: list[float], key: int = POSE_ID) -> None:
    for t_s in times_s:
        watch.seen(key, t_s)


def test_sends_on_time_tell_no_halt() -> None:
    watch = HaltWatch(frozenset({POSE_ID}))
    _sends(watch, [k * PERIOD_S for k in range(50)])
    assert not any(watch.after(k * 0.001) for k in range(1000))


def test_a_silence_of_the_firmware_then_a_send_opens_a_lockout() -> None:
    watch = HaltWatch(frozenset({POSE_ID}))
    _sends(watch, [0.0, 0.02, 0.04])
    resumed_s = 0.04 + (HALT_PERIODS + 0.5) * PERIOD_S  # a 60 ms hole: the MCU halted
    _sends(watch, [resumed_s])
    assert not watch.after(resumed_s - 0.001)
    assert watch.after(resumed_s)
    assert watch.after(resumed_s + LOCKOUT_S)
    assert not watch.after(resumed_s + LOCKOUT_S + 0.001)


@pytest.mark.parametrize("late_s", [0.005, 0.03])
def test_a_send_held_back_on_the_bus_is_no_halt(late_s: float) -> None:
    """A send heard late (a ``delay`` fault) fills no hole: the ones on time go on."""
    watch = HaltWatch(frozenset({POSE_ID}))
    _sends(watch, [0.0, 0.02, 0.06, 0.04 + late_s, 0.08, 0.1])
    assert not any(watch.after(k * 0.001) for k in range(200))


def test_other_messages_tell_nothing() -> None:
    """The motor controller's frames go on through the halt; only the firmware's sends count."""
    watch = HaltWatch(frozenset({POSE_ID}))
    _sends(watch, [0.0, 0.02])
    _sends(watch, [0.02 + k * 0.01 for k in range(1, 20)], key=OTHER_ID)
    assert not watch.after(0.2)
    _sends(watch, [0.2])
    assert watch.after(0.2)
