"""Frames a bus-off held back reach the bus, and the log, when the controller recovers (issue #11,
rule 5: a FAIL must never blame a correct firmware).

A frame held back by ``delay`` whose release falls in a bus-off waits in the controller's
transmit buffer and goes out at the recovery (T + DUR + 128 x 11 bits). It used to be stamped
with its due time: on kobuki, seed 703, ``delay=0.5:100,busoff=1:1`` the motor controller's
encoder frames due at 1.04, 1.06 and 1.09 s sat in the log at those times although nobody heard
them before 2.0028 s (the firmware took them at its tick of 2.01 s), and the log went back in
time (1.09 s, then 1.021 s). The judges took them in an E2E window the firmware never had and
FAILed the correct firmware 32 mm, 102 mrad off (``tests/test_combo_faults.py``).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import can
import pytest

from odocan.sim.busoff import ErrorCounters
from odocan.sim.faults import BusOff, FaultInjectingBus, FaultSpec
from tests.fault_rig import open_virtual, unique_channel

BITRATE = 500_000
RECOVERED_S = 1.0 + 1.0 + ErrorCounters.RECOVERY_BITS / BITRATE  # 2.002816 s


def _frame(i: int, t_s: float) -> can.Message:
    return can.Message(timestamp=t_s, arbitration_id=0x100, is_extended_id=False,
                       data=i.to_bytes(8, "little"))


def test_frames_held_through_a_bus_off_are_stamped_at_the_recovery() -> None:
    channel = unique_channel()
    rx = open_virtual(channel)
    spec = FaultSpec(delay=1.0, delay_ms=100, busoff=BusOff(1.0, 1.0), seed=1)
    with FaultInjectingBus(open_virtual(channel), spec, bitrate=BITRATE) as bus:
        bus.send(_frame(1, 0.92))  # due at 1.02 s, in the bus-off
        bus.send(_frame(2, 0.95))  # due at 1.05 s
        with pytest.raises(can.CanOperationError):
            bus.send(_frame(3, 1.0))
        bus.poll(1.5)
        assert bus.held == 2
        bus.poll(2.01)  # the first poll after the recovery
        bus.send(_frame(4, 2.02))  # due at 2.12 s, after the recovery: its own time
        bus.poll(2.2)
    got = [(int.from_bytes(m.data, "little"), m.timestamp) for m in iter(lambda: rx.recv(0), None)]
    rx.shutdown()
    assert [i for i, _ in got] == [1, 2, 4]
    assert got[0][1] == pytest.approx(RECOVERED_S, abs=1e-9)
    assert got[1][1] == pytest.approx(RECOVERED_S, abs=1e-9)
    assert got[2][1] == pytest.approx(2.12, abs=1e-9)


def test_the_log_of_a_bus_off_drive_is_in_time_order_and_silent_in_it(tmp_path: Path) -> None:
    log = tmp_path / "drive.log"
    subprocess.run([sys.executable, "-m", "odocan", "run", "--robot", "kobuki", "--duration", "3",
                    "--seed", "703", "--faults", "delay=0.5:100,busoff=1:1", "--firmware",
                    "python", "--log", str(log)], check=False, capture_output=True)
    assert log.stat().st_size > 0
    stamps, encoders = [], []
    for msg in can.LogReader(str(log)):
        stamps.append(msg.timestamp)
        if msg.arbitration_id == 0x100:
            encoders.append(msg.timestamp)
    assert stamps == sorted(stamps)
    # both handles are bus-off from 1.0 s to the recovery: no frame of theirs is heard then
    assert not [t for t in stamps if 1.0 + 0.025 < t < RECOVERED_S - 1e-9]
    assert sum(1 for t in encoders if abs(t - RECOVERED_S) < 1e-6) == 3  # 1.04, 1.06, 1.09's
