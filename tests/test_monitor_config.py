"""`odocan monitor` follows an ODOM_CONFIG the firmware applies (found by the trial).

The monitor restarted its reference at every ODOM_CONFIG APPLY it heard but kept the robot it
was started with: after a config the firmware ACKed (kobuki, wheelbase 0.23 -> 0.25 m, sent by
`odocan bridge` over MQTT, processes on udp_multicast) it said POSE WRONG, 938 mm, exit 1, while
the firmware was right with its new wheelbase. Here a real Python firmware takes the config
frames; an independent float64 dead reckoning (written here) with the ACKed wheelbase says
where its pose must be, and the monitor must judge it right; a NACKed config changes nothing.
"""

from __future__ import annotations

import json
import math

import can

from odocan.firmware import frames as fr
from odocan.firmware.ecu import OdomEcu
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.commands import CommandEncoder
from odocan.sim import frames as sf
from odocan.sim import robot
from odocan.sim.rig import firmware_params

KOBUKI = robot.load("kobuki")
PERIOD_S = 0.01
D_LEFT, D_RIGHT = 40, 55  # counts per period: a left curve at ~0.4 m/s
WIDER = {"id": "c1", "counts_per_rev": 2578, "wheel_radius_left_m": 0.035,
         "wheel_radius_right_m": 0.035, "wheelbase_m": 0.25, "counter_bits": 16,
         "integrator": "exact"}
REFUSED = {**WIDER, "id": "c2", "counts_per_rev": 4, "wheel_radius_left_m": 0.05,
           "wheel_radius_right_m": 0.05, "wheelbase_m": 0.01}  # one count turns it 450 deg


class _Hal:
    def __init__(self) -> None:
        self.sent: list[tuple[int, bytes]] = []

    def transmit(self, can_id: int, data: bytes) -> bool:
        self.sent.append((can_id, data))
        return True


class _Bus:
    """The firmware on kobuki fed one encoder frame a period, every frame heard by a monitor."""

    def __init__(self) -> None:
        self.hal = _Hal()
        self.ecu = OdomEcu(self.hal, firmware_params(KOBUKI, "exact"))
        self.monitor = BusMonitor(KOBUKI)
        self.t_s = 0.0
        self.counter = self.left = self.right = 0
        self.acks: list[int] = []  # RESULT of every ODOM_ACK

    def period(self, commands: list[tuple[int, bytes]] = ()) -> None:  # type: ignore[assignment]
        self.left = (self.left + D_LEFT) & 0xFFFF
        self.right = (self.right + D_RIGHT) & 0xFFFF
        frame = sf.pack_wheel_encoders(self.counter, self.left, self.right)
        self.counter = (self.counter + 1) & 0xF
        for can_id, data in [(fr.WHEEL_ENCODERS_ID, frame), *commands]:
            self._heard(can_id, data)
            self.ecu.isr_can_rx(can_id, data)
        self.ecu.tick()
        for can_id, data in self.hal.sent:
            self._heard(can_id, data)
            if can_id == fr.ODOM_ACK_ID:
                self.acks.append((data[4] >> 4) & 1)
        self.hal.sent.clear()
        self.t_s += PERIOD_S

    def _heard(self, can_id: int, data: bytes) -> None:
        self.monitor.feed(can.Message(timestamp=self.t_s, arbitration_id=can_id,
                                      is_extended_id=False, data=data), now_s=self.t_s)


def _dead_reckoned(steps: list[float]) -> tuple[float, float]:
    """Independent float64: the exact arc of the constant step, each with the wheelbase given."""
    per_count = 2 * math.pi * 0.035 / 2578
    ds = (D_LEFT + D_RIGHT) * per_count / 2
    x = y = th = 0.0
    for wheelbase_m in steps:
        dth = (D_RIGHT - D_LEFT) * per_count / wheelbase_m
        x += ds / dth * (math.sin(th + dth) - math.sin(th))
        y -= ds / dth * (math.cos(th + dth) - math.cos(th))
        th += dth
    return x, y


def _drive(bus: _Bus, encoder: CommandEncoder, config: dict[str, object], after: int) -> None:
    frames = [(f.can_id, f.data) for f in encoder.encode("config", json.dumps(config).encode())
              .frames]
    bus.period(frames)
    for _ in range(after):
        bus.period()


def test_the_monitor_takes_an_acked_config_and_ignores_a_nacked_one() -> None:
    bus, encoder = _Bus(), CommandEncoder()
    for _ in range(100):
        bus.period()
    _drive(bus, encoder, REFUSED, 99)
    assert bus.acks[-1] == 1  # the APPLY NACKed: the firmware keeps kobuki
    _drive(bus, encoder, WIDER, 299)
    assert set(bus.acks[-7:]) == {0}  # every frame and the APPLY ACKed
    # the firmware drains that tick's encoder frame before the config: 200 steps of kobuki (the
    # first frame primes), then 299 with 0.25 m
    x_m, y_m = _dead_reckoned([0.23] * 200 + [0.25] * 299)
    odo = bus.ecu.odometry
    assert abs(odo.x_q40_m / 2.0**40 - x_m) < 1e-4
    assert abs(odo.y_q40_m / 2.0**40 - y_m) < 1e-4
    health = bus.monitor.health(now_s=bus.t_s)
    assert health["pose_wrongs"]["episodes"] == 0, health["why"]
    assert health["state"] in ("OK", "DEGRADED"), health["why"]
    assert bus.monitor.tracker.geometry.wheelbase_m == 0.25
