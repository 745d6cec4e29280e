"""One socket write per burst of publications, and the bridge's batches handled in slices.

The coalesced writes go through a real mosquitto to a real subscriber: every message must arrive
intact and in order, also when the socket takes only a few bytes at a time (partial writes).
"""

from __future__ import annotations

import asyncio
import json
from typing import Any

import can

from odocan.host.mqtt.bridge import Batch, Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import LOOPBACK, BrokerURL
from odocan.host.mqtt.client import CoalescedSend, LinkClient
from tests.conftest_mqtt import Mosquitto, client, mosquitto  # noqa: F401 (fixtures)
from tests.test_mqtt_bridge import GEOMETRY, PMIR, ROBOT, rig_ticks

TOPIC = "odocan/robot001/pose"
BURST = 30


def _link_client(url: BrokerURL, name: str) -> LinkClient:
    return LinkClient(**url.client_kwargs(), on_refused=lambda *_: None,
                      on_overflow=lambda _: None, max_waiting=10, identifier=name, timeout=5.0)


async def _burst_through(
    broker: Mosquitto, *, bytes_per_send: int | None = None
) -> tuple[list[dict[str, Any]], int]:
    """BURST QoS-0 publications of growing size in one burst; what the subscriber got, in
    order, and how many send syscalls the link made for them."""
    async with client(broker.url("robot001")) as sub, \
            _link_client(broker.url("bridge"), "coalesced-test") as link:
        await sub.subscribe(TOPIC, qos=0)
        await asyncio.sleep(0.2)  # the subscription is in place at the broker
        coalesced = link.coalesced
        if bytes_per_send is not None:  # a socket that takes a few bytes per send
            real = coalesced.send
            coalesced.send = lambda buf: real(buf[:bytes_per_send])
        writes0 = coalesced.writes
        last = None
        for i in range(BURST):
            last = link.publish_now(TOPIC, json.dumps({"i": i, "pad": "x" * (i * 7)}).encode())
        link.flush()
        writes = coalesced.writes - writes0
        assert last is not None
        await link.written(last)
        got: list[dict[str, Any]] = []
        async with asyncio.timeout(10):
            async for message in sub.messages:
                assert isinstance(message.payload, bytes)
                got.append(json.loads(message.payload))
                if len(got) == BURST:
                    break
    return got, writes


