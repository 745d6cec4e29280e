"""A command the broker delivers again (DUP, after a reconnect) is not run twice (trial13).

From outside (installed wheel): ``odocan bridge`` on mosquitto, the bridge stopped with SIGSTOP,
four QoS-1 commands published, mosquitto restarted (SIGTERM, it saved its state), the bridge
continued: every command was answered ``accepted`` twice and run twice, a ``nav_goal`` with
``"append": true`` appending its goal twice. The bridge's PUBACKs went into the closed
connection, so mosquitto sent all four again with the DUP flag.
"""

from __future__ import annotations

import json
import time

import paho.mqtt.client as paho

from odocan.host.mqtt.client import Arrived, LinkClient
from odocan.host.mqtt.link import RobotLink
from tests.test_mqtt_robustness import URL

GOAL = json.dumps({"id": "g1", "x_m": 1.0, "y_m": 0.0, "append": True}).encode()


def _arrived(payload: bytes, *, dup: bool) -> Arrived:
    message = Arrived("odocan/robot001/cmd/nav_goal", payload, 1, False, 1, None)
    message.arrival_s = time.monotonic()
    message.dup = dup
    return message


def _link(seen: list[str]) -> RobotLink:
    return RobotLink(robot="robot001", broker=URL, command_expiry_s=5.0,
                     on_command=lambda n, p, v: seen.append(v) or [])  # type: ignore[func-returns-value]


def test_a_dup_copy_of_a_command_run_is_not_run_again() -> None:
    other = GOAL.replace(b"g1", b"g0")
    seen: list[str] = []
    link = _link(seen)
    link._answer("nav_goal", _arrived(other, dup=True))  # first delivered to another process: runs
    link._answer("nav_goal", _arrived(GOAL, dup=False))
    link._answer("nav_goal", _arrived(GOAL, dup=True))  # the broker's redelivery: not run
    link._answer("nav_goal", _arrived(GOAL, dup=False))  # its sender sent it again: runs
    assert seen == ["run", "run", "run"]
    assert link.counters()["commands_redelivered"] == 1


def test_the_client_keeps_the_dup_flag() -> None:
    import asyncio

    async def arrive() -> Arrived:
        client = LinkClient(hostname="127.0.0.1", on_refused=lambda *_: None,
                            on_overflow=lambda _: None, max_waiting=10, timeout=5.0)
        message = paho.MQTTMessage(mid=3, topic=b"odocan/robot001/cmd/nav_goal")
        message.payload, message.qos, message.dup = GOAL, 1, True
        client._on_message(client._client, None, message)
        arrived = client._queue.get_nowait()
        assert isinstance(arrived, Arrived)
        return arrived

    assert asyncio.run(arrive()).dup
