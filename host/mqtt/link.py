"""One robot's MQTT connection: MQTT v5, last will, session, reconnect, two bounded buffers.

``RobotLink.run(stop=...)`` keeps a connection to the broker until ``stop`` is set:

* MQTT v5 (``paho`` via aiomqtt) so the broker's reason codes are seen: a CONNACK refusal is a
  ``BrokerError`` naming the reason; a PUBACK or SUBACK refusal (an ACL denial) is one warning line
  per topic, counted in ``refused``. A broker that answers "unsupported protocol version" to a
  plain v5 CONNECT (``speaks_v5``, once per broker; amqtt) is spoken to in MQTT 3.1.1 instead (no
  reason codes, no message expiry);
* the first connection must succeed within ``connect_timeout_s``, else ``BrokerError`` (the
  CLI's exit 2); later losses are one line each: "connection lost", "reconnecting in N s",
  "reconnected" (exponential backoff from ``backoff_s`` up to ``max_backoff_s``);
* client id ``<client_prefix><robot>`` (0-9a-zA-Z, at most 23 bytes: MQTT 3.1.1's guarantee;
  else a stable short form: ``host.mqtt.clientids``), clean start off, session expiry
  ``command_expiry_s``.
  A broker that comes back without that session although we saw ourselves away for less is one
  warning line (``sessions_lost``: what it held is gone; ``broker.session_lost`` says why);
* commands are read off this loop: ``host.mqtt.cmdreader.CommandReader``, a thread with its own
  connection, one per bridge process (``commands``: this robot's share of it; without it, one of
  its own), with its own session of the same expiry (the broker keeps the ``cmd/+``
  subscriptions and queues commands while the bridge is away, for at most
  ``command_expiry_s``), reads and acknowledges them even while this loop is blocked,
  into a queue of ``command_queue`` (a broker's own queue for a client that does not read drops
  commands it acknowledged, unanswered); ``_receive`` takes them from there. Commands read
  before a connection broke, or before the bridge stopped, are still answered;
* last will: ``status`` = ``{"state": "offline", "reason": "connection lost"}``, QoS 1, retained;
  whenever ``run`` ends (stop, cancellation, an error) it publishes ``offline`` itself first,
  with ``last_status``'s fields (the bridge's: the robot's last status, its verdicts final);
* telemetry never waits for acknowledgements: QoS-0 telemetry and QoS-1 publications (status,
  results) have their own buffers and their own sender tasks. Telemetry is a bounded deque that
  drops the oldest (``telemetry_dropped``); while disconnected it is not kept at all
  (``telemetry_offline``: no stale pose is replayed after an outage), but before the first
  connection (a bridge joining a running firmware: nothing lost, sent once connected) and once
  the bridge stops (the watch's end, written before ``offline``) it is kept. QoS-1 publications stay
  queued until the broker acknowledged them (at least once across broker restarts; a ``status``
  queued while disconnected replaces the queued ones, ``status_superseded``), up to
  ``reliable_buffer`` entries: beyond, the oldest ``status`` (superseded) goes first, then the
  oldest interim ``accepted`` answer (a command's final answer stays), then the oldest entry
  (``reliable_dropped``). The answers owed when the bridge stops, to the commands the reader
  read and the link had not taken (up to ``command_queue``), are kept beyond the bound and
  flushed with ``offline``; those the broker did not acknowledge by then are counted
  (``answers_unsent``) and said in one warning line;
* commands arrive on ``odocan/<robot>/cmd/<name>`` and go to ``on_command(name, payload,
  verdict)``, which returns the publications that answer it (``cmd/result``). ``verdict`` is
  ``"run"``, or ``"expired"`` when the message is older than its MQTT v5 message expiry (the
  remaining interval the broker passed on) or, without one, than ``command_expiry_s`` since it
  arrived, or, when it carries ``sent_unix_s`` (``host.protocol.commands``), more than
  ``command_expiry_s`` older than that by this host's wall clock. The broker's expiry stops at
  the delivery into our socket and paho stamps the arrival when it reads the socket, so a
  message that waited in the socket (the bridge stopped, SIGSTOP, or starved) looks fresh to
  both rules: only its send time tells its age (a stamp ahead of our clock counts as age 0:
  the arrival rule still bounds it; the verdict, ``host.mqtt.expiry.Expired``, says which rule
  applied); or ``"busy"`` when ``command_queue`` messages already
  wait (answered at once, not run), or ``"retained"`` for a command the broker kept as
  retained (its age is unknown, and it would run again at every reconnect).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections import Counter, deque
from collections.abc import Callable
from itertools import islice
from typing import Any, Literal

import aiomqtt

from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import (
    BrokerError,
    BrokerURL,
    connect_failure,
    first_connect_failure,
    protocol_unsupported,
    session_lost,
)
from odocan.host.mqtt.client import Arrived, ClosedBeforeConnack, LinkClient, persistent_session
from odocan.host.mqtt.clientids import DEFAULT_PREFIX, link_client_id, reader_client_id
from odocan.host.mqtt.cmdreader import CommandReader, RobotCommands
from odocan.host.mqtt.expiry import Expired, Fresh, expired_by, fresh
from odocan.host.mqtt.outgoing import Outgoing, publish_once
from odocan.host.mqtt.redelivery import Redeliveries
from odocan.host.mqtt.v5probe import CLIENT_LOG, speaks_v5

log = logging.getLogger("odocan.mqtt")
Publication = tuple[str, dict[str, Any]]
Verdict = Literal["run", "expired", "busy", "retained"]
COMMANDS_PER_TURN = 8  # commands handled before the event loop's other tasks get a turn
ROOM_POLL_S = 0.01  # commands wait this long for room in the QoS-1 buffer (``_receive``)
GOODBYE_S, GOODBYE_S_PER_ENTRY = 2.0, 0.005  # the QoS-1 buffer's flush at the stop, at most
CommandHandler = Callable[[str, bytes, Verdict | Expired | Fresh], list[Publication]]


class _Stopped(Exception):
    """``stop`` was set: leave the connection's task group."""


