"""The paho-level MQTT client of ``host.mqtt.link.RobotLink``: aiomqtt's client, keeping what
aiomqtt drops.

* PUBACK reason codes of QoS-1 publications (a broker's ACL refusal is seen per topic);
* when paho read each message and its MQTT v5 message expiry (commands expire);
* the CONNACK's session-present flag (a broker that lost our session is noticed);
* a connection the broker closes before its CONNACK (amqtt, to some v5 CONNECTs) as an error
  instead of a wait for ever;
* QoS-0 telemetry straight into paho's queue, a robot's burst as one queue entry of PUBLISH
  packets built here (``publish_batch``; ``publish_now`` for one message), and a wait for its
  socket write (``written``), instead of aiomqtt's coroutine, task and event per message and
  paho's packet, info and write bookkeeping per message;
* one socket write for every packet queued (``CoalescedSend``; paho writes each packet with a send
  of its own, ~1.4 syscalls per publication, each a wake-up of the broker), and a batch written at
  once from the event loop (``flush``) instead of a writer callback a loop turn later, without
  paho's per-packet ``on_publish`` (``quiet_writes``: its ``ReasonCode`` and ``Properties`` per
  QoS-0 packet; ``written`` reads the packets' infos instead);
* no loop writer per burst: what paho queues from the loop's thread is written by that flush or
  a loop turn later (``_write_soon``); the loop's writer is registered only for what the socket
  does not take at once.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import aiomqtt
import paho.mqtt.client as paho
from paho.mqtt.enums import MQTTErrorCode
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

MAX_WRITE_BYTES = 64 * 1024  # one coalesced socket write at most (a loopback socket's buffer)
MAX_READ_PACKETS = 1024  # packets one readable event reads at most (then the loop turns)
DISCONNECT = PacketTypes.DISCONNECT << 4  # the packet-type nibble of paho's ``command``


def persistent_session(v5: bool, expiry_s: float) -> dict[str, Any]:
    """The CONNECT options of a session the broker keeps while the client is away: MQTT v5
    ``clean_start`` off with a session expiry of ``expiry_s`` (at least 1 s), 3.1.1
    ``clean_session`` off (kept until the client cleans it)."""
    if not v5:
        return {"protocol": aiomqtt.ProtocolVersion.V311, "clean_session": False}
    props = Properties(PacketTypes.CONNECT)  # type: ignore[no-untyped-call]
    props.SessionExpiryInterval = max(1, math.ceil(expiry_s))
    return {"protocol": aiomqtt.ProtocolVersion.V5, "clean_start": False, "properties": props}


class CoalescedSend:
    """paho's ``_sock_send`` (one packet's bytes per call) made to write, in one send, the packet
    it is given and the ones queued behind it (``_out_packet``, up to ``MAX_WRITE_BYTES``, never
    past a DISCONNECT). paho's write loop goes on packet by packet: the following calls are
    answered from the bytes already written (``credit``) without a syscall, so paho's own
    bookkeeping (a packet written, its ``on_publish``, a partial write) is unchanged."""

    def __init__(self, client: paho.Client) -> None:
        self.client = client
        self.send: Callable[[bytes | bytearray], int] = client._sock_send
        self.credit = 0  # bytes of the queued packets already written
        self.sock: object = None  # the socket the credit belongs to
        self.writes = 0  # send syscalls (bench figures)

    def __call__(self, buf: bytes | bytearray) -> int:
        client = self.client
        if self.credit and client._sock is self.sock:
            taken = min(self.credit, len(buf))
            self.credit -= taken
            return taken
        self.credit = 0
        parts: list[bytes | bytearray | memoryview] = [buf]
        size = len(buf)
        for packet in client._out_packet:
            if size >= MAX_WRITE_BYTES:
                break
            rest = memoryview(packet["packet"])[packet["pos"]:]
            parts.append(rest)
            size += len(rest)
            if packet["command"] & 0xF0 == DISCONNECT:
                break
        self.writes += 1
        if len(parts) == 1:
            return self.send(buf)
        sent = self.send(b"".join(parts))
        if sent > len(buf):
            self.credit, self.sock = sent - len(buf), client._sock
            return len(buf)
        return sent


MAX_PACKET_BYTES = 268_435_455  # MQTT's largest remaining length (four bytes of varint)


def publish_packets(
    messages: Sequence[tuple[str, bytes]], *, v5: bool, prefixes: dict[str, bytes] | None = None
) -> bytearray:
    """The QoS-0 PUBLISH packets (no retain, no DUP; MQTT v5: no properties) of ``messages``
    back to back, as paho's ``_send_publish`` builds each: the fixed header ``0x30``, the
    remaining length as a varint (7 bits a byte, least significant first), the topic as a UTF-8
    string with its 16-bit length, in v5 a zero property length, then the body. ``prefixes``
    caches each topic's encoded part. A topic with a wildcard, empty or over 65 535 bytes, or
    a packet over MQTT's limit is a ``ValueError``, as in paho."""
    cache: dict[str, bytes] = prefixes if prefixes is not None else {}
    packet = bytearray()
    for topic, body in messages:
        prefix = cache.get(topic)
        if prefix is None:
            prefix = cache[topic] = _topic_prefix(topic, v5)
        size = len(prefix) + len(body)
        if size > MAX_PACKET_BYTES:
            raise ValueError("Payload too large.")
        packet.append(0x30)
        while size > 0x7F:
            packet.append(size & 0x7F | 0x80)
            size >>= 7
        packet.append(size)
        packet += prefix
        packet += body
    return packet


