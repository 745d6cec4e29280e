"""Every command the broker delivered before it died is read, not just the first (trial13).

Reproduced from outside with an installed wheel: ``odocan bridge`` on mosquitto (persistence,
``autosave_on_changes``), the bridge stopped with SIGSTOP, an operator publishes four QoS-1
commands (each PUBACKed: mosquitto delivers them into the bridge's socket), mosquitto is killed
with -9 and restarted, the bridge continued: one or two of the four were answered on
``cmd/result``, the others never. paho's ``loop_read`` reads ONE packet per readable event
(it ignores ``max_packets``); the bridge's next write into the dead connection ends it, and paho
closes the socket with the other commands unread. ``LinkClient`` reads every packet the socket
holds: all four answered, in two runs of the same reproduction.
"""

from __future__ import annotations

import asyncio
import socket

from odocan.host.mqtt.client import LinkClient


def _publish_qos1(topic: str, payload: bytes, packet_id: int) -> bytes:
    """One MQTT 3.1.1 PUBLISH at QoS 1, built by hand (independent of paho's and ours)."""
    name = topic.encode()
    body = len(name).to_bytes(2, "big") + name + packet_id.to_bytes(2, "big") + payload
    assert len(body) < 128  # one byte of remaining length
    return bytes([0x32, len(body)]) + body


async def _read_once(close_peer: bool) -> int:
    """Four QoS-1 commands waiting in the socket; paho told once that it is readable (as the
    event loop does): how many reached the client's queue."""
    client = LinkClient(hostname="127.0.0.1", on_refused=lambda *_: None,
                        on_overflow=lambda _: None, max_waiting=100, timeout=5.0)
    ours, broker = socket.socketpair()
    ours.setblocking(False)
    client._client._sock = ours  # as after a CONNACK
    client._connected.set_result(None)
    broker.sendall(b"".join(
        _publish_qos1("odocan/robot001/cmd/set_pose", b'{"id": %d}' % i, i) for i in range(1, 5)
    ))
    if close_peer:
        broker.close()  # the broker is gone: its bytes are still in our socket
    try:
        client._client.loop_read()
        return client._queue.qsize()
    finally:
        ours.close()
        if not close_peer:
            broker.close()
        await asyncio.sleep(0)  # paho's PUBACKs, written a loop turn later, find no socket
        lost = client._disconnected
        if lost.done() and not lost.cancelled():
            lost.exception()  # retrieved: the end of the connection is expected here

def test_one_readable_event_reads_every_command_the_socket_holds() -> None:
    assert asyncio.run(_read_once(close_peer=False)) == 4


def test_commands_before_a_dead_brokers_end_of_stream_are_all_read() -> None:
    assert asyncio.run(_read_once(close_peer=True)) == 4
