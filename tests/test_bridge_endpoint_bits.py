"""A bridged robot's counter width is its robot profile's, never a default (issue #11's last
note): ``RobotEndpoint.counter_bits`` defaulted to 32, so a 16-bit robot (kobuki) built without it
was judged as a 32-bit one: the bridge expected another PROFILE CRC than its firmware's. The width
is now required (keyword) in ``RobotEndpoint`` and ``RobotTelemetry``; the CRC expected for kobuki
is checked against the test's own CRC-32 of the DBC comment's bytes."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import BridgeConfig, RobotEndpoint, _Robot
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from tests.test_bridge_profile import crc_text

KOBUKI = robot.load("kobuki")


def test_a_robot_without_its_counter_width_is_refused() -> None:
    with can.Bus(interface="virtual", channel="bits-required") as bus, \
            pytest.raises(TypeError, match="counter_bits"):
        RobotEndpoint("r", bus, Geometry.of(KOBUKI))  # type: ignore[call-arg]
    with pytest.raises(TypeError, match="counter_bits"):
        RobotTelemetry("r", Geometry.of(KOBUKI), "exact")  # type: ignore[call-arg]


def test_a_16_bit_robot_is_expected_with_its_own_profile_crc(tmp_path: Path) -> None:
    log = tmp_path / "kobuki.log"
    assert main(["run", "--robot", "kobuki", "--duration", "2", "--log", str(log)]) == 0
    with can.Bus(interface="virtual", channel="bits-kobuki") as bus:
        endpoint = RobotEndpoint("r", bus, Geometry.of(KOBUKI), counter_bits=KOBUKI.counter_bits,
                                 profile_name=KOBUKI.name)
        bridged = _Robot(endpoint, BridgeConfig(broker=BrokerURL("127.0.0.1", 1883)))
        for msg in can.LogReader(str(log)):
            bridged.telemetry.feed(msg)
    profile = bridged.telemetry.status()[1]["profile"]
    assert profile["expected_crc"] == profile["profile_crc"] == crc_text(KOBUKI)
    assert profile["verdict"] == "OK"