def _topic_prefix(topic: str, v5: bool) -> bytes:
    """A PUBLISH packet's variable header without a packet id (QoS 0): the topic's length and
    bytes, and in v5 an empty property list."""
    encoded = topic.encode()
    if b"+" in encoded or b"#" in encoded:
        raise ValueError(f"publish topic {topic!r} cannot contain wildcards")
    if not 0 < len(encoded) <= 0xFFFF:
        raise ValueError(f"publish topic of {len(encoded)} bytes: 1 to 65535")
    return len(encoded).to_bytes(2, "big") + encoded + (b"\x00" if v5 else b"")


class Arrived(aiomqtt.Message):
    """aiomqtt's message plus when paho read it (``time.monotonic`` s) and its expiry (s)."""

    arrival_s: float = 0.0
    expiry_s: float | None = None
    dup: bool = False  # the broker's DUP flag: a QoS-1 message sent again


class ClosedBeforeConnack(aiomqtt.MqttError):
    """The broker closed the connection without a CONNACK (amqtt does so to some v5 CONNECTs)."""


class LinkClient(aiomqtt.Client):
    """aiomqtt's client, keeping what it drops: PUBACK reason codes and arrival times.

    ``on_refused(topic, reason)`` is called for each QoS-1 publication the broker refused;
    ``on_overflow(message)`` for a message that finds ``max_waiting`` messages already queued.
    """

    def __init__(
        self,
        *,
        on_refused: Callable[[str, str], None],
        on_overflow: Callable[[Arrived], None],
        max_waiting: int,
        **kwargs: Any,
    ) -> None:
        super().__init__(**kwargs)
        self._on_refused, self._on_overflow = on_refused, on_overflow
        self._max_waiting = max_waiting
        self._qos1_topics: dict[int, str] = {}
        # QoS-0 mid -> its info and a future resolved once the socket took it (``written``)
        self._written: dict[int, tuple[paho.MQTTMessageInfo, asyncio.Future[None]]] = {}
        # flush without paho's on_publish (``flush``); off for good once aiomqtt publishes a
        # QoS-0 message itself (its ``publish`` waits for that callback)
        self.quiet_writes = True
        self.session_present = False  # the CONNACK's flag: the broker still had our session
        paho_publish = self._client.publish

        def publish(topic: str, payload: Any = None, qos: int = 0, retain: bool = False,
                    properties: Properties | None = None) -> paho.MQTTMessageInfo:
            info = paho_publish(topic, payload, qos, retain, properties)
            if qos > 0:
                self._qos1_topics[info.mid] = topic
            else:
                self.quiet_writes = False
            return info

        setattr(self._client, "publish", publish)  # noqa: B010 (an instance's own attribute)
        self.coalesced = CoalescedSend(self._client)
        setattr(self._client, "_sock_send", self.coalesced)  # noqa: B010
        setattr(self._client, "loop_read", self._read_all)  # noqa: B010
        self._loop_thread = threading.get_ident()  # made in the event loop's thread
        self._write_soon_due = False  # a ``_write_soon`` is scheduled
        self._writer_on = False  # the loop's writer is registered for the socket
        self._topic_prefixes: dict[str, bytes] = {}  # ``publish_packets``' cache per topic

    def _read_all(self, max_packets: int = 1) -> MQTTErrorCode:
        """Every packet the socket holds (up to ``MAX_READ_PACKETS``), not paho's one per
        readable event (its ``loop_read`` ignores ``max_packets``): commands a broker delivered
        before it died are all read before the next write. A write into the dead connection
        ends it, and paho closes the socket with whatever it still held unread: three of four
        acknowledged commands were never answered after mosquitto was killed with -9."""
        client = self._client
        for _ in range(MAX_READ_PACKETS):
            if client._sock is None:
                return MQTTErrorCode.MQTT_ERR_NO_CONN
            rc = client._packet_read()
            if rc > 0:
                return client._loop_rc_handle(rc)
            if rc == MQTTErrorCode.MQTT_ERR_AGAIN:
                break
        return MQTTErrorCode.MQTT_ERR_SUCCESS

    def flush(self) -> None:
        """Write what paho has queued now, from the event loop (one coalesced send), instead of
        a loop turn later from the writer callback; whatever the socket does not take now is
        still written by that callback. An error is the connection's end, as in aiomqtt.

        While ``quiet_writes``, paho's ``on_publish`` is off for the write: paho calls it for
        every QoS-0 packet written (a QoS-1 one's comes with its PUBACK, read elsewhere), with a
        ``ReasonCode`` and a ``Properties`` built for each (a tenth of a fleet worker's MQTT
        CPU), and the only QoS-0 packets are ``publish_batch``'s, whose writes ``written``
        learns from their infos here instead."""
        client = self._client
        quiet = self.quiet_writes
        on_publish = client._on_publish
        if quiet:
            client._on_publish = None
        try:
            client.loop_write()
        except Exception as exc:  # aiomqtt's own writer callback does the same
            if not self._disconnected.done():
                self._disconnected.set_exception(exc)
        finally:
            if quiet:
                client._on_publish = on_publish
                for info, done in self._written.values():
                    if info.is_published() and not done.done():
                        done.set_result(None)

    def _on_socket_register_write(self, client: paho.Client, userdata: Any,
                                  sock: Any) -> None:
        """paho queued a packet and wants the socket written. From the loop's own thread the
        packet is written by the ``flush`` that follows (the telemetry sender's) or, a loop turn
        later, by ``_write_soon``; a writer is registered with the loop only when the socket
        did not take it all. aiomqtt's writer (``add_writer`` here, ``remove_writer`` once the
        queue is written: two ``epoll_ctl`` and the selector's bookkeeping per burst) was ~3 %
        of a fleet worker's CPU. From another thread: aiomqtt's registration."""
        if threading.get_ident() != self._loop_thread:
            self._writer_on = True
            super()._on_socket_register_write(client, userdata, sock)
        elif not self._write_soon_due:
            self._write_soon_due = True
            self._loop.call_soon(self._write_soon)

    def _write_soon(self) -> None:
        """What paho still has queued, written now; the loop's writer only for what the socket
        does not take (``flush`` again when it is writable)."""
        self._write_soon_due = False
        client = self._client
        if self._writer_on or not client.want_write():
            return
        self.flush()
        sock = client.socket()
        if client.want_write() and sock is not None and not self._disconnected.done():
            self._writer_on = True
            self._loop.add_writer(sock.fileno(), self.flush)

    def _on_socket_unregister_write(self, client: paho.Client, userdata: Any,
                                    sock: Any) -> None:
        """paho's queue is written: the loop's writer off, if one was registered."""
        if self._writer_on:
            self._writer_on = False
            super()._on_socket_unregister_write(client, userdata, sock)

    def publish_now(self, topic: str, body: bytes) -> paho.MQTTMessageInfo:
        """One QoS-0 message straight into paho's outgoing queue (``publish_batch`` of one: no
        coroutine, no task, no event per message, as aiomqtt's ``publish`` makes them);
        ``MqttCodeError`` when the connection is gone. ``written(info)`` waits until the socket
        took it."""
        return self.publish_batch(((topic, body),))

    def publish_batch(self, messages: Sequence[tuple[str, bytes]]) -> paho.MQTTMessageInfo:
        """QoS-0 ``(topic, body)`` messages, in order, as ONE entry of paho's outgoing queue:
        their PUBLISH packets built here back to back (``publish_packets``: the bytes paho's
        ``publish`` builds for each) under one message id and one ``MQTTMessageInfo``, instead
        of paho's per-message topic checks, packet, queue entry, info (a ``Condition`` each)
        and write bookkeeping: a robot's telemetry of one period is one publication for paho.
        ``MqttCodeError`` when paho has no connection; ``written(info)`` waits for the socket."""
        client = self._client
        if client._sock is None:
            raise aiomqtt.MqttCodeError(paho.MQTT_ERR_NO_CONN, "Could not publish message")
        packet = publish_packets(messages, v5=client._protocol == paho.MQTTv5,
                                 prefixes=self._topic_prefixes)
        info = paho.MQTTMessageInfo(client._mid_generate())
        logger = client._logger
        if logger is not None and logger.isEnabledFor(logging.DEBUG):  # paho's line per message
            for topic, body in messages:
                logger.debug("Sending PUBLISH (d0, q0, r0, m%d), '%s', ... (%d bytes) [batch]",
                             info.mid, topic, len(body))
        client._packet_queue(paho.PUBLISH, packet, info.mid, 0, info)
        return info

    def publish_reliable(self, topic: str, body: bytes, retain: bool) -> paho.MQTTMessageInfo:
        """One QoS-1 message into paho's queue (as aiomqtt's ``publish`` puts it there, without
        its wait): ``acknowledged(info)`` waits for its PUBACK, and can be awaited again after a
        cancelled wait (the message is not sent twice); ``MqttCodeError`` when paho refuses."""
        info = self._client.publish(topic, body, 1, retain)
        if info.rc != paho.MQTT_ERR_SUCCESS:
            raise aiomqtt.MqttCodeError(info.rc, "Could not publish message")
        return info

    async def acknowledged(self, info: paho.MQTTMessageInfo) -> None:
        """Wait for the PUBACK of the QoS-1 publication ``info`` (``written``: paho calls
        ``on_publish`` when it reads the PUBACK)."""
        await self.written(info)

    async def written(self, info: paho.MQTTMessageInfo) -> None:
        """Wait until paho wrote the QoS-0 publication ``info`` to the socket (and so every one
        queued before it: paho writes in order)."""
        if info.is_published():
            return
        done = asyncio.get_running_loop().create_future()
        self._written[info.mid] = (info, done)
        try:  # not asyncio.wait_for: in 3.11 it can swallow a cancellation that meets the result
            async with asyncio.timeout(self.timeout):
                await done
        except TimeoutError:
            raise aiomqtt.MqttError("Operation timed out") from None
        finally:
            self._written.pop(info.mid, None)

    def _on_publish(self, client: paho.Client, userdata: Any, mid: int,
                    reason_code: Any, properties: Any) -> None:
        written = self._written.pop(mid, None)
        if written is not None and not written[1].done():
            written[1].set_result(None)
        topic = self._qos1_topics.pop(mid, None)
        if topic is not None and getattr(reason_code, "is_failure", False):
            self._on_refused(topic, str(reason_code))
        super()._on_publish(client, userdata, mid, reason_code, properties)

    def _on_connect(self, client: paho.Client, userdata: Any, flags: Any,
                    reason_code: Any, properties: Any = None) -> None:
        self.session_present = bool(getattr(flags, "session_present", False))
        super()._on_connect(client, userdata, flags, reason_code, properties)

    def _on_disconnect(self, client: paho.Client, userdata: Any, flags: Any,
                       reason_code: Any, properties: Any = None) -> None:
        if not self._connected.done():  # aiomqtt would wait for a CONNACK that never comes
            self._connected.set_exception(ClosedBeforeConnack(
                f"the broker closed the connection before its CONNACK ({reason_code})"))
            return
        super()._on_disconnect(client, userdata, flags, reason_code, properties)

    def _on_message(self, client: paho.Client, userdata: Any,
                    message: paho.MQTTMessage) -> None:
        arrived = arrived_of(message)
        if self._queue.qsize() >= self._max_waiting:
            self._on_overflow(arrived)
            return
        self._queue.put_nowait(arrived)


def arrived_of(message: paho.MQTTMessage) -> Arrived:
    """``message`` as paho read it, stamped now (``arrival_s``), with its DUP flag and MQTT v5
    expiry."""
    arrived = Arrived._from_paho_message(message)
    arrived.arrival_s = time.monotonic()
    arrived.dup = bool(message.dup)
    expiry = getattr(message.properties, "MessageExpiryInterval", None)
    arrived.expiry_s = float(expiry) if expiry is not None else None
    return arrived