class RobotLink:
    """The MQTT side of one robot (see the module docstring)."""

    def __init__(
        self,
        *,
        robot: str,
        broker: BrokerURL,
        on_command: CommandHandler,
        client_prefix: str = DEFAULT_PREFIX,
        keepalive_s: int = 5,
        connect_timeout_s: float = 5.0,
        command_expiry_s: float = 5.0,
        backoff_s: float = 0.1,
        max_backoff_s: float = 5.0,
        telemetry_buffer: int = 1000,
        reliable_buffer: int = 1000,
        inflight: int = 20,
        command_queue: int = 1000,
        commands: RobotCommands | None = None,
    ) -> None:
        self.robot = topics.check_robot_name(robot)
        self.broker = broker
        self.on_command = on_command
        self.client_id = link_client_id(client_prefix, robot)
        self.keepalive_s = keepalive_s
        self.connect_timeout_s, self.command_expiry_s = connect_timeout_s, command_expiry_s
        self.backoff_s, self.max_backoff_s = backoff_s, max_backoff_s
        self.reliable: deque[Outgoing] = deque()
        self.reliable_buffer, self.inflight = reliable_buffer, inflight
        self.telemetry: deque[tuple[str, bytes]] = deque(maxlen=telemetry_buffer)
        self.command_queue = command_queue
        self.v5 = broker.v5
        self.telemetry_dropped = self.telemetry_offline = self.reliable_dropped = 0
        self.commands_expired = self.commands_busy = self.status_superseded = 0
        self.refused: Counter[str] = Counter()  # topic -> publications the broker refused
        self.connects = 0
        self.answers_unsent = 0  # command answers the broker had not acknowledged at the stop
        self._owed = False  # the stop's answers are queued: the QoS-1 buffer drops none
        self.sessions_lost = 0  # reconnects to a broker that had lost our session (state)
        self.connected = asyncio.Event()
        # the fields ``offline`` carries besides its reason (the bridge's: the robot's last
        # status, its verdicts final); None: none
        self.last_status: Callable[[], dict[str, Any]] | None = None
        self._stop: asyncio.Event | None = None  # ``run``'s
        self.redeliveries = Redeliveries()  # a DUP copy of a command handled is not run again
        # this robot's commands, read on the process's reader thread (started by ``run``)
        self.reader: RobotCommands = commands or CommandReader(
            robots=[self.robot], broker=broker,
            client_id=reader_client_id(client_prefix, [self.robot]), keepalive_s=keepalive_s,
            connect_timeout_s=connect_timeout_s, session_expiry_s=command_expiry_s,
            capacity=command_queue, backoff_s=backoff_s, max_backoff_s=max_backoff_s,
        ).robots[self.robot]
        self._receiver: asyncio.Task[None] | None = None  # ``_receive``, from the first connection
        self._telemetry_wake = asyncio.Event()
        self._reliable_wake = asyncio.Event()

    # --- the buffers (any task of the event loop) ---
    def publish(self, leaf: str, payload: dict[str, Any]) -> None:
        """Queue one publication on ``odocan/<robot>/<leaf>`` (QoS and retain by its class)."""
        topic, body = topics.topic(self.robot, leaf), topics.dumps(payload)
        if topics.qos(leaf) == topics.QOS_TELEMETRY:
            if not self.connected.is_set() and self.connects and not self._stopping:
                self.telemetry_offline += 1  # stale by the time the broker is back
                return
            if len(self.telemetry) == self.telemetry.maxlen:
                self.telemetry_dropped += 1
            self.telemetry.append((topic, body))
            self._telemetry_wake.set()
            return
        if leaf == topics.STATUS_LEAF and not self.connected.is_set():
            self._supersede_status(topic)
        if len(self.reliable) >= self.reliable_buffer and not self._owed:
            self._drop_reliable()
        interim = leaf == topics.RESULT_LEAF and payload.get("result") == "accepted"
        self.reliable.append(Outgoing(topic, body, topics.retained(leaf), interim))
        self._reliable_wake.set()

    @property
    def _stopping(self) -> bool:
        """The bridge stops: its last telemetry (the watch's end) goes with ``offline``."""
        return self._stop is not None and self._stop.is_set()

    def _supersede_status(self, topic: str) -> None:
        """Offline, a new ``status`` (retained: the broker keeps only the latest) supersedes
        the queued ones: not replayed in a burst when the broker is back (``status_superseded``)."""
        kept = deque(p for p in self.reliable if p.topic != topic)
        self.status_superseded += len(self.reliable) - len(kept)
        self.reliable = kept

    def _drop_reliable(self) -> None:
        """The oldest ``status`` (the next supersedes it), else the oldest interim answer (its
        command's final answer is the one its sender waits for), else the oldest."""
        status = topics.topic(self.robot, topics.STATUS_LEAF)
        victim = next((p for p in self.reliable if p.topic == status), None) or next(
            (p for p in self.reliable if p.interim), self.reliable[0])
        self.reliable.remove(victim)
        if self.reliable_dropped == 0:
            log.warning("%s: QoS-1 buffer full (%d): dropping the oldest", self.robot,
                        self.reliable_buffer)
        self.reliable_dropped += 1

    def counters(self) -> dict[str, int]:
        """What this link dropped, refused, expired (published in ``rates``, and reported)."""
        return {
            "telemetry_dropped": self.telemetry_dropped,
            "telemetry_offline": self.telemetry_offline,
            "reliable_dropped": self.reliable_dropped,
            "reliable_queued": len(self.reliable),
            "status_superseded": self.status_superseded,
            "refused": sum(self.refused.values()),
            "commands_expired": self.commands_expired,
            "commands_busy": self.commands_busy + self.reader.busy,
            "reconnects": max(self.connects - 1, 0),
            "sessions_lost": self.sessions_lost,
            "answers_unsent": self.answers_unsent,
            "commands_redelivered": self.redeliveries.skipped,
        }

    # --- the connection ---
    def _client(self) -> LinkClient:
        will = aiomqtt.Will(
            topics.topic(self.robot, topics.STATUS_LEAF),
            topics.dumps(topics.status_payload(self.robot, "offline", reason="connection lost")),
            qos=topics.QOS_RELIABLE,
            retain=True,
        )
        session = persistent_session(self.v5, self.command_expiry_s)
        client = LinkClient(
            **self.broker.client_kwargs(), **session,
            on_refused=self._refused, on_overflow=self._overflow,
            max_waiting=0,  # commands come on the reader's connection: one here is not run
            identifier=self.client_id, will=will, keepalive=self.keepalive_s,
            timeout=self.connect_timeout_s, logger=CLIENT_LOG,
        )
        client._client.connect_timeout = self.connect_timeout_s  # the TCP connect, in paho
        client.pending_calls_threshold = 10**9  # our buffers are bounded; no per-call warning
        return client

    async def _serve(self, *, stop: asyncio.Event) -> None:
        """``run``'s connections: the first, then again after each loss, with backoff."""
        if self.v5:
            self.v5 = await speaks_v5(self.broker, self.connect_timeout_s)
        backoff, lost_at = self.backoff_s, time.monotonic()
        while not stop.is_set():
            client = self._client()
            try:
                await self._connect(client)
            except (aiomqtt.MqttError, TimeoutError, OSError) as exc:
                if self.v5 and (protocol_unsupported(exc) or isinstance(exc, ClosedBeforeConnack)):
                    self.v5 = False
                    log.info("%s: %s speaks MQTT 3.1.1 only: no reason codes, no message "
                             "expiry", self.robot, self.broker)
                    continue
                if self.connects == 0:
                    reason = await first_connect_failure(exc, self.broker, self.connect_timeout_s)
                    raise BrokerError(f"cannot connect to {self.broker}: {reason}") from None
                reason = connect_failure(exc, self.connect_timeout_s, tls=self.broker.tls)
                log.warning("%s: reconnecting in %.1f s (%s)", self.robot, backoff, reason)
                await _sleep_or_stop(stop, backoff)
                backoff = min(backoff * 2, self.max_backoff_s)
                continue
            if self.connects == 0:
                await self._start_reader(client)
            self.connects += 1
            backoff = self.backoff_s
            if self.connects > 1:
                log.warning("%s: reconnected to %s", self.robot, self.broker)
                self._check_session(client, time.monotonic() - lost_at)
            try:
                await self._session(client, stop)
            except* (aiomqtt.MqttError, OSError) as group:
                lost_at = time.monotonic()
                log.warning("%s: connection lost (%s); reconnecting in %.1f s", self.robot,
                            group.exceptions[0], backoff)
                await _sleep_or_stop(stop, backoff)

    async def run(self, *, stop: asyncio.Event) -> None:
        """Connect, serve, reconnect with backoff; returns after ``stop``.

        ``BrokerError`` when the first connection fails (refused, not authorized, TLS, DNS, no
        answer within ``connect_timeout_s``): a bridge that never connected tells so at once.
        The command reader's thread, started with the first connection, is stopped and joined
        whatever ends ``run``.
        """
        self._stop = stop
        try:
            await self._serve(stop=stop)
        finally:
            if self._receiver is not None:
                self._receiver.cancel()
            self.reader.stop_now()  # stopped already unless an error or a cancellation

    async def _start_reader(self, client: LinkClient) -> None:
        """The command reader's thread (its subscriptions in place; started by the process's
        first link), then ``_receive``; ``BrokerError`` when it cannot subscribe. A session
        this connection kept from a bridge that read its commands here loses its ``cmd/+``
        subscription (no command read twice)."""
        if client.session_present:
            with contextlib.suppress(aiomqtt.MqttError):
                await client.unsubscribe(topics.command_filter(self.robot))
        try:
            await self.reader.start(v5=self.v5)
        except BaseException:
            with contextlib.suppress(Exception):
                await client.__aexit__(None, None, None)
            raise
        self._receiver = asyncio.create_task(self._receive(self.reader),
                                             name=f"mqtt-commands-{self.robot}")

    def _check_session(self, client: LinkClient, away_s: float) -> None:
        """A v5 broker without our session, though we saw ourselves away for less than its
        expiry: commands it acknowledged but had not delivered, and results it had not
        delivered, are gone. Said once a time, with the causes it can be (``session_lost``)."""
        if self.v5 and not client.session_present and away_s < self.command_expiry_s:
            self.sessions_lost += 1
            log.warning("%s", session_lost(self.robot, away_s, self.command_expiry_s))

    async def _connect(self, client: LinkClient) -> None:
        """CONNECT within ``connect_timeout_s`` (TCP, TLS and CONNACK; DNS gets one more s)."""
        async with asyncio.timeout(self.connect_timeout_s + 1.0):
            await client.__aenter__()

    async def _session(self, client: LinkClient, stop: asyncio.Event) -> None:
        """Serve one connection; whatever ends it, ``offline`` is published first if it can be."""
        try:
            self.connected.set()
            async with asyncio.TaskGroup() as tg:
                tg.create_task(self._send_telemetry(client), name=f"mqtt-tel-{self.robot}")
                tg.create_task(self._send_reliable(client), name=f"mqtt-qos1-{self.robot}")
                tg.create_task(_raise_on(stop), name=f"mqtt-stop-{self.robot}")
        except* _Stopped:
            pass
        finally:
            self.connected.clear()
            if not stop.is_set():  # (stopping: the watch's last telemetry, ``_goodbye``'s)
                self.telemetry.clear()
            if stop.is_set():  # (a lost connection: they wait)
                await self.reader.stop()  # no command read any more: the read ones answered
                self._answer_waiting()
            if stop.is_set() or not client._disconnected.done():
                await self._goodbye(client)
            if stop.is_set():
                self._report_unsent()
            with contextlib.suppress(Exception):
                await client.__aexit__(None, None, None)
            lost = client._disconnected
            if lost.done() and not lost.cancelled():
                lost.exception()  # retrieved (``_receive`` read it here before): asyncio logs none

    async def _receive(self, reader: RobotCommands) -> None:
        """Commands as the reader read them, at most ``COMMANDS_PER_TURN`` in one loop turn: a
        flood (1 500 at once) handled in one turn held the telemetry, the frames and paho's
        keepalive back for seconds. None is taken while the QoS-1 buffer is half full: 1 000
        commands read during a stall, each answered at once (``expired``), filled it and pushed
        out answers owed (the connection, timed out by the stall, was coming back); they wait
        in the reader's queue instead (beyond it, answered ``rejected`` by the reader)."""
        while True:
            if len(self.reliable) > self.reliable_buffer // 2 - 2 * COMMANDS_PER_TURN:
                await asyncio.sleep(ROOM_POLL_S)  # their answers would push out others
                continue
            batch = reader.take(COMMANDS_PER_TURN)
            if not batch:
                reader.wake.clear()  # set again by the reader when its queue was empty
                batch = reader.take(COMMANDS_PER_TURN)
                if not batch:
                    await reader.wake.wait()
                    continue
            for message in batch:
                self._handle(message)
            await asyncio.sleep(0)  # the other tasks' turn

    def _handle(self, message: aiomqtt.Message) -> None:
        """Answer one message on ``cmd/<name>`` (not our ``cmd/result``, nor another topic)."""
        name = self._command_name(message)
        if name is not None and isinstance(message, Arrived):
            for leaf, payload in self._answer(name, message):
                self.publish(leaf, payload)

    def _answer_waiting(self) -> None:
        """Answer the commands the reader read but we did not handle yet: paho has
        acknowledged them to the broker, so the broker will not send them again. Their answers
        push no other out of the QoS-1 buffer (up to ``command_queue`` beyond its bound)."""
        self._owed = True
        try:
            while batch := self.reader.take(self.command_queue):
                for message in batch:
                    self._handle(message)
        finally:
            self._owed = False

    def _report_unsent(self) -> None:
        """The bridge stops: the command answers still in the QoS-1 buffer (the broker did not
        acknowledge them) are counted in ``answers_unsent`` and said in one line."""
        result = topics.topic(self.robot, topics.RESULT_LEAF)
        self.answers_unsent = sum(p.topic == result for p in self.reliable)
        if self.answers_unsent:
            log.warning("%s: %d command answers not delivered: the broker had not acknowledged "
                        "them when the bridge stopped", self.robot, self.answers_unsent)

    def _answer(self, name: str, message: Arrived) -> list[Publication]:
        if message.retain:  # kept by the broker from whenever: would run again each reconnect
            return self.on_command(name, _payload(message), "retained")
        if self.redeliveries.is_repeat(name, _payload(message), dup=message.dup):
            return []  # sent again after a reconnect: run and answered at its first delivery
        payload = _payload(message)
        expired = expired_by(message, payload, self.command_expiry_s)
        self.commands_expired += expired is not None
        return self.on_command(name, payload,
                               expired or fresh(message, payload, self.command_expiry_s))

    def _overflow(self, message: Arrived) -> None:
        """A command on this connection (a session kept from a bridge that read its commands
        here, before ``_start_reader`` unsubscribed): answered at once, not run."""
        name = self._command_name(message)
        if name is not None:
            self.commands_busy += 1
            for leaf, payload in self.on_command(name, _payload(message), "busy"):
                self.publish(leaf, payload)

    def _command_name(self, message: aiomqtt.Message) -> str | None:
        """Its name when ``message`` is one of this robot's commands (``topics.command_of``)."""
        robot, name = topics.command_of(message.topic.value) or ("", "result")
        return name if robot == self.robot and name != "result" else None

    def _refused(self, topic: str, reason: str) -> None:
        if not self.refused[topic]:
            log.warning("%s: the broker refused a publication on %s (%s)", self.robot, topic,
                        reason)
        self.refused[topic] += 1

    async def _send_telemetry(self, client: LinkClient) -> None:
        """QoS 0, in batches: awaits only the socket writes, never an acknowledgement. A batch
        goes to paho at once, as one queue entry of back-to-back PUBLISH packets
        (``LinkClient.publish_batch``), and the next waits until the socket took it, so while
        the socket is slow the telemetry waits in the bounded deque (drop-oldest), not in
        paho's unbounded queue. The batch is written at once, in one send
        (``LinkClient.flush``)."""
        while True:
            await self._telemetry_wake.wait()
            self._telemetry_wake.clear()
            while self.telemetry:
                batch = list(self.telemetry)
                self.telemetry.clear()
                last = client.publish_batch(batch)  # one entry of paho's queue
                client.flush()  # the batch in one socket write, now
                await client.written(last)

    async def _send_reliable(self, client: LinkClient) -> None:
        """QoS 1, up to ``inflight`` at once; each entry leaves the buffer once acknowledged."""
        while True:
            if not self.reliable:
                self._reliable_wake.clear()
                await self._reliable_wake.wait()
                continue
            await self._publish_window(client)

    async def _publish_window(self, client: LinkClient) -> None:
        """The oldest ``inflight`` QoS-1 entries at once; each leaves once acknowledged."""
        window = list(islice(self.reliable, self.inflight))
        await asyncio.gather(*(publish_once(client, p) for p in window))
        for p in window:
            with contextlib.suppress(ValueError):  # dropped meanwhile (buffer full)
                self.reliable.remove(p)

    async def _goodbye(self, client: LinkClient) -> None:
        """The telemetry still queued written, ``offline`` (superseding queued statuses; with
        ``last_status``'s fields: the watch's verdicts), then flush the QoS-1 buffer, if
        possible (within ``GOODBYE_S``, and ``GOODBYE_S_PER_ENTRY`` more for each entry)."""
        if self.telemetry:  # the telemetry queued at the stop (the watch's end), QoS 0
            with contextlib.suppress(Exception):
                client.publish_batch(list(self.telemetry))
                client.flush()
            self.telemetry.clear()
        status = topics.topic(self.robot, topics.STATUS_LEAF)
        self.reliable = deque(p for p in self.reliable if p.topic != status)
        last = {} if self.last_status is None else self.last_status()
        offline = topics.status_payload(self.robot, "offline",
                                        **{**last, "reason": "bridge stopped"})
        self.reliable.append(Outgoing(status, topics.dumps(offline), True))
        timeout_s = GOODBYE_S + GOODBYE_S_PER_ENTRY * len(self.reliable)
        with contextlib.suppress(Exception):
            async with asyncio.timeout(timeout_s):
                while self.reliable:
                    await self._publish_window(client)


def _payload(message: aiomqtt.Message) -> bytes:
    return bytes(message.payload) if isinstance(message.payload, bytes | bytearray) else b""


async def _raise_on(stop: asyncio.Event) -> None:
    await stop.wait()
    raise _Stopped


async def _sleep_or_stop(stop: asyncio.Event, delay_s: float) -> None:
    """Sleep ``delay_s`` seconds, or less when ``stop`` is set."""
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(stop.wait(), timeout=delay_s)
