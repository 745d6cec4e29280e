"""A robot's telemetry of one period as one entry of paho's queue (``LinkClient.publish_batch``).

The packets are built by the link, not by paho: their bytes must be paho's own, byte for byte
(checked against paho's ``_send_publish`` in MQTT 3.1.1 and v5, across every width of the
remaining-length varint), and a batch must reach a real subscriber through a real mosquitto
whole and in order, also when the socket takes a few bytes at a time.
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

from odocan.host.mqtt.client import publish_packets
from tests.conftest_mqtt import Mosquitto, client, mosquitto  # noqa: F401 (fixtures)
from tests.test_mqtt_coalesced import TOPIC, _link_client

# bodies whose packets' remaining length crosses each varint width (1, 2, 3 bytes)
SIZES = (0, 1, 90, 127 - 24, 128 - 24, 500, 16383 - 24, 16384 - 24, 70000)


class _Socket:
    """Enough of a socket for paho to build and queue packets (nothing is written)."""

    def send(self, buf: bytes) -> int:
        return 0

    def fileno(self) -> int:
        return -1

    def close(self) -> None:
        pass


def _paho_bytes(protocol: MQTTProtocolVersion, messages: list[tuple[str, bytes]]) -> bytes:
    """The bytes paho's own ``publish`` queues for ``messages`` at QoS 0."""
    mqtt = paho.Client(CallbackAPIVersion.VERSION2, protocol=protocol)
    queued: list[bytes] = []

    def queue(command: int, packet: bytes, mid: int, qos: int, info: Any = None) -> int:
        queued.append(bytes(packet))
        return 0

    mqtt._sock = _Socket()  # type: ignore[assignment]
    setattr(mqtt, "_packet_queue", queue)  # noqa: B010 (this client's own attribute)
    for topic, body in messages:
        assert mqtt.publish(topic, body, 0).rc == paho.MQTT_ERR_SUCCESS
    mqtt._sock = None
    return b"".join(queued)


@pytest.mark.parametrize("protocol", [paho.MQTTv311, paho.MQTTv5])
def test_the_batch_is_paho_s_own_packets_byte_for_byte(
    protocol: MQTTProtocolVersion,
) -> None:
    topics = ["odocan/robot001/pose", "odocan/r/error", "odocan/" + "x" * 300 + "/truth"]
    messages = [(topics[i % len(topics)], bytes([i % 251]) * size)
                for i, size in enumerate(SIZES)]
    cache: dict[str, bytes] = {}
    v5 = protocol == paho.MQTTv5
    assert bytes(publish_packets(messages, v5=v5, prefixes=cache)) == _paho_bytes(protocol,
                                                                                   messages)
    assert bytes(publish_packets(messages, v5=v5, prefixes=cache)) == _paho_bytes(protocol,
                                                                                   messages)
    assert set(cache) == {t for t, _ in messages}


@pytest.mark.parametrize("topic", ["odocan/+/pose", "odocan/#", "", "x" * 65536])
def test_a_topic_paho_refuses_is_refused(topic: str) -> None:
    with pytest.raises(ValueError, match="publish topic"):
        publish_packets([(topic, b"{}")], v5=True)


async def _batch_through(broker: Mosquitto, bytes_per_send: int | None) -> list[dict[str, Any]]:
    """Two batches of 15 publications of growing size; what the subscriber got, in order."""
    async with client(broker.url("robot001")) as sub, \
            _link_client(broker.url("bridge"), "batch-test") as link:
        await sub.subscribe(TOPIC, qos=0)
        await asyncio.sleep(0.2)  # the subscription is in place at the broker
        if bytes_per_send is not None:  # a socket that takes a few bytes per send
            real = link.coalesced.send
            link.coalesced.send = lambda buf: real(buf[:bytes_per_send])
        for first in (0, 15):
            last = link.publish_batch(
                [(TOPIC, json.dumps({"i": i, "pad": "x" * (i * 7)}).encode())
                 for i in range(first, first + 15)])
            link.flush()
            async with asyncio.timeout(5):
                await link.written(last)
        got: list[dict[str, Any]] = []
        async with asyncio.timeout(10):
            async for message in sub.messages:
                assert isinstance(message.payload, bytes)
                got.append(json.loads(message.payload))
                if len(got) == 30:
                    break
    return got


@pytest.mark.parametrize("bytes_per_send", [None, 7])
def test_a_batch_arrives_whole_and_in_order(
    mosquitto: Mosquitto, bytes_per_send: int | None,  # noqa: F811
) -> None:
    got = asyncio.run(_batch_through(mosquitto, bytes_per_send))
    assert [p["i"] for p in got] == list(range(30))
    assert [len(p["pad"]) for p in got] == [i * 7 for i in range(30)]
