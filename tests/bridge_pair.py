"""One bridge robot (``host.mqtt.bridge._Robot``) and a real Python firmware on a virtual pair.

The bridge sends its command frames on one handle of a python-can ``virtual`` channel; the
listener (the other handle) hands them to the firmware (``OdomEcu`` on kobuki), which is fed one
encoder frame a period and answers in its tick; everything the firmware sends, and each encoder
frame, goes back to the bridge's telemetry. ``Board.period`` delivers the command frames the
bridge sent since the last period before this period's encoder frame (the bridge sent them after
hearing the last one), or with ``late=True`` after it: the firmware then acts on them one
encoder frame after the one the bridge had heard when it sent them (a live bus's reader lags).
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from typing import Any

import can

from odocan.firmware import frames as fr
from odocan.firmware.ecu import OdomEcu
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import topics
from odocan.host.mqtt.bridge import BridgeConfig, RobotEndpoint, _Robot
from odocan.host.mqtt.broker import BrokerURL
from odocan.sim import frames as sf
from odocan.sim import robot
from odocan.sim.rig import firmware_params
from tests.test_monitor_config import _Hal

KOBUKI = robot.load("kobuki")
PERIOD_S = 0.01
D_LEFT, D_RIGHT = 40, 55  # counts per period: a left curve at ~0.4 m/s


@contextlib.contextmanager
def bridged_robot(channel: str, **config: Any) -> Iterator[tuple[_Robot, can.BusABC]]:
    """The bridge's robot001 (kobuki, 16-bit counters) sending on ``channel``, and a listener on
    it; ``config``: more ``BridgeConfig`` fields (no broker is contacted)."""
    send_bus = can.Bus(interface="virtual", channel=channel)
    listener = can.Bus(interface="virtual", channel=channel)
    try:
        bridge = _Robot(RobotEndpoint("robot001", send_bus, Geometry.of(KOBUKI),
                                      counter_bits=16),
                        BridgeConfig(broker=BrokerURL("127.0.0.1", 1883), **config))
        yield bridge, listener
    finally:
        send_bus.shutdown()
        listener.shutdown()


class Board:
    """The firmware on kobuki, fed one encoder frame a period and the bridge's command frames
    (see the module docstring); ``results``: every ``cmd/result`` the bridge published."""

    def __init__(self, bridge: _Robot, listener: can.BusABC) -> None:
        self.hal = _Hal()
        self.ecu = OdomEcu(self.hal, firmware_params(KOBUKI, "exact"))
        self.bridge, self.listener = bridge, listener
        self.t_s = 0.0
        self.counter = self.left = self.right = 0
        self.results: list[dict[str, Any]] = []
        self.commands: list[can.Message] = []  # every frame the bridge sent, as delivered

    def period(self, *, late: bool = False) -> None:
        """One period: encoder frame and command frames (``late``: the commands after the
        encoder frame), the firmware's tick, its frames to the bridge."""
        self.left = (self.left + D_LEFT) & 0xFFFF
        self.right = (self.right + D_RIGHT) & 0xFFFF
        frame = sf.pack_wheel_encoders(self.counter, self.left, self.right)
        self.counter = (self.counter + 1) & 0xF
        if late:
            self._encoder(frame)
        while (msg := self.listener.recv(0)) is not None:
            self.command_frame(msg)
        if not late:
            self._encoder(frame)
        self.ecu.tick()
        for can_id, data in self.hal.sent:
            self.firmware_frame(can_id, data)
        self.hal.sent.clear()
        self.t_s += PERIOD_S

    def _encoder(self, frame: bytes) -> None:
        self.to_bridge(fr.WHEEL_ENCODERS_ID, frame)
        self.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, frame)

    def command_frame(self, msg: can.Message) -> None:
        """A frame the bridge sent, into the firmware's mailbox (a subclass may watch it)."""
        self.commands.append(msg)
        self.ecu.isr_can_rx(msg.arbitration_id, bytes(msg.data))

    def firmware_frame(self, can_id: int, data: bytes) -> None:
        """A frame the firmware sent, to the bridge (a subclass may watch it)."""
        self.to_bridge(can_id, data)

    def to_bridge(self, can_id: int, data: bytes) -> list[dict[str, Any]]:
        """One frame heard by the bridge (paced); the ``cmd/result`` answers it made."""
        msg = can.Message(timestamp=self.t_s, arbitration_id=can_id, is_extended_id=False,
                          data=data)
        published = self.bridge.paced(self.bridge.telemetry.feed(msg))
        results = [p for leaf, p in published if leaf == topics.RESULT_LEAF]
        self.results += results
        return results


def reckoned_from(x_m: float, y_m: float, heading_rad: float, steps: int
                  ) -> tuple[float, float, float]:
    """Independent float64: ``steps`` exact arcs of kobuki's constant step (``D_LEFT``,
    ``D_RIGHT`` counts) from the pose given; the pose reached (m, m, rad)."""
    per_count_l = 2 * math.pi * KOBUKI.wheel_radius_left_m / KOBUKI.counts_per_rev
    per_count_r = 2 * math.pi * KOBUKI.wheel_radius_right_m / KOBUKI.counts_per_rev
    ds = (D_LEFT * per_count_l + D_RIGHT * per_count_r) / 2
    dth = (D_RIGHT * per_count_r - D_LEFT * per_count_l) / KOBUKI.wheelbase_m
    x, y, th = x_m, y_m, heading_rad
    for _ in range(steps):
        x += ds / dth * (math.sin(th + dth) - math.sin(th))
        y -= ds / dth * (math.cos(th + dth) - math.cos(th))
        th += dth
    return x, y, th
