"""One robot's MQTT connection: last will, persistent session, reconnect, outgoing buffer.

``RobotLink.run(stop=...)`` keeps a connection to the broker until ``stop`` is set:

* client id ``<client_prefix>-<robot>`` with ``clean_session=False`` (MQTT 3.1.1): the broker
  keeps the ``cmd/+`` subscription (QoS 1) and queues commands sent while the bridge is away;
* last will: ``status`` = ``{"state": "offline", "reason": "connection lost"}``, QoS 1, retained;
  on a clean stop the bridge publishes ``offline`` (reason ``bridge stopped``) itself;
* reconnect with exponential backoff (``backoff_s`` doubling up to ``max_backoff_s``);
* an outgoing buffer: QoS-1 publications (status, results) stay queued until the broker
  acknowledged them (PUBACK), so none is lost across a broker restart (at least once); QoS-0
  telemetry goes into a bounded deque (the oldest is dropped when it is full, e.g. while the
  broker is away) and is counted in ``telemetry_dropped``.

Commands arrive on ``odocan/<robot>/cmd/<name>`` and go to ``on_command(name, payload)``, which
returns the publications that answer them.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import deque
from collections.abc import Callable
from typing import Any

import aiomqtt

from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import BrokerURL

log = logging.getLogger(__name__)
Publication = tuple[str, dict[str, Any]]
CommandHandler = Callable[[str, bytes], list[Publication]]


class RobotLink:
    """The MQTT side of one robot (see the module docstring)."""

    def __init__(
        self,
        *,
        robot: str,
        broker: BrokerURL,
        on_command: CommandHandler,
        client_prefix: str = "odocan-bridge",
        keepalive_s: int = 5,
        backoff_s: float = 0.1,
        max_backoff_s: float = 5.0,
        telemetry_buffer: int = 1000,
    ) -> None:
        self.robot = topics.check_robot_name(robot)
        self.broker = broker
        self.on_command = on_command
        self.client_id = f"{client_prefix}-{robot}"
        self.keepalive_s = keepalive_s
        self.backoff_s, self.max_backoff_s = backoff_s, max_backoff_s
        self.reliable: deque[tuple[str, bytes, bool]] = deque()
        self.telemetry: deque[tuple[str, bytes]] = deque(maxlen=telemetry_buffer)
        self.telemetry_dropped = 0
        self.connects = 0
        self.connected = asyncio.Event()
        self._wake = asyncio.Event()

    def publish(self, leaf: str, payload: dict[str, Any]) -> None:
        """Queue one publication on ``odocan/<robot>/<leaf>`` (QoS and retain by its class)."""
        topic, body = topics.topic(self.robot, leaf), topics.dumps(payload)
        if topics.qos(leaf) == topics.QOS_TELEMETRY:
            if len(self.telemetry) == self.telemetry.maxlen:
                self.telemetry_dropped += 1
            self.telemetry.append((topic, body))
        else:
            self.reliable.append((topic, body, topics.retained(leaf)))
        self._wake.set()

    def _client(self) -> aiomqtt.Client:
        will = aiomqtt.Will(
            topics.topic(self.robot, topics.STATUS_LEAF),
            topics.dumps(topics.status_payload(self.robot, "offline", reason="connection lost")),
            qos=topics.QOS_RELIABLE,
            retain=True,
        )
        return aiomqtt.Client(
            **self.broker.client_kwargs(),
            identifier=self.client_id,
            clean_session=False,
            will=will,
            keepalive=self.keepalive_s,
            timeout=10,
        )

    async def run(self, *, stop: asyncio.Event) -> None:
        """Connect, serve, reconnect with backoff; returns after a clean stop."""
        backoff = self.backoff_s
        while not stop.is_set():
            try:
                async with self._client() as client:
                    self.connects += 1
                    backoff = self.backoff_s
                    await self._serve(client, stop)
                return
            except* aiomqtt.MqttError as group:
                log.info("%s: broker unreachable (%s); retry in %.1f s",
                         self.robot, group.exceptions[0], backoff)
            finally:
                self.connected.clear()
            await _sleep_or_stop(stop, backoff)
            backoff = min(backoff * 2, self.max_backoff_s)

    async def _serve(self, client: aiomqtt.Client, stop: asyncio.Event) -> None:
        await client.subscribe(topics.command_filter(self.robot), qos=topics.QOS_RELIABLE)
        self.connected.set()
        async with asyncio.TaskGroup() as tg:
            commands = tg.create_task(self._receive(client), name=f"mqtt-commands-{self.robot}")
            tg.create_task(self._send(client, stop, commands), name=f"mqtt-publish-{self.robot}")

    async def _receive(self, client: aiomqtt.Client) -> None:
        prefix = topics.topic(self.robot, "cmd/")
        async for message in client.messages:
            name = message.topic.value.removeprefix(prefix)
            if name == "result" or not isinstance(message.payload, bytes | bytearray):
                continue
            for leaf, payload in self.on_command(name, bytes(message.payload)):
                self.publish(leaf, payload)

    async def _send(
        self, client: aiomqtt.Client, stop: asyncio.Event, commands: asyncio.Task[None]
    ) -> None:
        """Drain the buffers until ``stop``; then ``offline``, flush, and end the receiver."""
        while not stop.is_set():
            await self._flush(client)
            self._wake.clear()
            if not (self.reliable or self.telemetry):
                await _wait_any(self._wake, stop)
        self.telemetry.clear()
        status = topics.topic(self.robot, topics.STATUS_LEAF)
        self.reliable = deque(p for p in self.reliable if p[0] != status)  # superseded
        offline = topics.status_payload(self.robot, "offline", reason="bridge stopped")
        self.publish(topics.STATUS_LEAF, offline)
        await self._flush(client)
        commands.cancel()

    async def _flush(self, client: aiomqtt.Client) -> None:
        """Send what is queued: QoS 1 one by one, each removed only once acknowledged."""
        while self.reliable:
            topic, body, retain = self.reliable[0]
            await client.publish(topic, body, qos=topics.QOS_RELIABLE, retain=retain)
            self.reliable.popleft()
        batch = [self.telemetry.popleft() for _ in range(len(self.telemetry))]
        if batch:
            qos = topics.QOS_TELEMETRY
            await asyncio.gather(*(client.publish(t, b, qos=qos) for t, b in batch))


async def _wait_any(*events: asyncio.Event) -> None:
    """Until one of ``events`` is set."""
    waiters = [asyncio.ensure_future(e.wait()) for e in events]
    try:
        await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for w in waiters:
            w.cancel()


async def _sleep_or_stop(stop: asyncio.Event, delay_s: float) -> None:
    """Sleep ``delay_s`` seconds, or less when ``stop`` is set."""
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(stop.wait(), timeout=delay_s)
