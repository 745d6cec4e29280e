"""Live Foxglove of a whole fleet: its MQTT telemetry served as the Foxglove WebSocket protocol.

``odocan fleet --foxglove [PORT]``: a ``FleetFoxglove`` subscribes to ``odocan/+/#`` on the
fleet's broker (what ``odocan bridge`` publishes for every robot: ``host.mqtt.topics``) and
republishes each robot under its own name, with the schemas of ``odocan run --foxglove``
(``host.io.export``):

* ``/<robot>/pose/onboard``, ``/<robot>/pose/reference``, ``/<robot>/pose/truth``
  (``foxglove.PoseInFrame`` in ``odom``);
* ``/tf`` (``foxglove.FrameTransform``): the transform tree, one frame per robot and pose,
  ``odom`` -> ``<robot>/base_link``, ``<robot>/reference_link``, ``<robot>/truth_link``;
* ``/<robot>/errors/reference`` (``odocan.PoseError``: on-board minus float64 reference at the
  same encoder frame) and ``/<robot>/errors/reference_vs_truth`` (the reference minus the truth
  sampled at the same encoder frame: the drift that ``--errors`` makes).

The host learns the poses only from the bus, through the bridge, as the MQTT view does. Log
times are the wall clock at arrival (the robots' own bus clocks do not share an origin). Robots
named at construction get their channels at once (a client sees them in its first advertise);
others get theirs when their first message arrives.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from typing import Any

import aiomqtt
import foxglove

from odocan.host.io.export import (
    POSE_TOPICS,
    frame_transform,
    json_schema,
    pose_error,
    pose_in_frame,
)
from odocan.host.jsonutil import real
from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.report.foxglove_options import Served, start_server

RECONNECT_S = 1.0  # after the broker went away
_POSE_LEAVES = {"pose": "onboard", "reference": "reference", "truth": "truth"}
_ERROR_TOPICS = {"pose_vs_reference": "errors/reference",
                 "reference_vs_truth": "errors/reference_vs_truth"}


class FleetFoxglove(Served):
    """A Foxglove server of every robot's poses, transforms and errors (module docstring).

    Args:
        port: the TCP port on 127.0.0.1 (0: any free one, see ``port``).
        robots: names whose channels are opened at once.
    """

    def __init__(self, *, port: int, robots: Iterable[str] = ()) -> None:
        self._context = foxglove.Context()
        self._channels: dict[str, foxglove.Channel] = {}
        self.published = 0
        self.skipped = 0  # MQTT messages that raised while being served (none expected)
        self._lock = threading.Lock()
        self._channel("/tf", "foxglove.FrameTransform")
        for name in robots:
            self._open_robot(name)
        self.server = start_server("odocan fleet", port, context=self._context)

    def _channel(self, topic: str, schema_name: str) -> None:
        self._channels[topic] = foxglove.Channel(
            topic,
            schema=foxglove.Schema(
                name=schema_name, encoding="jsonschema", data=json_schema(schema_name)
            ),
            message_encoding="json",
            context=self._context,
        )

    def _open_robot(self, robot: str) -> None:
        for prefix in _POSE_LEAVES.values():
            self._channel(f"/{robot}{POSE_TOPICS[prefix][0]}", "foxglove.PoseInFrame")
        for topic in _ERROR_TOPICS.values():
            self._channel(f"/{robot}/{topic}", "odocan.PoseError")

    def on_telemetry(self, robot: str, leaf: str, payload: dict[str, Any]) -> None:
        """Publish one MQTT telemetry message of ``robot`` (``leaf``: pose, reference, truth,
        error; others are ignored). Malformed payloads are skipped, never raised."""
        t_ns = time.time_ns()
        with self._lock:
            if f"/{robot}/pose/onboard" not in self._channels:
                self._open_robot(robot)
            if leaf in _POSE_LEAVES:
                self._publish_pose(robot, _POSE_LEAVES[leaf], payload, t_ns)
            elif leaf == "error":
                self._publish_errors(robot, payload, t_ns)

    def _publish_pose(self, robot: str, prefix: str, payload: dict[str, Any], t_ns: int) -> None:
        pose = _numbers(payload, "x_m", "y_m", "heading_rad")
        if pose is None:
            return
        topic, child = POSE_TOPICS[prefix]
        self._log(f"/{robot}{topic}", t_ns, pose_in_frame(t_ns, *pose))
        self._log("/tf", t_ns, frame_transform(t_ns, f"{robot}/{child}", *pose))

    def _publish_errors(self, robot: str, payload: dict[str, Any], t_ns: int) -> None:
        for key, topic in _ERROR_TOPICS.items():
            part = payload.get(key)
            error = _numbers(part, "dpos_m", "dheading_rad") if isinstance(part, dict) else None
            if error is not None:
                self._log(f"/{robot}/{topic}", t_ns, pose_error(t_ns, *error))

    def _log(self, topic: str, t_ns: int, message: dict[str, Any]) -> None:
        self._channels[topic].log(message, log_time=t_ns)
        self.published += 1

    async def follow(self, broker: BrokerURL, *, identifier: str | None = None) -> None:
        """Subscribe to every robot's telemetry on ``broker`` and publish it, until cancelled
        (reconnecting every ``RECONNECT_S`` while the broker is away)."""
        said = ""
        while True:
            try:
                kwargs = broker.client_kwargs()
                async with aiomqtt.Client(**kwargs, identifier=identifier) as client:
                    await client.subscribe(f"{topics.PREFIX}/+/#", qos=topics.QOS_TELEMETRY)
                    async for message in client.messages:
                        self._on_mqtt_guarded(message.topic.value, message.payload)
            except aiomqtt.MqttError as exc:
                why = str(exc) or type(exc).__name__
                if why != said:  # once per distinct problem, not once a second
                    said = why
                    print(f"foxglove: broker {broker}: {why} (retrying every {RECONNECT_S:g} s)",
                          file=sys.stderr, flush=True)
                await asyncio.sleep(RECONNECT_S)

    def _on_mqtt_guarded(self, topic_name: str, payload: object) -> None:
        """``_on_mqtt``; a message it cannot serve is counted in ``skipped``, never raised: one
        message must not stop the live view for the rest of the fleet's run."""
        try:
            self._on_mqtt(topic_name, payload)
        except Exception:  # house rule 6: no single message stops the node
            self.skipped += 1

    def _on_mqtt(self, topic_name: str, payload: object) -> None:
        split = topics.split(topic_name)
        if split is None or split[1] not in (*_POSE_LEAVES, "error"):
            return
        if not isinstance(payload, bytes | bytearray):
            return
        try:
            data = json.loads(payload)
        except ValueError:
            return
        if isinstance(data, dict):
            self.on_telemetry(split[0], split[1], data)

    def close(self) -> None:
        """Stop serving (clients are disconnected)."""
        self.server.stop()


