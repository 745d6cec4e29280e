"""A message on a topic that is not one of our commands is never taken for one (#13).

amqtt (the embedded broker, ``EmbeddedBroker``) sends a client, as it connects, the retained
messages of every filter ANY client subscribed to: ``Broker`` walks the broker-wide
``_subscriptions`` for "a pre-existing session's subscriptions" (amqtt 0.12.1, broker.py), so a
fresh subscriber of ``odocan/robot002/status`` got robot001's retained status as well. While a
monitor held ``odocan/+/#``, each link connecting got every robot's retained ``status`` on its
own connection: counted a ``busy`` command and answered on ``cmd/result`` (command
``odocan/robot002/status``); and a retained message on any 4-level topic under a robot (here
``odocan/robot001/ui/marker``) reached the command reader and was answered as a command.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import aiomqtt
import pytest

from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import EmbeddedBroker
from odocan.host.mqtt.client import Arrived
from odocan.host.mqtt.cmdreader import CommandReader
from odocan.host.mqtt.link import RobotLink
from tests.test_mqtt_robustness import URL

FOREIGN = ["odocan/robot002/status", "odocan/robot001/status", "odocan/robot001/ui/marker",
           "odocan/robot002/cmd/set_pose", "other/robot001/cmd/set_pose",
           "odocan/robot001/cmd/set_pose/x", "odocan/robot001/cmd/result"]
COMMAND = "odocan/robot001/cmd/set_pose"


def _arrived(topic_name: str, *, retain: bool = False) -> Arrived:
    message = Arrived(topic_name, b'{"id": "x"}', 1, retain, 1, None)
    message.arrival_s, message.dup = time.monotonic(), False
    return message


def test_command_of_names_only_a_command_topic() -> None:
    assert topics.command_of(COMMAND) == ("robot001", "set_pose")
    assert topics.command_of("odocan/robot001/cmd/") == ("robot001", "")  # cmd/+ matches it
    assert [topics.command_of(t) for t in FOREIGN[:3] + FOREIGN[4:6]] == [None] * 5


@pytest.mark.parametrize("topic_name", FOREIGN)
def test_the_link_takes_no_foreign_message_for_a_command(topic_name: str) -> None:
    calls: list[tuple[str, Any]] = []
    link = RobotLink(robot="robot001", broker=URL,
                     on_command=lambda n, p, v: calls.append((n, v)) or [])  # type: ignore[func-returns-value]
    link._overflow(_arrived(topic_name, retain=True))
    link._handle(_arrived(topic_name, retain=True))
    assert (calls, link.commands_busy) == ([], 0)
    link._overflow(_arrived(COMMAND))  # a command of its own is one (the test can fail)
    assert (calls, link.commands_busy) == ([("set_pose", "busy")], 1)


@pytest.mark.parametrize("topic_name", FOREIGN[:-1])  # (cmd/result: the echo, dropped in read)
def test_the_reader_queues_no_foreign_message(topic_name: str) -> None:
    reader = CommandReader(robots=["robot001", "robot002"], broker=URL, client_id="t",
                           keepalive_s=5, connect_timeout_s=1.0, session_expiry_s=5.0,
                           capacity=10)
    reader._arrive(None, _arrived(topic_name))  # type: ignore[arg-type]
    reader._arrive(None, _arrived(COMMAND))  # type: ignore[arg-type] # (only a full queue's)
    queued = [m.topic.value for r in reader.robots.values() for m in r.take(10)]
    other = ["odocan/robot002/cmd/set_pose"] if "robot002/cmd" in topic_name else []
    assert sorted(queued) == [COMMAND, *other]


def test_a_bridge_link_on_amqtt_answers_no_other_topics_retained_message(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """amqtt, a monitor subscribed to ``odocan/+/#``, robot002's status and a 4-level topic
    retained: robot001's link connects and reads its commands; it answers none."""
    reached: list[str] = []  # what amqtt sent the link's and the reader's connections
    overflow, arrive = RobotLink._overflow, CommandReader._arrive

    def link_read(link: RobotLink, message: Arrived) -> None:
        reached.append(message.topic.value)
        overflow(link, message)

    def reader_read(reader: CommandReader, client: Any, message: Arrived) -> None:
        reached.append(message.topic.value)
        arrive(reader, client, message)

    monkeypatch.setattr(RobotLink, "_overflow", link_read)
    monkeypatch.setattr(CommandReader, "_arrive", reader_read)

    async def scenario() -> list[tuple[str, Any]]:
        calls: list[tuple[str, Any]] = []
        async with EmbeddedBroker() as broker, aiomqtt.Client(
            **broker.url.client_kwargs()
        ) as monitor:
            foreign = {"odocan/robot002/status", "odocan/robot001/ui/marker"}
            for topic_name in sorted(foreign):
                await monitor.publish(topic_name, b'{"id": "f"}', qos=1, retain=True)
            await monitor.subscribe("odocan/+/#", qos=1)
            link = RobotLink(robot="robot001", broker=broker.url, client_prefix="test-foreign-",
                             on_command=lambda n, p, v: calls.append((n, v)) or [])  # type: ignore[func-returns-value]
            stop = asyncio.Event()
            task = asyncio.create_task(link.run(stop=stop))
            async with asyncio.timeout(20):  # its commands subscribed (a command published
                await link.connected.wait()  # before, on a loaded machine, reached no one)
            await monitor.publish(COMMAND, b'{"id": "c"}', qos=1)  # a command: taken
            async with asyncio.timeout(20):  # the command answered, the foreign ones read
                while not (calls and foreign <= set(reached)):
                    await asyncio.sleep(0.01)
            stop.set()
            await asyncio.wait_for(task, 20)
        return calls

    assert [name for name, _ in asyncio.run(scenario())] == ["set_pose"], reached