def test_a_burst_of_publications_is_one_socket_write_and_arrives_whole(
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    got, writes = asyncio.run(_burst_through(mosquitto))
    assert [p["i"] for p in got] == list(range(BURST))
    assert [len(p["pad"]) for p in got] == [i * 7 for i in range(BURST)]
    assert writes == 1  # paho alone: one send per packet (30)


def test_partial_writes_still_deliver_every_message_intact_in_order(
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    got, writes = asyncio.run(_burst_through(mosquitto, bytes_per_send=7))
    assert [p["i"] for p in got] == list(range(BURST))
    assert [len(p["pad"]) for p in got] == [i * 7 for i in range(BURST)]
    assert writes > BURST  # 7 bytes a time: many sends, each starting where the last stopped


def test_a_coalesced_write_stops_at_a_disconnect() -> None:
    """Bytes queued after a DISCONNECT are not written with it (paho closes the socket)."""
    import paho.mqtt.client as paho
    from paho.mqtt.enums import CallbackAPIVersion

    sent: list[bytes] = []
    mqtt = paho.Client(CallbackAPIVersion.VERSION2)
    coalesced = CoalescedSend(mqtt)

    def send(buf: bytes | bytearray) -> int:
        sent.append(bytes(buf))
        return len(buf)

    coalesced.send = send
    sock = object()
    mqtt._sock = sock  # type: ignore[assignment]
    for command, packet in ((0x30, b"BBBB"), (0xE0, b"\xe0\x00"), (0x30, b"CCCC")):  # PUBLISH,
        mqtt._out_packet.append({"command": command, "pos": 0, "packet": packet,  # DISCONNECT
                                 "mid": 0, "qos": 0, "to_process": len(packet), "info": None})
    assert coalesced(b"AA") == 2
    assert sent == [b"AABBBB\xe0\x00"]
    assert coalesced(b"BBBB") == 4
    assert coalesced(b"\xe0\x00") == 2
    assert len(sent) == 1
    for _ in range(3):  # paho pops each packet before it sends it
        mqtt._out_packet.popleft()
    assert coalesced(b"CCCC") == 4
    assert sent[-1] == b"CCCC"
    mqtt._sock = None  # nothing for paho to close


def test_a_large_batch_is_handled_in_slices_with_loop_turns_between() -> None:
    """A batch of many frames gives the loop a turn every ``slice_frames`` frames; stopping
    mid-batch still handles the rest (``_drain``); the telemetry is that of one whole pass."""
    frames: Batch = [(0, m) for tick in rig_ticks(1.0) for m in tick]
    assert len(frames) > 200
    url = BrokerURL(host=LOOPBACK, port=1)  # never connected: handling needs no broker

    def bridge(slice_frames: int) -> Bridge:
        bus = can.Bus(interface="virtual", channel="coalesced-slices")
        return Bridge([RobotEndpoint(ROBOT, bus, GEOMETRY, counter_bits=PMIR.counter_bits)],
                      config=BridgeConfig(broker=url, slice_frames=slice_frames))

    async def sliced() -> tuple[list[int], Bridge]:
        b = bridge(64)
        b.offer(frames)
        seen = []
        consume = asyncio.create_task(b._consume())
        for _ in range(3):
            await asyncio.sleep(0)
            seen.append(b.frames_in)
        consume.cancel()
        b._drain()
        return seen, b

    async def whole() -> Bridge:
        b = bridge(10**6)
        b.offer(frames)
        consume = asyncio.create_task(b._consume())
        await asyncio.sleep(0)
        consume.cancel()
        return b

    seen, in_slices = asyncio.run(sliced())
    at_once = asyncio.run(whole())
    assert seen == [64, 128, 192]  # one slice per loop turn
    assert in_slices.frames_in == at_once.frames_in == len(frames)
    telemetry = [b.robots[0].telemetry for b in (in_slices, at_once)]
    assert telemetry[0].frames == telemetry[1].frames
    assert telemetry[0].tracker.vs_reference == telemetry[1].tracker.vs_reference
    assert telemetry[0].tracker.vs_reference.samples > 0
    for b in (in_slices, at_once):
        b.robots[0].endpoint.bus.shutdown()


def test_aiomqtts_own_qos0_publish_still_completes(mosquitto: Mosquitto) -> None:  # noqa: F811
    """The links' writes skip paho's per-packet ``on_publish`` (``LinkClient.quiet_writes``); a
    QoS-0 publication made through aiomqtt's ``publish``, which waits for that callback, turns
    it back on and completes, as does a ``publish_now`` after it."""

    async def scenario() -> tuple[bool, bool]:
        async with _link_client(mosquitto.url("bridge"), "quiet-test") as link:
            quiet_before = link.quiet_writes
            for i in range(20):  # aiomqtt's QoS 0: awaits on_publish unless written at once
                link.publish_now(TOPIC, b"{}")  # queued ahead: its own publish waits
                async with asyncio.timeout(5):
                    await link.publish(TOPIC, json.dumps({"i": i}).encode(), qos=0)
            last = link.publish_now(TOPIC, b"{}")
            link.flush()
            async with asyncio.timeout(5):
                await link.written(last)
            return quiet_before, link.quiet_writes

    assert asyncio.run(scenario()) == (True, False)


def _refusing(real: Any) -> Any:
    """A socket send that refuses two calls of three (EAGAIN), then sends."""
    calls = [0]

    def send(buf: bytes | bytearray) -> int:
        calls[0] += 1
        if calls[0] % 3:
            raise BlockingIOError
        return int(real(buf))

    return send


def _count_writers(loop: asyncio.AbstractEventLoop, fd: int) -> list[int]:
    """Each ``add_writer`` for ``fd`` from now on, appended to the list returned."""
    writers: list[int] = []
    add_writer = loop.add_writer

    def counted(fileno: Any, callback: Any, *args: Any) -> None:
        if fileno == fd:
            writers.append(fileno)
        add_writer(fileno, callback, *args)

    setattr(loop, "add_writer", counted)  # noqa: B010 (this loop's own attribute)
    return writers


async def _bursts_and_a_qos1(broker: Mosquitto, busy: bool) -> tuple[int, list[int]]:
    """Three bursts of ten QoS-0 publications, each flushed at once, then one QoS-1 through
    aiomqtt; the loop writers registered for the link's socket, what the subscriber got."""
    async with client(broker.url("robot001")) as sub, \
            _link_client(broker.url("bridge"), "writer-test") as link:
        await sub.subscribe(TOPIC, qos=1)
        await asyncio.sleep(0.2)
        sock = link._client.socket()
        assert sock is not None
        writers = _count_writers(asyncio.get_running_loop(), sock.fileno())
        if busy:
            link.coalesced.send = _refusing(link.coalesced.send)
        for burst in range(3):
            last = None
            for i in range(10):
                last = link.publish_now(TOPIC, json.dumps({"i": burst * 10 + i}).encode())
            link.flush()
            assert last is not None
            async with asyncio.timeout(5):
                await link.written(last)
        async with asyncio.timeout(5):
            await link.publish(TOPIC, json.dumps({"i": 30}).encode(), qos=1)
        got: list[int] = []
        async with asyncio.timeout(10):
            async for message in sub.messages:
                assert isinstance(message.payload, bytes)
                got.append(json.loads(message.payload)["i"])
                if len(got) == 31:
                    break
        return len(writers), got


def test_a_burst_written_at_once_registers_no_loop_writer(
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    """A telemetry burst flushed at once, and a QoS-1 publication through aiomqtt, are written
    without the loop's writer (``add_writer``/``remove_writer`` per burst: two ``epoll_ctl``);
    a socket that is not ready (EAGAIN) still gets one, and every message arrives."""
    writers, got = asyncio.run(_bursts_and_a_qos1(mosquitto, busy=False))
    assert got == list(range(31))
    assert writers == 0  # before: one add_writer per burst and per QoS-1 publication
    writers, got = asyncio.run(_bursts_and_a_qos1(mosquitto, busy=True))
    assert got == list(range(31))
    assert writers > 0  # what the socket did not take waits for the loop's writer


def test_frames_a_hold_lets_go_at_once_are_judged_a_slice_at_a_time() -> None:
    """With a hold (framehold, the fleet's), the frames judged in one loop turn are bounded by
    ``slice_frames`` (+ what one ``slice_step`` of taken frames lets go), not by the frames
    taken: eight robots whose holds end on the same tick were judged in one callback (a 64-frame
    slice of the tick let ~240 go: ~6 ms of CPU before the fleet's next tick could run); every
    frame is still judged, and each robot's telemetry is what judging it whole makes."""
    robots, size = 8, 64
    ticks = rig_ticks(1.0)
    url = BrokerURL(host=LOOPBACK, port=1)  # never connected: handling needs no broker

    def bridge(slice_frames: int) -> tuple[Bridge, list[int]]:
        ends = [RobotEndpoint(f"{ROBOT}{i}", can.Bus(interface="virtual", channel=f"held-{i}"),
                              GEOMETRY, counter_bits=PMIR.counter_bits) for i in range(robots)]
        b = Bridge(ends, config=BridgeConfig(broker=url, slice_frames=slice_frames, hold_s=0.1))
        per_turn = [0]
        feed = b._feed

        def counted(batch: Batch) -> None:
            per_turn[-1] += len(batch)
            feed(batch)
        b._feed = counted  # type: ignore[method-assign]
        return b, per_turn

    async def run(slice_frames: int) -> tuple[Bridge, list[int]]:
        b, per_turn = bridge(slice_frames)
        for tick in ticks:  # every robot's frames of a tick, robot by robot, as a fleet's
            b.offer([(i, m) for i in range(robots) for m in tick])
        consume = asyncio.create_task(b._consume())
        while b.frames_in < robots * sum(map(len, ticks)):
            await asyncio.sleep(0)
            per_turn.append(0)
        consume.cancel()
        b._drain()
        return b, per_turn

    sliced, per_turn = asyncio.run(run(size))
    whole, _ = asyncio.run(run(10**6))
    # 8 frames taken span at most 4 robots (~32 frames held each): 192 judged at most; 288 before
    assert max(per_turn) <= size + 4 * 40, per_turn
    assert sum(per_turn) == whole.frames_in == robots * sum(map(len, ticks))
    for one, other in zip(sliced.robots, whole.robots, strict=True):
        assert one.telemetry.frames == other.telemetry.frames
        assert one.telemetry.tracker.vs_reference == other.telemetry.tracker.vs_reference
    for b in (sliced, whole):
        for robot in b.robots:
            robot.endpoint.bus.shutdown()
