"""The MQTT bridge follows the firmware's PROFILE page as the monitor does (issue #11 point 4).

A kobuki drive bridged as a pmir: its ``status`` (retained, read back from a real broker) names
the robot whose parameters the firmware runs with, the CRCs checked against the test's own
CRC-32 (``tests.test_profile_page``, from the DBC comment), and the mismatch is an event. A pmir
drive bridged with a profile whose speed bound is below the firmware's: the bridge's live judges
take the bus's bound (the genuine steps are not refused: no POSE WRONG on a correct firmware),
and the status names MAX_WHEEL_SPEED.
"""

from __future__ import annotations

import asyncio
import os
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.host.mqtt import topics
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from odocan.sim.robot import RobotProfile
from tests.conftest_mqtt import broker_of, client, collect
from tests.test_profile_page import crc32_iso_hdlc, parameter_bytes, slow_pmir

NAME = "robot042"
KOBUKI_SAID = ("profile mismatch: profile hash differs: the log's firmware runs with the "
               "parameters of robot 'kobuki', not 'pmir' (--robot)")


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("bridge_profile")
    paths = {name: folder / f"{name}.log" for name in ("kobuki", "pmir")}
    for name, path in paths.items():
        assert main(["run", "--robot", name, "--duration", "3", "--log", str(path)]) == 0
    return paths


def crc_text(profile: RobotProfile, integrator: str = "exact") -> str:
    return f"0x{crc32_iso_hdlc(parameter_bytes(profile, integrator)):08X}"


def bridged(log: Path, profile: RobotProfile) -> RobotTelemetry:
    """The bridge's telemetry of ``log`` for a robot run as ``profile`` (``--robot``)."""
    telemetry = RobotTelemetry(NAME, Geometry.of(profile), "exact",
                               counter_bits=profile.counter_bits, profile_name=profile.name)
    for msg in can.LogReader(str(log)):
        telemetry.feed(msg)
    return telemetry


def test_the_bridge_status_names_a_kobuki_bridged_as_a_pmir(
    logs: dict[str, Path], tmp_path: Path
) -> None:
    """Through a real bridge and broker: the retained status a subscriber reads."""
    pmir = robot.load("pmir")

    async def scenario() -> dict[str, Any]:
        async with broker_of("amqtt", tmp_path) as brokers:
            channel = f"test-bridge-profile-{os.getpid()}"
            bus = can.Bus(interface="virtual", channel=channel)
            endpoint = RobotEndpoint(NAME, bus, Geometry.of(pmir), counter_bits=pmir.counter_bits,
                                     profile_name="pmir")
            bridge = Bridge([endpoint],
                            config=BridgeConfig(broker=brokers.bridge, status_period_s=0.2,
                                                client_prefix=f"test-{channel}"))
            stop = asyncio.Event()
            task = asyncio.create_task(bridge.run(stop=stop), name="bridge")
            try:
                async with asyncio.timeout(10):
                    await bridge.links[0].connected.wait()
                bridge.offer([(0, msg) for msg in can.LogReader(str(logs["kobuki"]))])
                async with client(brokers.operator) as sub:
                    await sub.subscribe(topics.topic(NAME, topics.STATUS_LEAF), qos=1)
                    got = await collect(sub, lambda g: g[-1][1].get("profile") is not None)
            finally:
                stop.set()
                await asyncio.wait_for(task, 10)
                bus.shutdown()
            return got[-1][1]

    status = asyncio.run(scenario())
    assert status["profile"] == {
        "verdict": "MISMATCH", "profile_crc": crc_text(robot.load("kobuki")),
        "expected_crc": crc_text(pmir), "max_wheel_speed_m_s": 0.7, "parameters": [],
        "robot": "kobuki", "detail": KOBUKI_SAID,
    }
    assert [e["detail"] for e in status["events"] if e["kind"] == "profile"] == [KOBUKI_SAID]


def test_the_bridge_status_says_ok_for_the_right_robot(logs: dict[str, Path]) -> None:
    kobuki = robot.load("kobuki")
    status = bridged(logs["kobuki"], kobuki).status()[1]
    assert status["profile"]["verdict"] == "OK"
    assert status["profile"]["profile_crc"] == status["profile"]["expected_crc"] == crc_text(kobuki)
    assert status["profile"]["detail"] is None
    assert "profile" not in [e["kind"] for e in status["events"]]


def test_the_bridge_takes_the_buss_speed_bound(logs: dict[str, Path], tmp_path: Path) -> None:
    """A pmir firmware (4 m/s) bridged with a 0.25 m/s profile: its drive goes beyond 0.25 m/s
    after the first PROFILE page (``test_profile_page``'s monitor case). The bridge published
    the page but kept the profile's bound: its gate refused the genuine steps, POSE WRONG."""
    slow = robot.load(str(slow_pmir(tmp_path, 0.25)))
    telemetry = bridged(logs["pmir"], slow)
    assert telemetry.tracker.counter_restarts == 0
    assert telemetry.tracker.vs_reference.max_dpos_m < POSITION_LSB_M
    status = telemetry.status()[1]
    assert status["pose_wrongs"]["episodes"] == 0
    assert status["distance"]["passed"]
    said = ("profile mismatch: the log's firmware runs with max wheel speed 4 m/s, --robot slow "
            "says 0.25 m/s")
    assert status["profile"] == {
        "verdict": "MISMATCH", "profile_crc": crc_text(robot.load("pmir")),
        "expected_crc": crc_text(slow), "max_wheel_speed_m_s": 4.0,
        "parameters": ["MAX_WHEEL_SPEED"], "robot": None, "detail": said,
    }


def test_the_bridge_names_the_integrator(logs: dict[str, Path]) -> None:
    """The bridge's reference runs rk2 (``--integrator``), the firmware exact: named."""
    kobuki = robot.load("kobuki")
    telemetry = RobotTelemetry(NAME, Geometry.of(kobuki), "rk2", counter_bits=kobuki.counter_bits,
                               profile_name="kobuki")
    for msg in can.LogReader(str(logs["kobuki"])):
        telemetry.feed(msg)
    profile = telemetry.status()[1]["profile"]
    assert profile["parameters"] == ["INTEGRATOR"]
    assert profile["detail"] == ("profile mismatch: the log's firmware runs with integrator "
                                 "exact, not rk2")
