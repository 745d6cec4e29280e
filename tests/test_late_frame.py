"""A frame that arrives one tick late, followed by a lost frame (``--faults delay=..,drop=..``,
found in a 30-minute kobuki run): the firmware must keep the distance and never take the
genuine step that follows for a counter restart.

Expected values come from the float robot geometry (``tests.odo_helpers.geometry``), never from
the code under test.
"""

from __future__ import annotations

import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorFlag, Reason, State
from tests.odo_helpers import geometry
from tests.test_health_firmware import COUNTS_PER_PERIOD, TimedRig


def _late_then_lost(rig: TimedRig) -> None:
    """Frame k arrives in the tick of period k + 1; frame k + 1 is lost on the bus."""
    late = rig.encoders(COUNTS_PER_PERIOD, COUNTS_PER_PERIOD)
    rig.tick()  # period k: its frame is still on its way
    rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, late)
    rig.encoders(COUNTS_PER_PERIOD, COUNTS_PER_PERIOD)  # frame k + 1: lost
    rig.tick()


@pytest.mark.parametrize("after", [20, 40])
def test_a_late_frame_then_a_lost_one_keeps_the_distance(after: int) -> None:
    rig = TimedRig("euler")
    for _ in range(20):
        rig.step()
    _late_then_lost(rig)
    for _ in range(after):
        rig.step()
    frames = 20 + 2 + after
    g = geometry(rig.ecu.params)
    assert rig.ecu.frames_implausible == 0
    assert not rig.ecu.errors.has(ErrorFlag.COUNTER_RESET)
    assert rig.ecu.reason is not Reason.COUNTER_RESET
    assert rig.state() is State.OK
    assert rig.ecu.odometry.x_q40_m / 2**40 == pytest.approx(
        (frames - 1) * COUNTS_PER_PERIOD * g.m_per_count_left, abs=1e-9
    )
