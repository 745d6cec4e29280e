"""A command's age counts from when it was sent, not from when the bridge read it (issue #11's
last note).

A bridge stopped 7 s (SIGSTOP) ran a 7 s old set_pose despite the 5 s expiry: the broker's MQTT
v5 message expiry stops at the delivery into the bridge's socket, and the bridge stamped the
arrival when paho read the socket, after SIGCONT. A command may now carry ``sent_unix_s`` (its
sender's wall clock, UNIX s, as a ROS 2 ``header.stamp``): older than ``--command-expiry`` by
the bridge's clock, it is answered ``expired`` and not run, wherever it waited.

The units: the link's verdict from the stamp (a stamp ahead of the clock counts as age 0; the
arrival rule still holds), the encoder takes the key (a wrong type is rejected with its reason).
The process: ``odocan bridge`` on a real mosquitto, stopped with SIGSTOP while three set_poses
are published (plain, with a v5 message expiry, with ``sent_unix_s``), continued after twice
the expiry: the stamped one is answered expired. The other two say what the arrival rule can
know: the report prints them (they run: their age is not known to the bridge).
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import aiomqtt
import can
import pytest
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from odocan.host.mqtt import topics
from odocan.host.mqtt.client import Arrived
from odocan.host.mqtt.link import RobotLink
from tests.conftest_mqtt import Mosquitto, client, collect, mosquitto  # noqa: F401
from tests.test_mqtt_robustness import URL, _bridge

ROOT = Path(__file__).resolve().parents[1]
EXPIRY_S = 2.0  # the bridge's --command-expiry here
STOP_S = 2 * EXPIRY_S  # the bridge stopped this long with the commands waiting in its socket
POSE = {"x_m": 1.0, "y_m": 2.0, "heading_rad": 0.0}


def _arrived(payload: dict[str, Any]) -> Arrived:
    message = Arrived("odocan/robot001/cmd/set_pose", json.dumps(payload).encode(), 1, False, 1,
                      None)
    message.arrival_s = time.monotonic()  # read just now: fresh by the arrival rule
    return message


@pytest.mark.parametrize(("sent_ago_s", "verdict"), [
    (7.0, "expired"),  # the case of the note: waited 7 s before the bridge read it
    (1.0, "run"),
    (-7.0, "run"),  # a sender's clock ahead: age 0 (the arrival rule still bounds it)
])
def test_a_stamped_command_older_than_the_expiry_is_not_run(sent_ago_s: float,
                                                            verdict: str) -> None:
    seen: list[str] = []
    link = RobotLink(robot="robot001", broker=URL, command_expiry_s=5.0,
                     on_command=lambda n, p, v: seen.append(v) or [])  # type: ignore[func-returns-value]
    link._answer("set_pose", _arrived({"id": "s", **POSE,
                                       "sent_unix_s": time.time() - sent_ago_s}))
    assert seen == [verdict]
    assert link.commands_expired == (verdict == "expired")


def test_the_encoder_takes_the_stamp_and_checks_its_type() -> None:
    with can.Bus(interface="virtual", channel=f"sent-{time.monotonic_ns()}") as bus:
        robot_ = _bridge(bus).robots[0]
        fresh = json.dumps({"id": "ok", **POSE, "sent_unix_s": time.time()}).encode()
        (_, accepted), = robot_.on_command("set_pose", fresh)
        wrong = json.dumps({"id": "bad", **POSE, "sent_unix_s": "now"}).encode()
        (_, rejected), = robot_.on_command("set_pose", wrong)
        assert robot_.commands_sent == 1
    assert (accepted["id"], accepted["result"]) == ("ok", "accepted")
    assert (rejected["id"], rejected["result"], rejected["reason"]) == (
        "bad", "rejected", "sent_unix_s must be a number")


def _start_bridge(broker: Mosquitto) -> subprocess.Popen[str]:
    url = broker.url("bridge")
    return subprocess.Popen(
        [sys.executable, "-m", "odocan", "bridge", "-i", "virtual", "-c",
         f"sent-expiry-{os.getpid()}", "--duration", "300", "--command-expiry", f"{EXPIRY_S:g}",
         "--broker", f"mqtt://{url.username}:{url.password}@{url.host}:{url.port}",
         "--client-prefix", f"sent-{os.getpid()}"],
        cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, text=True,
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


async def _while_stopped(broker: Mosquitto, bridge: subprocess.Popen[str]) -> dict[str, str]:
    operator = broker.url("robot001")
    async with client(operator, protocol=aiomqtt.ProtocolVersion.V5) as sub:
        await sub.subscribe(topics.topic("robot001", "status"), qos=1)
        await collect(sub, lambda g: g[-1][1].get("state") == "online", timeout_s=120)
        await sub.unsubscribe(topics.topic("robot001", "status"))
        await sub.subscribe(topics.topic("robot001", topics.RESULT_LEAF), qos=1)
        bridge.send_signal(signal.SIGSTOP)
        try:
            expiring = Properties(PacketTypes.PUBLISH)
            expiring.MessageExpiryInterval = int(EXPIRY_S)
            topic = topics.topic("robot001", "cmd/set_pose")
            await sub.publish(topic, json.dumps({"id": "plain", **POSE}), qos=1)
            await sub.publish(topic, json.dumps({"id": "v5", **POSE}), qos=1,
                              properties=expiring)
            await sub.publish(topic, json.dumps({"id": "stamped", **POSE,
                                                 "sent_unix_s": time.time()}), qos=1)
            await asyncio.sleep(STOP_S)
        finally:
            bridge.send_signal(signal.SIGCONT)
        got = await collect(sub, lambda g: len(g) >= 3, timeout_s=60)
    return {answer["id"]: answer["result"] for _, answer in got}


def test_a_stopped_bridge_refuses_the_stamped_command_it_read_late(
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    bridge = _start_bridge(mosquitto)
    try:
        results = asyncio.run(_while_stopped(mosquitto, bridge))
    finally:
        bridge.send_signal(signal.SIGCONT)
        bridge.terminate()
        _, err = bridge.communicate(timeout=60)
    print(f"\nstopped {STOP_S:g} s, expiry {EXPIRY_S:g} s: {results}")
    assert results["stamped"] == "expired", err
    assert "the bridge's process was stopped for " in err, err  # not "commands read meanwhile"
    assert "event loop did not run" not in err, err
    assert set(results) == {"plain", "v5", "stamped"}
