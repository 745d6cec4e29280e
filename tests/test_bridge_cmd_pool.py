"""One command reader per bridge process: one thread and one connection for all its robots (#13).

The command reader (``host.mqtt.cmdreader``) used to be one thread and one MQTT connection per
robot: a fleet worker with 50 robots held 100 connections to the broker and 50 reader threads.
Here a bridge of ``ROBOTS`` robots on a real broker (mosquitto, and the embedded amqtt which
speaks MQTT 3.1.1): the connections this process holds to the broker (counted by the kernel,
through psutil) are one per robot and one more, one reader thread runs, and each robot's
commands still reach that robot (a command to each one, answered on its own ``cmd/result``).
When the bridge has stopped, no reader thread is left.
"""

from __future__ import annotations

import asyncio
import json
import os
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import can
import psutil
import pytest

from odocan.host.mqtt import cmdreader, topics
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.client import arrived_of
from odocan.sim.fleet import robot_name
from tests.conftest_mqtt import broker_of, client, collect
from tests.test_mqtt_bridge import BROKERS, GEOMETRY, PMIR

ROBOTS = 5
NAMES = [robot_name(i) for i in range(ROBOTS)]


def _reader_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("mqtt-cmd-")]


def _connections_to(port: int) -> int:
    """This process's established TCP connections to ``port`` (the kernel's count)."""
    return sum(1 for c in psutil.Process().net_connections(kind="tcp")
               if c.raddr and c.raddr.port == port and c.status == psutil.CONN_ESTABLISHED)


@asynccontextmanager
async def _bridge(url: BrokerURL) -> AsyncIterator[Bridge]:
    buses = [can.Bus(interface="virtual", channel=f"pool-{os.getpid()}-{n}") for n in NAMES]
    endpoints = [RobotEndpoint(n, bus, GEOMETRY, counter_bits=PMIR.counter_bits)
                 for n, bus in zip(NAMES, buses, strict=True)]
    bridge = Bridge(endpoints, config=BridgeConfig(broker=url,
                                                   client_prefix=f"pool{os.getpid()}"))
    stop = asyncio.Event()
    task = asyncio.create_task(bridge.run(stop=stop), name="bridge")
    try:
        async with asyncio.timeout(20):
            for link in bridge.links:
                await link.connected.wait()
        yield bridge
    finally:
        stop.set()
        await asyncio.wait_for(task, 20)
        for bus in buses:
            bus.shutdown()


async def _answers(url: BrokerURL) -> dict[str, dict[str, Any]]:
    """One unknown command to each robot: its answer by the topic it came on."""
    async with client(url) as sub:
        await sub.subscribe([(topics.topic(n, topics.RESULT_LEAF), 1) for n in NAMES])
        for name in NAMES:
            await sub.publish(topics.topic(name, "cmd/teleport"),
                              json.dumps({"id": name}).encode(), qos=1)
        got = await collect(sub, lambda g: len(g) >= ROBOTS, timeout_s=20)
    return {t: payload for t, payload in got}


@pytest.mark.parametrize("kind", BROKERS)
def test_one_reader_thread_and_one_connection_serve_every_robot(
    kind: str, tmp_path: Path,
) -> None:
    async def scenario() -> tuple[list[str], int, dict[str, dict[str, Any]]]:
        async with broker_of(kind, tmp_path) as brokers, _bridge(brokers.bridge) as _:
            threads = _reader_threads()
            connections = _connections_to(brokers.bridge.port)
            answers = await _answers(brokers.bridge)
        return threads, connections, answers

    threads, connections, answers = asyncio.run(scenario())
    assert connections == ROBOTS + 1  # a link each, one reader
    assert len(threads) == 1, threads
    assert {t: (a["id"], a["result"]) for t, a in answers.items()} == {
        topics.topic(n, topics.RESULT_LEAF): (n, "rejected") for n in NAMES}
    assert _reader_threads() == []  # stopped: joined


@pytest.mark.parametrize("kind", BROKERS)
def test_the_bridges_own_answers_come_back_and_are_dropped_unread(
    kind: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each answer a link publishes on ``cmd/result`` comes back to the reader (its ``cmd/+``;
    MQTT 3.1.1 has no no-local, and v5's keeps only a connection's own): it is counted and
    dropped on its topic, never stamped and copied as a command is (``arrived_of``, counted
    here), nor answered. Before, every answer was made an ``Arrived`` and dropped after."""
    parsed: list[str] = []
    real = arrived_of  # the reader's (cmdreader imports it from client)

    def counting(message: Any) -> Any:
        parsed.append(message.topic)
        return real(message)

    monkeypatch.setattr(cmdreader, "arrived_of", counting)

    async def scenario() -> tuple[dict[str, dict[str, Any]], int]:
        async with broker_of(kind, tmp_path) as brokers, _bridge(brokers.bridge) as bridge:
            answers = await _answers(brokers.bridge)
            async with asyncio.timeout(20):  # every echo read, or (before) parsed
                while getattr(bridge.commands, "echoes", 0) < ROBOTS and \
                        len(parsed) < 2 * ROBOTS:
                    await asyncio.sleep(0.05)
            return answers, getattr(bridge.commands, "echoes", 0)

    answers, echoes = asyncio.run(scenario())
    assert sorted(parsed) == sorted(topics.topic(n, "cmd/teleport") for n in NAMES)
    assert echoes == ROBOTS
    assert sorted(answers) == sorted(topics.topic(n, topics.RESULT_LEAF) for n in NAMES)
