"""Live Foxglove: the Foxglove WebSocket protocol (``foxglove-sdk``) served on 127.0.0.1.

``FoxgloveLive`` is a python-can ``Listener``: every frame goes through ``BusMonitor`` (E2E,
decoding, the live ``PoseTracker``: on-board pose vs float64 reference at the encoder frame the
pose names, vs ground truth), and what it yields is published on the topics of the MCAP export
(``host.io.mcap``), with the same JSON messages and schemas:

* ``/pose/onboard``, ``/pose/reference``, ``/pose/truth`` (``foxglove.PoseInFrame``, frame
  ``odom``) and ``/tf`` (``foxglove.FrameTransform``: odom -> base_link, reference_link,
  truth_link), at every on-board sample (50 Hz) and every truth sample;
* ``/errors/reference``, ``/errors/truth`` (``odocan.PoseError``: on-board minus reference or
  truth, m and rad);
* ``/can/frames``: every frame heard, raw (``odocan.CanFrame``); ``/can/<MESSAGE>``: the decoded
  signals of every accepted frame, named as in the Parquet export (``X_m``,
  ``LEFT_COUNT_count``), enum values by name.

Log times are the frames' timestamps (simulated time in the lockstep rig). The lockstep rig runs
far faster than real time, so a run waits for a client's first subscription
(``wait_for_client``) and the server buffers up to ``BACKLOG`` messages per client; with
``realtime`` each frame waits for its simulated time on the wall clock.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from typing import Any

import can
import foxglove
from cantools.database.can import Database
from foxglove.websocket import ChannelView, Client, ServerListener

from odocan.host.io.export import (
    FOXGLOVE_PORT,
    POSE_TOPICS,
    TIME_SCHEMA,
    can_frame,
    column_name,
    foxglove_time,
    frame_transform,
    json_schema,
    pose_error,
    pose_in_frame,
    to_ns,
)
from odocan.host.judge.livepose import FramePose
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.decode import frame_key
from odocan.host.report.foxglove_options import Served, start_server
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import RobotProfile

DEFAULT_PORT = FOXGLOVE_PORT
SETTLE_S = 0.3  # a client's subscriptions are complete after this long without a new one
BACKLOG = 1 << 17  # messages buffered per client (a 61 s run at full speed is ~6e4)


class _Subscriptions(ServerListener):
    """A ``foxglove.websocket.ServerListener``: counts subscriptions, wakes waiters."""

    def __init__(self) -> None:
        self.count = 0
        self.last_subscribe_s = 0.0  # time.monotonic() of the latest subscription
        self.changed = threading.Condition()

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        with self.changed:
            self.count += 1
            self.last_subscribe_s = time.monotonic()
            self.changed.notify_all()

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        with self.changed:
            self.count = max(0, self.count - 1)
            self.changed.notify_all()

    def wait(self, subscribed: bool, timeout_s: float | None) -> bool:
        """Wait until some channel is subscribed (or none is); False on timeout."""
        with self.changed:
            return self.changed.wait_for(lambda: (self.count > 0) == subscribed, timeout_s)


class FoxgloveLive(can.Listener, Served):
    """Serve a drive live to Foxglove (module docstring); a context manager (stops the server)."""

    def __init__(
        self,
        robot: RobotProfile,
        *,
        port: int = DEFAULT_PORT,
        integrator: str | None = None,
        db: Database | None = None,
        realtime: bool = False,
        monitor: BusMonitor | None = None,
    ) -> None:
        """``port`` 0: any free port (see ``self.port``); ``integrator`` None: ODOM_STATUS's.

        ``monitor``: a ``BusMonitor`` that its owner feeds (``odocan monitor``), then calls
        ``publish(msg)`` after each frame; None: this listener keeps and feeds its own."""
        self.monitor = monitor if monitor is not None else BusMonitor(robot, integrator, db)
        self.realtime = realtime
        self.published = 0
        self._context = foxglove.Context()
        self._subscriptions = _Subscriptions()
        self._channels: dict[str, foxglove.Channel] = {}
        self._columns: dict[str, dict[str, str]] = {}
        self._open_channels()
        self._last: tuple[FramePose | None, FramePose | None] = (None, None)
        self._frames_shown: dict[str, object] = {}
        self._truth_samples = 0
        self._by_key = {frame_key(m.frame_id, m.is_extended_frame): m.name
                        for m in self.monitor.db.messages}
        self._start_s: float | None = None
        self.server = start_server("odocan", port, context=self._context,
                                   server_listener=self._subscriptions,
                                   message_backlog_size=BACKLOG)

    def _open_channels(self) -> None:
        topics = {"/can/frames": "odocan.CanFrame", "/tf": "foxglove.FrameTransform",
                  "/errors/reference": "odocan.PoseError", "/errors/truth": "odocan.PoseError"}
        topics.update({topic: "foxglove.PoseInFrame" for topic, _ in POSE_TOPICS.values()})
        for topic, name in topics.items():
            self._channel(topic, name, json_schema(name))
        for message in self.monitor.db.messages:
            self._columns[message.name] = {s.name: column_name(s) for s in message.signals}
            props: dict[str, Any] = {column: {} for column in self._columns[message.name].values()}
            schema = {"title": f"odocan.{message.name}", "type": "object",
                      "properties": {"timestamp": TIME_SCHEMA, **props}}
            self._channel(f"/can/{message.name}", f"odocan.{message.name}",
                          json.dumps(schema).encode())

    def _channel(self, topic: str, name: str, schema: bytes) -> None:
        self._channels[topic] = foxglove.Channel(
            topic, schema=foxglove.Schema(name=name, encoding="jsonschema", data=schema),
            message_encoding="json", context=self._context,
        )

    def wait_for_client(self, timeout_s: float | None = None, settle_s: float = SETTLE_S) -> bool:
        """Block until a client subscribes to a topic and then ``settle_s`` passes without a new
        subscription (a client subscribes channel by channel: what comes before the last
        would be lost); False when ``timeout_s`` passed before the first."""
        if not self._subscriptions.wait(True, timeout_s):
            return False
        while (quiet := time.monotonic() - self._subscriptions.last_subscribe_s) < settle_s:
            time.sleep(settle_s - quiet)
        return True

    def wait_for_clients_to_leave(self, timeout_s: float | None = None) -> bool:
        """Block until no topic is subscribed (clients gone); False on timeout."""
        return self._subscriptions.wait(False, timeout_s)

    def on_message_received(self, msg: can.Message) -> None:
        """One frame heard: pace it (``realtime``), feed the monitor, publish what it yields."""
        if self.realtime:
            self._pace(msg.timestamp)
        self.monitor.feed(msg)
        self.publish(msg)

    def publish(self, msg: can.Message) -> None:
        """Publish what the monitor made of ``msg`` (already fed to it)."""
        t_ns = to_ns(msg.timestamp)
        self._log("/can/frames", t_ns, can_frame(
            t_ns, msg.arbitration_id, bytes(msg.data), extended=msg.is_extended_id,
            remote=msg.is_remote_frame, error=msg.is_error_frame,
        ))
        self._publish_signals(msg, t_ns)
        tracker = self.monitor.tracker
        if tracker.pose is not self._last[0]:  # at its ODOM_POSE_Y (it settles a bit later)
            self._publish_onboard(to_ns(tracker.pose_t_s))
        if tracker.truth is not self._last[1]:
            self._publish_truth(t_ns)
        self._last = (tracker.pose, tracker.truth)

    def _pace(self, timestamp_s: float) -> None:
        now = time.monotonic()
        if self._start_s is None:
            self._start_s = now - timestamp_s
        delay = self._start_s + timestamp_s - now
        if delay > 0:
            time.sleep(delay)

    def _publish_signals(self, msg: can.Message, t_ns: int) -> None:
        """The decoded signals of the frame, when the monitor accepted and decoded it."""
        name = self._by_key.get(frame_key(msg.arbitration_id, msg.is_extended_id))
        stats = self.monitor.messages.get(name) if name is not None else None
        if name is None or stats is None or not stats.last_frame:
            return
        if self._frames_shown.get(name) is stats.last_frame:
            return  # not accepted: the monitor kept the previous frame's values
        self._frames_shown[name] = stats.last_frame
        columns = self._columns[name]
        values = {columns.get(k, k): v for k, v in stats.last_frame.items()}
        self._log(f"/can/{name}", t_ns, {"timestamp": foxglove_time(t_ns), **values})

    def _publish_onboard(self, t_ns: int) -> None:
        tracker = self.monitor.tracker
        self._publish_pose("onboard", tracker.pose, t_ns)
        reference = tracker.reference
        if reference is not None and tracker.pose is not None and reference.seq == tracker.pose.seq:
            self._publish_pose("reference", reference, t_ns)
            latest = tracker.vs_reference.latest
            self._log("/errors/reference", t_ns,
                      pose_error(t_ns, latest["dpos_m"], latest["dheading_rad"]))

    def _publish_truth(self, t_ns: int) -> None:
        tracker = self.monitor.tracker
        self._publish_pose("truth", tracker.truth, t_ns)
        latest = tracker.vs_truth.latest
        if latest and tracker.vs_truth.samples != self._truth_samples:
            self._truth_samples = tracker.vs_truth.samples
            self._log("/errors/truth", t_ns,
                      pose_error(t_ns, latest["dpos_m"], latest["dheading_rad"]))

    def _publish_pose(self, prefix: str, pose: FramePose | None, t_ns: int) -> None:
        if pose is None:
            return
        topic, child = POSE_TOPICS[prefix]
        self._log(topic, t_ns, pose_in_frame(t_ns, pose.x_m, pose.y_m, pose.heading_rad))
        self._log("/tf", t_ns, frame_transform(t_ns, child, pose.x_m, pose.y_m, pose.heading_rad))

    def _log(self, topic: str, t_ns: int, message: dict[str, Any]) -> None:
        self._channels[topic].log(message, log_time=t_ns)
        self.published += 1

    def close(self) -> None:
        """Stop serving (clients are disconnected). Not ``stop``: python-can's ``Notifier`` and
        the rig call a listener's ``stop`` when the bus goes, and the server outlives the drive."""
        self.server.stop()

    def __enter__(self) -> FoxgloveLive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# --- odocan run --foxglove (its options: host.report.foxglove_options, light) ------------------


@contextmanager
def serve_foxglove(
    args: argparse.Namespace, robot: RobotProfile, integrator: str | None
) -> Iterator[FoxgloveLive | None]:
    """With ``--foxglove``: serve, wait for a client, yield the listener; after the drive keep
    serving until the client leaves (or Ctrl-C). Without: yield None."""
    if args.foxglove is None:
        if args.realtime:
            raise ConfigurationError("--realtime paces the drive for --foxglove: give --foxglove")
        yield None
        return
    live = FoxgloveLive(robot, port=args.foxglove, integrator=integrator, realtime=args.realtime)
    try:
        _say(f"serving on {live.url}: in Foxglove, Open connection > Foxglove WebSocket > "
             f"{live.url}; the drive starts when a client subscribes (Ctrl-C stops)")
        live.wait_for_client()
        yield live
        _say(f"drive done ({live.published} messages); serving until the client disconnects "
             "(Ctrl-C stops)")
        with suppress(KeyboardInterrupt):
            live.wait_for_clients_to_leave()
    finally:
        live.close()


def _say(text: str) -> None:
    print(f"foxglove: {text}", file=sys.stderr, flush=True)
