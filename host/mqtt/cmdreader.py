"""The commands of a bridge's robots read off its event loop: one thread, one MQTT connection.

Found by the last pass (#13.4, ``host.mqtt.stallwatch``): a broker holds a bounded queue for a
client that does not read (mosquitto: 20 in flight + ``max_queued_messages``, 1 000) and drops
the rest, silently for the sender, which already has its PUBACK. The link's commands used to
arrive on its event loop's connection, so a loop blocked 6 s under a 1 500-command flood left
~480 acknowledged commands unanswered. ``CommandReader`` reads them on a thread of its own
(``mqtt-cmd-reader``), with its own asyncio loop and its own connection, ONE per bridge process
for all its robots (it subscribes every robot's ``cmd/+``: a fleet worker of 50 robots holds 51
connections and one reader thread, not 100 and 50). Its client id is
``host.mqtt.clientids.reader_client_id`` (<= 23 bytes, stable for the same robots: a worker's
reader differs from every other's); clean start off, session expiry ``session_expiry_s``: the
broker keeps the subscriptions and queues commands while it is away, as the links' connections
did. paho reads, stamps (``Arrived.arrival_s``: the expiry rules count from here) and
acknowledges each command while the bridge's loop is blocked, and the broker never has a queue
to overflow.

Each robot's commands wait in a bounded queue of its own (``capacity``, the link's
``command_queue``) for its link (``RobotCommands``: ``take``; ``wake`` is set when the queue was
empty); a command that finds it full is answered at once from the thread, on this connection,
``rejected`` ("bridge busy"; counted in the robot's ``busy``), and is not run. That answer is
published inside paho's ``on_message``, so it goes out on the socket before the command's own
PUBACK (paho sends it after ``on_message`` returns): a connection that breaks before the broker
has the answer breaks before it has the PUBACK too, and the broker (our session) delivers the
command again, which is answered again (checked: the reader's socket shut right after a busy
answer was published, with the answer not sent again by us, still got the operator its
``rejected``). The bound, then: a blocked loop loses no command; it answers ``busy`` those beyond
``capacity`` that arrive while it is blocked, and ``expired`` those it takes after their expiry.
The links' own ``cmd/result`` answers, published on their connections, come back here
(``cmd/+`` holds them, and MQTT v5's no-local only keeps a connection's own; MQTT 3.1.1 has none,
so there the busy answers come back too): ``read`` drops them on the topic string alone, before
anything is stamped or copied, and counts them (``echoes``). The subscription stays ``cmd/+``
rather than one filter per known command: an unknown command must still be read to be answered
``rejected``; the echo's PUBACK (QoS 1) is paho's and stays. ``start`` is called by
every link at its first connection: the first starts the thread, the others wait for the same
subscriptions. ``stop`` disconnects and joins the thread; nothing is left running.
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
    """A ``LinkClient`` whose messages go to ``reader`` (in its thread) as they are read."""

    reader: Any = None  # the ``CommandReader``

    def _on_message(self, client: paho.Client, userdata: Any,
                    message: paho.MQTTMessage) -> None:
        self.reader.read(self, message)


ECHO_SUFFIX = "/" + topics.RESULT_LEAF  # a topic ending so is an answer, never a command
COMMAND_QUEUE = 1000  # commands per robot read and waiting for its link (``capacity``)
SUBSCRIBE_FILTERS = 64  # ``cmd/+`` filters in one SUBSCRIBE packet


class RobotCommands:
    """One robot's commands read by the process's ``CommandReader``: its link takes them here
    (its event loop); the reader's thread appends them (under the reader's lock)."""

    def __init__(self, reader: CommandReader, robot: str) -> None:
        self.reader, self.robot = reader, robot
        self.arrived: deque[Arrived] = deque()
        self.busy = 0  # commands answered ``rejected`` by the thread: the queue was full
        self.wake = asyncio.Event()  # the link's loop: a command waits (``take``)

    def take(self, n: int) -> list[Arrived]:
        """Up to ``n`` of this robot's commands read, oldest first."""
        with self.reader.lock:
            arrived = self.arrived
            return [arrived.popleft() for _ in range(min(n, len(arrived)))]

    async def start(self, *, v5: bool) -> None:
        """The reader's ``start`` (see there)."""
        await self.reader.start(v5=v5)

    async def stop(self) -> None:
        """The reader's ``stop`` (every robot's: the thread serves them all)."""
        await self.reader.stop()

    def stop_now(self) -> None:
        self.reader.stop_now()


