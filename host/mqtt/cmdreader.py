"""One robot's commands read off the bridge's event loop: a thread with its own MQTT connection.

Found by the last pass (#13.4, ``host.mqtt.stallwatch``): a broker holds a bounded queue for a
client that does not read (mosquitto: 20 in flight + ``max_queued_messages``, 1 000) and drops
the rest, silently for the sender, which already has its PUBACK. The link's commands used to
arrive on its event loop's connection, so a loop blocked 6 s under a 1 500-command flood left
~480 acknowledged commands unanswered. ``CommandReader`` reads them on a thread of its own
(``mqtt-cmd-<robot>``), with its own asyncio loop and its own connection (client id
``<link's>-cmd``, clean start off, session expiry ``session_expiry_s``: the broker keeps the
``cmd/+`` subscription and queues commands while it is away, as the link's connection did), so
paho reads, stamps (``Arrived.arrival_s``: the expiry rules count from here) and acknowledges
each command while the bridge's loop is blocked, and the broker never has a queue to overflow.

Commands read wait in a bounded queue (``capacity``, the link's ``command_queue``) for the link
(``take``; ``wake`` is set when the queue was empty); a command that finds it full is answered
at once from the thread, on this connection, ``rejected`` ("bridge busy"; counted in ``busy``),
and is not run. The bound, then: a blocked loop loses no command; it answers ``busy`` those
beyond ``capacity`` that arrive while it is blocked, and ``expired`` those it takes after their
expiry. The link's own ``cmd/result`` answers, published on its other connection, come back here
(``cmd/+`` holds them, and MQTT v5's no-local only keeps a connection's own) and are dropped in
the thread. ``stop`` disconnects and joins the thread; nothing is left running.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections import deque
from typing import Any

import aiomqtt
import paho.mqtt.client as paho
from paho.mqtt.subscribeoptions import SubscribeOptions

from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import BrokerError, BrokerURL, connect_failure
from odocan.host.mqtt.client import Arrived, LinkClient, arrived_of, persistent_session
from odocan.host.mqtt.v5probe import CLIENT_LOG
from odocan.host.protocol.commands import command_id

log = logging.getLogger("odocan.mqtt")
BUSY_REASON = "bridge busy: {} commands already wait to be run: not run"


class _ReaderClient(LinkClient):
    """A ``LinkClient`` whose messages go to ``sink`` (in its thread) as they are read."""

    sink: Any = None

    def _on_message(self, client: paho.Client, userdata: Any,
                    message: paho.MQTTMessage) -> None:
        self.sink(self, arrived_of(message))


class CommandReader:
    """``robot``'s ``cmd/+`` on a thread (see the module docstring)."""

    def __init__(self, *, robot: str, broker: BrokerURL, client_id: str, v5: bool,
                 keepalive_s: int, connect_timeout_s: float, session_expiry_s: float,
                 capacity: int, backoff_s: float = 0.1, max_backoff_s: float = 5.0) -> None:
        self.robot, self.broker, self.client_id, self.v5 = robot, broker, client_id, v5
        self.keepalive_s, self.connect_timeout_s = keepalive_s, connect_timeout_s
        self.session_expiry_s, self.capacity = session_expiry_s, capacity
        self.backoff_s, self.max_backoff_s = backoff_s, max_backoff_s
        self.busy = 0  # commands answered ``rejected`` by the thread: the queue was full
        self.wake = asyncio.Event()  # the link's loop: a command waits (``take``)
        self._arrived: deque[Arrived] = deque()
        self._lock = threading.Lock()
        self._prefix = topics.topic(robot, "cmd/")
        self._main = asyncio.get_running_loop()
        self._subscribed = asyncio.Event()  # the link's loop: the first subscription is in
        self._done = asyncio.Event()  # the link's loop: the thread's loop has ended
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None  # the thread's
        self._stop: asyncio.Event | None = None  # the thread's
        self._stopping = False

    # --- the link's side (its event loop) ---
    async def start(self) -> None:
        """Start the thread and wait for its first subscription; ``BrokerError`` when it is not
        in place within ``connect_timeout_s`` (+ 1 s)."""
        self._thread = threading.Thread(target=self._serve_in_thread, daemon=True,
                                        name=f"mqtt-cmd-{self.robot}")
        self._thread.start()
        try:
            async with asyncio.timeout(self.connect_timeout_s + 1.0):
                await self._subscribed.wait()
        except TimeoutError:
            self.stop_now()
            raise BrokerError(f"cannot connect to {self.broker}: the command reader's "
                              "connection did not subscribe in time") from None

    def take(self, n: int) -> list[Arrived]:
        """Up to ``n`` commands read, oldest first."""
        with self._lock:
            return [self._arrived.popleft() for _ in range(min(n, len(self._arrived)))]

    async def stop(self) -> None:
        """Disconnect and join the thread (commands it read stay for ``take``)."""
        if self._thread is None:
            return
        self._signal_stop()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self.connect_timeout_s + 3.0):
                await self._done.wait()
        self.stop_now()

    def stop_now(self) -> None:
        """``stop`` without the loop (a cancelled link): signal, join (2 s at most)."""
        self._signal_stop()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _signal_stop(self) -> None:
        self._stopping = True
        if self._loop is not None and self._stop is not None:
            with contextlib.suppress(RuntimeError):  # its loop has ended already
                self._loop.call_soon_threadsafe(self._stop.set)

    def _to_main(self, callback: Any) -> None:
        with contextlib.suppress(RuntimeError):  # the link's loop is closed: nobody waits
            self._main.call_soon_threadsafe(callback)

    # --- the thread ---
    def _serve_in_thread(self) -> None:
        try:
            asyncio.run(self._serve())
        finally:
            self._to_main(self._done.set)

    async def _serve(self) -> None:
        """Connect, subscribe, hold the connection; reconnect with backoff until stopped."""
        self._loop, self._stop = asyncio.get_running_loop(), asyncio.Event()
        if self._stopping:
            return
        backoff = self.backoff_s
        while not self._stop.is_set():
            client = self._client()
            try:
                async with asyncio.timeout(self.connect_timeout_s + 1.0):
                    await client.__aenter__()
            except (aiomqtt.MqttError, TimeoutError, OSError) as exc:
                log.warning("%s: command reader reconnecting in %.1f s (%s)", self.robot,
                            backoff, connect_failure(exc, self.connect_timeout_s,
                                                     tls=self.broker.tls))
                await self._sleep(backoff)
                backoff = min(backoff * 2, self.max_backoff_s)
                continue
            backoff = self.backoff_s
            await self._hold(client)

    async def _hold(self, client: _ReaderClient) -> None:
        """Subscribe, then wait for the connection's end or ``stop``; disconnect."""
        assert self._stop is not None
        try:
            await self._subscribe(client)
            self._to_main(self._subscribed.set)
            stop = asyncio.ensure_future(self._stop.wait())
            lost = client._disconnected
            await asyncio.wait((stop, lost), return_when=asyncio.FIRST_COMPLETED)
            stop.cancel()
            if lost.done() and not lost.cancelled() and lost.exception() is not None:
                log.warning("%s: command reader lost its connection (%s)", self.robot,
                            lost.exception())  # (retrieved: asyncio logs none at exit)
        except (aiomqtt.MqttError, OSError) as exc:
            log.warning("%s: command reader lost its connection (%s)", self.robot, exc)
        finally:
            with contextlib.suppress(Exception):
                await client.__aexit__(None, None, None)
            lost = client._disconnected
            if lost.done() and not lost.cancelled():
                lost.exception()  # retrieved, whatever ended the connection: asyncio logs none
        if not self._stop.is_set():
            await self._sleep(self.backoff_s)

    async def _sleep(self, delay_s: float) -> None:
        assert self._stop is not None
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._stop.wait(), timeout=delay_s)

    def _client(self) -> _ReaderClient:
        session = persistent_session(self.v5, self.session_expiry_s)
        client = _ReaderClient(
            **self.broker.client_kwargs(), **session, on_refused=self._refused,
            on_overflow=lambda _: None, max_waiting=self.capacity,
            identifier=self.client_id, keepalive=self.keepalive_s,
            timeout=self.connect_timeout_s, logger=CLIENT_LOG,
        )
        client.sink = self._arrive
        client._client.connect_timeout = self.connect_timeout_s
        client.pending_calls_threshold = 10**9
        return client

    async def _subscribe(self, client: _ReaderClient) -> None:
        """``cmd/+`` at QoS 1; in v5 with no-local (this connection's busy answers)."""
        if self.v5:
            options = SubscribeOptions(qos=topics.QOS_RELIABLE, noLocal=True)
            codes = await client.subscribe(topics.command_filter(self.robot), options=options)
        else:
            codes = await client.subscribe(topics.command_filter(self.robot), qos=1)
        for code in codes if isinstance(codes, list) else [codes]:
            if getattr(code, "is_failure", False) or code == 0x80:
                log.warning("%s: the broker refused the subscription %s (%s): no command will "
                            "arrive", self.robot, topics.command_filter(self.robot), code)

    def _arrive(self, client: _ReaderClient, message: Arrived) -> None:
        """One message read (paho's thread of this loop): queued for the link, or answered
        ``rejected`` when ``capacity`` wait already; the link's own answers are dropped."""
        name = message.topic.value.removeprefix(self._prefix)
        if name == "result":
            return
        with self._lock:
            full = len(self._arrived) >= self.capacity
            if not full:
                self._arrived.append(message)
                first = len(self._arrived) == 1
        if full:
            self._answer_busy(client, name, message)
        elif first:
            self._to_main(self.wake.set)

    def _answer_busy(self, client: _ReaderClient, name: str, message: Arrived) -> None:
        self.busy += 1
        payload = bytes(message.payload) if isinstance(message.payload, bytes | bytearray) \
            else b""
        answer = topics.stamp({"id": command_id(payload), "command": name[:64],
                               "result": "rejected", "reason": BUSY_REASON.format(self.capacity)})
        with contextlib.suppress(aiomqtt.MqttError):
            client.publish_reliable(topics.topic(self.robot, topics.RESULT_LEAF),
                                    topics.dumps(answer), False)

    def _refused(self, topic: str, reason: str) -> None:
        log.warning("%s: the broker refused a publication on %s (%s)", self.robot, topic, reason)
