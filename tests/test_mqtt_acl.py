"""Least privilege with mosquitto ACLs: the roles of docs/mqtt.md (``ROLES_ACL``) against a real
broker, and the CAN side of each refusal.

Each robot's bridge logs in as its robot name and may publish only its own telemetry and
results and read only its own commands (``pattern`` lines with ``%u``); an operator may command
any robot; a viewer may only read. A command from a user without the right is refused by the
broker (MQTT v5 PUBACK reason code 0x87, "Not authorized") and never reaches the bus: the test
listens on the robot's virtual CAN channel. The bridge reports what the broker refused it.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import threading
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from itertools import count
from pathlib import Path

import can
import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import topics
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL, EmbeddedBroker
from odocan.sim import robot
from odocan.sim.exceptions import ConfigurationError
from tests.conftest_mqtt import Mosquitto, client
from tests.requires import require_executables

README = Path(__file__).resolve().parents[1] / "docs" / "mqtt.md"  # its security section
USERS = {"robot001": "pw-r1", "robot002": "pw-r2", "operator": "pw-op", "viewer": "pw-view"}
PMIR = robot.load("pmir")
GEOMETRY = Geometry.of(PMIR)
SET_POSE = {"x_m": 1.0, "y_m": 2.0, "heading_rad": 0.5}
_channels = count()
ANSWER_WAIT_S = 30.0  # a bound only: each wait ends when what it waits for came
REFUSED_STATUS = ("robot001: the broker refused a publication on odocan/robot001/status "
                  "(Not authorized)")


def roles_acl() -> str:
    """The example ACL of the README (the block after "# odocan roles"): the tests prove the
    documented file, not a copy of it."""
    text = README.read_text()
    start = text.index("# odocan roles")
    return text[start:text.index("```", start)]


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[Mosquitto]:
    require_executables("mosquitto", "mosquitto_passwd", install="apt-get install mosquitto")
    mosquitto = Mosquitto(tmp_path, users=USERS, acl=roles_acl())
    mosquitto.start()
    try:
        yield mosquitto
    finally:
        mosquitto.stop()


def publish_v5(url: BrokerURL, topic: str, payload: dict[str, object]) -> str:
    """Publish at QoS 1 with MQTT v5 (paho, no aiomqtt in between) and return the PUBACK's
    reason code as text ("Success", "Not authorized", ...)."""
    acked, reason = threading.Event(), []

    def on_publish(_c: paho.Client, _u: object, _mid: int, code: object, _p: object) -> None:
        reason.append(str(code))
        acked.set()

    mqtt = paho.Client(CallbackAPIVersion.VERSION2, protocol=paho.MQTTv5)
    mqtt.username_pw_set(url.username, url.password)
    mqtt.on_publish = on_publish
    mqtt.connect(url.host, url.port)
    mqtt.loop_start()
    try:
        mqtt.publish(topic, json.dumps(payload), qos=1)
        assert acked.wait(5), "no PUBACK"
    finally:
        mqtt.disconnect()
        mqtt.loop_stop()
    return reason[0]


@asynccontextmanager
async def bridge_of(url: BrokerURL, name: str) -> AsyncIterator[can.BusABC]:
    """A bridge for robot ``name`` logged in as ``url``'s user; yields a listener on its CAN
    channel (every frame the bridge sends arrives there)."""
    channel = f"test-acl-{os.getpid()}-{next(_channels)}"
    send_bus = can.Bus(interface="virtual", channel=channel)
    listener = can.Bus(interface="virtual", channel=channel)
    bridge = Bridge([RobotEndpoint(name, send_bus, GEOMETRY, counter_bits=PMIR.counter_bits)],
                    config=BridgeConfig(broker=url, client_prefix=f"acl-{channel}"))
    stop = asyncio.Event()
    task = asyncio.create_task(bridge.run(stop=stop), name="bridge")
    try:
        async with asyncio.timeout(10):
            await bridge.links[0].connected.wait()
        yield listener
    finally:
        stop.set()
        await asyncio.wait_for(task, 10)
        send_bus.shutdown()
        listener.shutdown()


def frames_on(bus: can.BusABC) -> list[can.Message]:
    frames = []
    while (msg := bus.recv(0)) is not None:
        frames.append(msg)
    return frames


async def results(url: BrokerURL, name: str, subscribed: asyncio.Event,
                  last_id: str) -> list[dict[str, object]]:
    """``cmd/result`` messages of robot ``name`` (read as ``url``), from ``subscribed`` (set once
    the broker granted the subscription) until the answer to command ``last_id`` (a bound of
    ``ANSWER_WAIT_S``: a loaded machine's bridge answers late, and a fixed 3 s watch closed
    before it did)."""
    got: list[dict[str, object]] = []
    async with client(url) as sub:
        await sub.subscribe(topics.topic(name, topics.RESULT_LEAF), qos=1)
        subscribed.set()
        async with asyncio.timeout(ANSWER_WAIT_S):
            async for message in sub.messages:
                assert isinstance(message.payload, bytes)
                got.append(json.loads(message.payload))
                if got[-1]["id"] == last_id:
                    break
    return got


def test_only_an_operator_moves_a_robot(broker: Mosquitto) -> None:
    """robot002, the viewer and robot001 itself publish set_pose to robot001: each PUBACK says
    "Not authorized", no result is published, no frame reaches robot001's bus. Then the
    operator: "Success", an accepted result, and the frames on the bus."""

    async def scenario() -> tuple[dict[str, str], list[can.Message], list[can.Message],
                                  list[dict[str, object]]]:
        target = topics.topic("robot001", "cmd/set_pose")
        async with bridge_of(broker.url("robot001"), "robot001") as bus:
            subscribed = asyncio.Event()
            watch = asyncio.create_task(results(broker.url("viewer"), "robot001", subscribed,
                                                "by-operator"))
            async with asyncio.timeout(ANSWER_WAIT_S):
                await subscribed.wait()
            codes = {}
            for user in ("robot002", "viewer", "robot001"):
                codes[user] = await asyncio.to_thread(
                    publish_v5, broker.url(user), target, {"id": f"by-{user}", **SET_POSE})
            await asyncio.sleep(1.0)  # time for a command to arrive, had it been let through
            refused_frames = frames_on(bus)
            codes["operator"] = await asyncio.to_thread(
                publish_v5, broker.url("operator"), target, {"id": "by-operator", **SET_POSE})
            answers = await watch
            return codes, refused_frames, frames_on(bus), answers

    codes, refused_frames, operator_frames, answers = asyncio.run(scenario())
    assert codes == {"robot002": "Not authorized", "viewer": "Not authorized",
                     "robot001": "Not authorized", "operator": "Success"}
    assert refused_frames == []
    assert len(operator_frames) >= 1  # ODOM_SET_POSE (in as many frames as it takes)
    assert {a["id"] for a in answers} == {"by-operator"}  # no answer to any refused command
    assert answers[0]["result"] == "accepted"


def test_a_robot_reads_only_its_own_commands(broker: Mosquitto,
                                             caplog: pytest.LogCaptureFixture) -> None:
    """A bridge for robot001 logged in as robot002 (a wrong set-up): the broker refuses its
    publications, and the bridge says so with the v5 reason code; the operator's command for
    robot001 never reaches it. (mosquitto 2.0 grants the subscription, SUBACK "Granted QoS 1",
    and filters at delivery, so there is no subscription refusal to report.)"""
    caplog.set_level(logging.WARNING, logger="odocan")

    async def scenario() -> list[can.Message]:
        async with bridge_of(broker.url("robot002"), "robot001") as bus:
            await asyncio.to_thread(publish_v5, broker.url("operator"),
                                    topics.topic("robot001", "cmd/set_pose"),
                                    {"id": "op", **SET_POSE})
            async with asyncio.timeout(ANSWER_WAIT_S):  # the first status (QoS 1) refused
                while REFUSED_STATUS not in warnings_of(caplog):
                    await asyncio.sleep(0.05)
            await asyncio.sleep(1.0)  # time for the command to arrive, had it been let through
            return frames_on(bus)

    assert asyncio.run(scenario()) == []  # the operator's command never reached this bridge
    assert REFUSED_STATUS in warnings_of(caplog)


def warnings_of(caplog: pytest.LogCaptureFixture) -> list[str]:
    """The WARNING lines logged so far."""
    return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]


def test_a_viewer_reads_what_robots_publish(broker: Mosquitto) -> None:
    """The positive side of the roles: robot001's retained status reaches a viewer."""

    async def scenario() -> dict[str, object]:
        async with bridge_of(broker.url("robot001"), "robot001"), \
                client(broker.url("viewer")) as sub:
            await sub.subscribe(topics.topic("robot001", topics.STATUS_LEAF), qos=1)
            async with asyncio.timeout(5):
                async for message in sub.messages:
                    assert isinstance(message.payload, bytes)
                    status: dict[str, object] = json.loads(message.payload)
                    return status
        raise AssertionError("no status")

    assert asyncio.run(scenario())["state"] == "online"


def test_the_embedded_broker_listens_on_loopback_only(capsys: pytest.CaptureFixture[str]) -> None:
    from odocan.host.cli.app import main

    code = main(["bridge", "-i", "virtual", "-c", "acl-listen", "--listen", "0.0.0.0"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.splitlines() == [
        "error: the embedded broker lets anyone in (no users, no TLS): it listens on loopback "
        "only, not on '0.0.0.0'; to serve other machines run a broker with users, ACLs and TLS "
        "and give it with --broker"]
    for address in ("0.0.0.0", "::", "192.168.1.10", "broker.example"):
        with pytest.raises(ConfigurationError, match="loopback only"):
            EmbeddedBroker(bind=address)
    for address in ("127.0.0.1", "::1", "localhost"):
        EmbeddedBroker(bind=address)  # accepted (it binds 127.0.0.1)