class CommandReader:
    """``robots``' ``cmd/+`` on one thread (see the module docstring)."""

    def __init__(self, *, robots: list[str], broker: BrokerURL, client_id: str,
                 keepalive_s: int, connect_timeout_s: float, session_expiry_s: float,
                 capacity: int, backoff_s: float = 0.1, max_backoff_s: float = 5.0) -> None:
        self.broker, self.client_id, self.v5 = broker, client_id, broker.v5
        self.keepalive_s, self.connect_timeout_s = keepalive_s, connect_timeout_s
        self.session_expiry_s, self.capacity = session_expiry_s, capacity
        self.backoff_s, self.max_backoff_s = backoff_s, max_backoff_s
        self.robots = {name: RobotCommands(self, name) for name in robots}
        # its log lines' name: the robot's, as the link's lines, or the first and last robots'
        self.label = robots[0] if len(robots) == 1 else f"{robots[0]}..{robots[-1]}"
        self.lock = threading.Lock()
        self._main: asyncio.AbstractEventLoop | None = None
        self._started: asyncio.Future[None] | None = None  # the first ``start``'s outcome
        self._subscribed: asyncio.Event | None = None  # the link's loop: subscriptions in place
        self._done: asyncio.Event | None = None  # the link's loop: the thread's loop has ended
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None  # the thread's
        self._stop: asyncio.Event | None = None  # the thread's
        self._stopping = False
        self.echoes = 0  # answers on ``cmd/result`` that came back here: dropped unread

    # --- the links' side (their event loop) ---
    async def start(self, *, v5: bool) -> None:
        """Start the thread (the first call; ``v5``: the broker speaks MQTT v5) and wait for its
        subscriptions; ``BrokerError`` when they are not in place within ``connect_timeout_s``
        (+ 1 s). Later calls wait for the first's outcome."""
        if self._started is None:
            self._started = asyncio.get_running_loop().create_future()
            try:
                await self._start_thread(v5)
            except asyncio.CancelledError:
                self._started.cancel()
                raise
            except BaseException as exc:
                self._started.set_exception(exc)
                self._started.exception()  # retrieved: the other links' waits raise it again
                raise
            self._started.set_result(None)
            return
        await asyncio.shield(self._started)

    async def _start_thread(self, v5: bool) -> None:
        self.v5, self._main = v5, asyncio.get_running_loop()
        self._subscribed, self._done = asyncio.Event(), asyncio.Event()
        self._thread = threading.Thread(target=self._serve_in_thread, daemon=True,
                                        name="mqtt-cmd-reader")
        self._thread.start()
        try:
            async with asyncio.timeout(self.connect_timeout_s + 1.0):
                await self._subscribed.wait()
        except TimeoutError:
            self.stop_now()
            raise BrokerError(f"cannot connect to {self.broker}: the command reader's "
                              "connection did not subscribe in time") from None

    async def stop(self) -> None:
        """Disconnect and join the thread (commands it read stay for ``take``)."""
        if self._thread is None or self._done is None:
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
        if self._main is None:
            return
        with contextlib.suppress(RuntimeError):  # the link's loop is closed: nobody waits
            self._main.call_soon_threadsafe(callback)

    # --- the thread ---
    def _serve_in_thread(self) -> None:
        try:
            asyncio.run(self._serve())
        finally:
            assert self._done is not None
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
                log.warning("%s: command reader reconnecting in %.1f s (%s)", self.label, backoff,
                            connect_failure(exc, self.connect_timeout_s, tls=self.broker.tls))
                await self._sleep(backoff)
                backoff = min(backoff * 2, self.max_backoff_s)
                continue
            backoff = self.backoff_s
            await self._hold(client)

    async def _hold(self, client: _ReaderClient) -> None:
        """Subscribe, then wait for the connection's end or ``stop``; disconnect."""
        assert self._stop is not None and self._subscribed is not None
        try:
            await self._subscribe(client)
            self._to_main(self._subscribed.set)
            stop = asyncio.ensure_future(self._stop.wait())
            lost = client._disconnected
            await asyncio.wait((stop, lost), return_when=asyncio.FIRST_COMPLETED)
            stop.cancel()
            if lost.done() and not lost.cancelled() and lost.exception() is not None:
                log.warning("%s: command reader lost its connection (%s)", self.label,
                            lost.exception())  # (retrieved: asyncio logs none at exit)
        except (aiomqtt.MqttError, OSError) as exc:
            log.warning("%s: command reader lost its connection (%s)", self.label, exc)
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
            on_overflow=lambda _: None, max_waiting=self.capacity * len(self.robots),
            identifier=self.client_id, keepalive=self.keepalive_s,
            timeout=self.connect_timeout_s, logger=CLIENT_LOG,
        )
        client.reader = self
        client._client.connect_timeout = self.connect_timeout_s
        client.pending_calls_threshold = 10**9
        return client

    async def _subscribe(self, client: _ReaderClient) -> None:
        """Every robot's ``cmd/+`` at QoS 1, ``SUBSCRIBE_FILTERS`` filters a packet; in v5 with
        no-local (this connection's busy answers)."""
        filters = [topics.command_filter(robot) for robot in self.robots]
        for start in range(0, len(filters), SUBSCRIBE_FILTERS):
            chunk = filters[start:start + SUBSCRIBE_FILTERS]
            if self.v5:
                options = SubscribeOptions(qos=topics.QOS_RELIABLE, noLocal=True)
                codes = await client.subscribe([(f, options) for f in chunk])
            else:
                codes = await client.subscribe([(f, topics.QOS_RELIABLE) for f in chunk])
            for topic_filter, code in zip(chunk, codes, strict=False):
                if getattr(code, "is_failure", False) or code == 0x80:
                    log.warning("%s: the broker refused the subscription %s (%s): no command "
                                "will arrive", self.label, topic_filter, code)

    def read(self, client: _ReaderClient, message: paho.MQTTMessage) -> None:
        """One message as paho read it (this thread): an answer that came back (``cmd/result``:
        the links' and this connection's own, MQTT 3.1.1 has no no-local) is counted in
        ``echoes`` and dropped on its topic alone, before it is stamped or copied; a command
        goes on to ``_arrive``."""
        if message.topic.endswith(ECHO_SUFFIX):
            self.echoes += 1
            return
        self._arrive(client, arrived_of(message))

    def _arrive(self, client: _ReaderClient, message: Arrived) -> None:
        """One command read (paho's thread of this loop): queued for its robot's link, or
        answered ``rejected`` when ``capacity`` wait already."""
        command = topics.command_of(message.topic.value)  # None: not a command (amqtt)
        if command is None or command[0] not in self.robots:
            return
        robot, name = self.robots[command[0]], command[1]
        with self.lock:
            full = len(robot.arrived) >= self.capacity
            if not full:
                robot.arrived.append(message)
                first = len(robot.arrived) == 1
        if full:
            self._answer_busy(client, robot, name, message)
        elif first:
            self._to_main(robot.wake.set)

    def _answer_busy(self, client: _ReaderClient, robot: RobotCommands, name: str,
                     message: Arrived) -> None:
        robot.busy += 1
        payload = bytes(message.payload) if isinstance(message.payload, bytes | bytearray) \
            else b""
        answer = topics.stamp({"id": command_id(payload), "command": name[:64],
                               "result": "rejected", "reason": BUSY_REASON.format(self.capacity)})
        with contextlib.suppress(aiomqtt.MqttError):
            client.publish_reliable(topics.topic(robot.robot, topics.RESULT_LEAF),
                                    topics.dumps(answer), False)

    def _refused(self, topic: str, reason: str) -> None:
        log.warning("%s: the broker refused a publication on %s (%s)", self.label, topic, reason)