def _numbers(payload: dict[str, Any], *keys: str) -> tuple[float, ...] | None:
    """The finite numbers under ``keys``, or None when one is missing or not a finite number
    (a JSON integer beyond every float, ``1`` followed by 400 zeros, is not one)."""
    numbers = [n for key in keys if (n := real(payload.get(key))) is not None]
    return tuple(numbers) if len(numbers) == len(keys) else None


class FollowerThread:
    """``FleetFoxglove.follow`` on an event loop of its own thread (the fleet runs its own)."""

    def __init__(self, live: FleetFoxglove, broker: BrokerURL) -> None:
        self._loop = asyncio.new_event_loop()
        self._task: asyncio.Task[None] | None = None
        self._ready = threading.Event()
        self._thread = threading.Thread(
            target=self._run, args=(live, broker), name="foxglove-fleet", daemon=True
        )

    def _run(self, live: FleetFoxglove, broker: BrokerURL) -> None:
        asyncio.set_event_loop(self._loop)
        identifier = f"odocan-foxglove-{os.getpid()}"  # one per process: shards do not clash
        self._task = self._loop.create_task(live.follow(broker, identifier=identifier))
        self._ready.set()
        with contextlib.suppress(asyncio.CancelledError):
            self._loop.run_until_complete(self._task)
        self._loop.close()

    def start(self) -> None:
        """Start following."""
        self._thread.start()
        self._ready.wait()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Cancel the follower and wait for its thread."""
        if self._task is not None:
            self._loop.call_soon_threadsafe(self._task.cancel)
        self._thread.join(timeout_s)


@contextlib.contextmanager
def serve_fleet_foxglove(
    args: argparse.Namespace, broker: BrokerURL, robots: Iterable[str]
) -> Iterator[FleetFoxglove | None]:
    """With ``--foxglove``: serve the fleet on ``broker`` while the block runs; else None."""
    if getattr(args, "foxglove", None) is None:
        yield None
        return
    live = FleetFoxglove(port=args.foxglove, robots=robots)
    follower = FollowerThread(live, broker)
    try:
        follower.start()
        print(f"foxglove: serving the fleet on {live.url}: in Foxglove, Open connection > "
              f"Foxglove WebSocket > {live.url}", file=sys.stderr, flush=True)
        yield live
    finally:
        follower.stop()
        live.close()


__all__ = ["FleetFoxglove", "FollowerThread", "serve_fleet_foxglove"]
