"""A ``status`` written to the broker's socket, never acknowledged, when the broker dies (#13).

Under load, ``test_no_qos1_message_lost_across_a_broker_restart`` once missed one status it could
not account for; it was its own subscriber's (``StatusSeqs``), but that test cannot choose the
instant the broker stops, so it never covered the one status in flight then: a link that forgot
the entries written on the dead connection passed it. Here mosquitto is frozen (SIGSTOP: its
kernel still takes our bytes, it reads none, acknowledges none), the link writes a status, and
mosquitto is killed (-9: it never read it). That status must reach the broker after the
reconnect, or, superseded by one queued while offline, be counted in ``status_superseded``.
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Callable

import pytest

from odocan.host.mqtt import topics
from odocan.host.mqtt.link import RobotLink
from tests.conftest_mqtt import Mosquitto, client, collect, mosquitto  # noqa: F401

ROBOT = "robot001"


async def _until(condition: Callable[[], bool], timeout_s: float = 20.0) -> None:
    """Poll ``condition()`` (an event the link has no hook for) until true."""
    async with asyncio.timeout(timeout_s):
        while not condition():
            await asyncio.sleep(0.01)


def _written(link: RobotLink) -> bool:
    """The oldest queued QoS-1 entry is in the socket: paho took it and wrote all it had."""
    if not link.reliable or link.reliable[0].sent_on is None:
        return False
    return not link.reliable[0].sent_on._client._out_packet  # type: ignore[attr-defined]


def _kill(broker: Mosquitto) -> None:
    assert broker.proc is not None
    broker.proc.kill()  # SIGKILL works on a stopped process; the bytes it held unread are gone
    broker.proc.wait(timeout=10)
    broker.proc = None


@pytest.mark.parametrize("offline_status", [False, True])
def test_a_status_in_flight_when_the_broker_dies_is_delivered_or_counted(
    mosquitto: Mosquitto, offline_status: bool  # noqa: F811
) -> None:
    async def scenario() -> tuple[list[int], RobotLink]:
        url = mosquitto.url("bridge")
        link = RobotLink(robot=ROBOT, broker=url, on_command=lambda n, p, v: [],
                         client_prefix="test-unacked-", connect_timeout_s=2.0)
        stop = asyncio.Event()
        task = asyncio.create_task(link.run(stop=stop))
        try:
            await _until(link.connected.is_set)
            assert mosquitto.proc is not None
            mosquitto.proc.send_signal(signal.SIGSTOP)
            link.publish(topics.STATUS_LEAF, {"state": "online", "seq": 1})
            await _until(lambda: _written(link))  # in the socket; no PUBACK can come
            _kill(mosquitto)
            await _until(lambda: not link.connected.is_set())  # the ack wait timed out
            if offline_status:
                link.publish(topics.STATUS_LEAF, {"state": "online", "seq": 2})
            mosquitto.start()
            await _until(lambda: link.connects >= 2 and not link.reliable)  # all acknowledged
            async with client(url) as sub:  # the retained status: the latest the broker took
                await sub.subscribe(topics.topic(ROBOT, topics.STATUS_LEAF), qos=1)
                got = await collect(sub, lambda g: True)
        finally:
            stop.set()
            await asyncio.wait_for(task, 20)
        return [payload["seq"] for _, payload in got], link

    seqs, link = asyncio.run(scenario())
    assert seqs == ([2] if offline_status else [1])
    assert link.status_superseded == (1 if offline_status else 0)
