"""One hostile MQTT message must not stop a fleet's live views (house rule 6).

Anyone who may publish under ``odocan/<robot>/`` (a third-party bridge, a test tool, a broker
without ACLs) can send a pose of ``{"x_m": 1e400-as-an-integer}`` or ``{"x_m": "1"}``. JSON
parses both. ``odocan fleet --foxglove``'s follower used to die on the first (``float()`` of a
400-digit integer raised OverflowError out of its message loop: Foxglove went silent for the
rest of the run, with a thread traceback on stderr). The fleet table:
tests/test_fleet_table_hostile.py.
"""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any

import aiomqtt

from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.foxglove_fleet import FleetFoxglove, FollowerThread
from odocan.host.mqtt.shards import embedded_broker

HUGE = b"1" + b"0" * 400  # a valid JSON integer beyond every float
GOOD_POSE = b'{"x_m": 1.0, "y_m": 2.0, "heading_rad": 0.5}'
HOSTILE_POSES = (
    b'{"x_m": ' + HUGE + b', "y_m": 0, "heading_rad": 0}',
    b'{"x_m": 0, "y_m": -' + HUGE + b', "heading_rad": 0}',
)
LAST_X_M = 3.0  # the good pose sent after the subscription was seen in place
BOUND_S = 60.0  # each wait for a pose served (was 20 s: a loaded machine's broker and thread)


def test_foxglove_skips_a_pose_beyond_every_float() -> None:
    live = FleetFoxglove(port=0, robots=["robot001"])
    try:
        for payload in HOSTILE_POSES:
            live._on_mqtt("odocan/robot001/pose", payload)
        live._on_mqtt("odocan/robot001/error",
                      b'{"pose_vs_reference": {"dpos_m": ' + HUGE + b', "dheading_rad": 0}}')
        assert live.published == 0
        live._on_mqtt("odocan/robot001/pose", GOOD_POSE)
        assert live.published == 2  # the pose and its transform
    finally:
        live.close()


async def _publish(url: BrokerURL, messages: list[tuple[str, bytes]]) -> None:
    async with aiomqtt.Client(**url.client_kwargs(), identifier="test-hostile") as client:
        for topic, payload in messages:
            await client.publish(topic, payload, qos=1)


class _Served(FleetFoxglove):
    """The live view, keeping the x of every pose it served (on its onboard pose channel)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.served_x: list[float] = []

    def _log(self, topic: str, t_ns: int, message: dict[str, Any]) -> None:
        super()._log(topic, t_ns, message)
        if topic.endswith("/pose/onboard"):
            self.served_x.append(message["pose"]["position"]["x"])


def _good_pose(x_m: float) -> bytes:
    return json.dumps({"x_m": x_m, "y_m": 2.0, "heading_rad": 0.5}).encode()


def test_the_follower_outlives_a_hostile_message_on_a_real_broker() -> None:
    """Hostile poses, then a good one, until the follower served a good one (its subscription
    in place); then hostile poses and a good one of its own x: that one is served. (Before: a
    count of published messages, read while the follower thread was between a pose and its
    transform or still serving an earlier round, could be one or two off.)"""
    live = _Served(port=0, robots=["robot001"])
    try:
        with embedded_broker(None) as url:
            follower = FollowerThread(live, url)
            follower.start()
            try:
                messages = [("odocan/robot001/pose", p) for p in HOSTILE_POSES]
                deadline = time.monotonic() + BOUND_S
                while not live.served_x and time.monotonic() < deadline:
                    # the subscription may not be in place yet: send until a good pose counts
                    asyncio.run(_publish(url, [*messages, ("odocan/robot001/pose",
                                                           _good_pose(1.0))]))
                    time.sleep(0.3)
                assert live.served_x, "no pose served"
                asyncio.run(_publish(url, [*messages, ("odocan/robot001/pose",
                                                       _good_pose(LAST_X_M))]))
                deadline = time.monotonic() + BOUND_S
                while LAST_X_M not in live.served_x and time.monotonic() < deadline:
                    time.sleep(0.1)
                assert LAST_X_M in live.served_x, "the follower stopped after a hostile pose"
                assert set(live.served_x) == {1.0, LAST_X_M}  # no hostile pose served
                assert live.skipped == 0  # each was refused as malformed, none raised
            finally:
                follower.stop()
    finally:
        live.close()
