"""CAN <-> MQTT for any number of robots (asyncio + aiomqtt; python-can on the CAN side).

Frames reach the bridge as batches of ``(robot index, frame)`` in a bounded ``asyncio.Queue``, a
frame being a ``can.Message`` or, from the lockstep fleet, the ``(t, id, payload)`` tuple its
transport queued (``sim.framebatch.Received``: no ``Message`` built per frame):

* from a live bus, ``host.mqtt.busfeed.BusFeed`` reads it on a thread (``host.io.busreader``,
  as the monitor does) and its task ``can-feed`` puts the frames here, waiting for room (what
  this process lost of the bus is ``status``'s ``receive``);
* from the in-process fleet (``sim.fleet``), the fleet's timer task offers its batches directly.

A full queue drops the batch and counts it (``frames_dropped``): the bus never waits for MQTT. The
task ``can-frames`` feeds each robot's ``RobotTelemetry`` and queues its publications on the
robot's ``RobotLink``, a loop turn after each ``slice_frames`` frames judged (so a large fleet's
tick never holds the loop for long); ``periodic`` publishes ``status`` and ``rates``,
the robots' turns spread over the period (a robot a turn, up to ``periodic.SLOTS`` turns a period);
each link runs its own connection. Commands are validated by the robot's ``CommandEncoder`` and
only then sent on the robot's bus, paced (``host.mqtt.pacing``: a window of frames un-answered, the
rest queued); each one is answered on ``cmd/result`` (accepted, rejected with the reason, expired),
then once more with its end (acked, nacked, expired, rejected, timeout). No frame and no command
can stop the bridge: a handler that raises anyway is counted (``frames_failed``,
``commands_failed``) and logged once. ``rates`` carries each link's counters (``link``: telemetry
dropped, QoS-1 dropped, refused, commands expired, reconnects) and its pacer's (``pacing``:
commands queued, frames in flight, refused, expired in the queue, timed out, aborted). When the
bridge stops, every command taken and not answered yet is answered ``aborted`` (the reason says
whether it ran) before the links say ``offline`` and disconnect, and a command that arrives
meanwhile is answered ``aborted`` too, not sent. With an ``end_rule`` (``odocan bridge``'s,
``odocan fleet``'s), each robot is judged once its watch ended (``host.mqtt.endverdict``) and its
``offline`` status carries that verdict as ``watch_verdict`` (``end_verdicts``: the same verdicts,
for the bridge's lines and exit code).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import Counter
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import can

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import firmwareheard, topics
from odocan.host.mqtt.bridgeconfig import BridgeConfig as BridgeConfig  # (its home before)
from odocan.host.mqtt.broker import first_error
from odocan.host.mqtt.clientids import reader_client_id
from odocan.host.mqtt.cmdreader import COMMAND_QUEUE, CommandReader, RobotCommands
from odocan.host.mqtt.endverdict import EndJudge, EndVerdict
from odocan.host.mqtt.expiry import Expired, Fresh
from odocan.host.mqtt.framehold import FrameHold
from odocan.host.mqtt.link import RobotLink, Verdict
from odocan.host.mqtt.livecommands import PendingAck
from odocan.host.mqtt.pacing import CommandPacer
from odocan.host.mqtt.periodic import publish_in_turns
from odocan.host.mqtt.stallwatch import StallWatch
from odocan.host.mqtt.telemetry import Publication, RobotTelemetry
from odocan.host.protocol.commands import (
    Command,
    CommandEncoder,
    CommandRejected,
    Frame,
    command_id,
)
from odocan.host.protocol.secoc import SecocSigner
from odocan.sim.framebatch import Received
from odocan.sim.releasegate import ReleaseGate

log = logging.getLogger(__name__)
# (robot index, frame): a live bus's frames are Messages, the lockstep fleet's mostly DataFrames
Batch = list[tuple[int, Received]]


@dataclass(frozen=True)
class RobotEndpoint:
    """One robot as the bridge sees it: a name, the bus to send its commands on, its geometry
    and ``counter_bits``, its hardware encoder counters' width (16 or 32; its robot profile's),
    keyword-only and required: a default width made a 16-bit robot's expected PROFILE CRC and its
    counter wraps wrong without a word."""

    name: str
    bus: can.BusABC
    geometry: Geometry
    integrator: str = "exact"
    counter_bits: int = field(kw_only=True)
    # SecOC (docs/secoc.md): an ODOM_AUTH after each secured frame; None: commands unsigned
    signer: SecocSigner | None = field(default=None, repr=False)
    publish_phase_s: float = 0.0  # its first pose published this long after the first sample
    profile_name: str | None = None  # its robot profile's (--robot), said in a profile mismatch
    from_page: bool = False  # no --robot: the firmware's PROFILE page picks (judge.liverobot)


class _Robot:
    """A robot's telemetry, command encoder, bus and link."""

    def __init__(self, endpoint: RobotEndpoint, config: BridgeConfig,
                 commands: RobotCommands | None = None) -> None:
        self.endpoint = endpoint
        self.telemetry = RobotTelemetry(
            endpoint.name, endpoint.geometry, endpoint.integrator,
            counter_bits=endpoint.counter_bits, publish_hz=config.publish_hz,
            publish_phase_s=endpoint.publish_phase_s,
            now_s=time.monotonic(), profile_name=endpoint.profile_name,
            from_page=endpoint.from_page,
        )
        self.feed_fields = self.telemetry.feed_fields  # (bound once: per frame, ``_handle``)
        self.plans = self.telemetry.plans  # a frame's plan by 11-bit id (host.mqtt.liveplan)
        self.signer = endpoint.signer
        self.encoder = CommandEncoder(self.telemetry.db)
        self.link = RobotLink(
            robot=endpoint.name, broker=config.broker, on_command=self.on_command,
            client_prefix=config.client_prefix, keepalive_s=config.keepalive_s,
            connect_timeout_s=config.connect_timeout_s,
            command_expiry_s=config.command_expiry_s,
            telemetry_buffer=config.telemetry_buffer, reliable_buffer=config.reliable_buffer,
            commands=commands,
        )
        self.link.last_status = self.last_status  # the ``offline`` status carries it
        self.pacer = CommandPacer(
            self.telemetry, self._send_frame, window_frames=config.command_window_frames,
            ack_timeout_s=config.command_ack_timeout_s, max_queued=config.command_queue,
            expiry_s=config.command_expiry_s,
        )
        self.commands_sent = self.commands_rejected = self.commands_failed = 0
        self.stopping = False  # the bridge stops: no command is sent any more (``abort``)
        # what this process lost of the robot's live bus, for ``status`` (``host.mqtt.busfeed``)
        self.receive: Callable[[], dict[str, Any]] | None = None
        self.verdict: EndVerdict | None = None  # its watch's, once ended (``Bridge.end_rule``)

    def status(self) -> Publication:
        """``status``, with ``receive`` when the robot's frames come from a live bus."""
        if self.receive is None:
            return self.telemetry.status()
        receive = self.receive()  # first: its ``lost_here`` event goes out with this status
        leaf, payload = self.telemetry.status()  # and the firmware's age: silence is not OK
        return leaf, {**payload, "receive": receive,
                      "firmware_heard": firmwareheard.telemetry_heard(self.telemetry, time.time())}

    def last_status(self) -> dict[str, Any]:
        """The fields of ``status`` but its ``robot``, ``state`` and stamp, and the watch's
        ``watch_verdict`` once judged: the link's ``offline`` status carries them (the watch's
        verdicts, retained after the bridge)."""
        payload = self.status()[1]
        last = {k: v for k, v in payload.items() if k not in ("robot", "state", "unix_s")}
        if self.verdict is not None:
            last["watch_verdict"] = self.verdict.as_dict()
        return last

    def on_command(
        self, name: str, payload: bytes, verdict: Verdict | Expired | Fresh = "run"
    ) -> list[Publication]:
        """Validate, then send; always the one answer for ``cmd/result``, never an exception."""
        name = name[:64]  # a topic level is up to 64 KiB: the answer echoes a bounded name
        if verdict == "expired":
            self.commands_rejected += 1
            reason = (verdict.reason if isinstance(verdict, Expired) else
                      "older than its expiry: not run")  # the rule, when the link said it
            return [_result(command_id(payload), name, "expired", reason)]
        if self.stopping:
            self.commands_rejected += 1
            return [_result(command_id(payload), name, "aborted",
                            "the bridge is stopping: not run")]
        if verdict in ("busy", "retained"):
            self.commands_rejected += 1
            reason = ("bridge busy: not run" if verdict == "busy" else
                      "a retained command is not run (its age is unknown): publish without retain")
            return [_result(command_id(payload), name, "rejected", reason)]
        try:
            command = self.encoder.encode(name, payload)
            paced = self._submit(command, getattr(verdict, "remaining_s", None))
        except CommandRejected as exc:
            self.commands_rejected += 1
            return [_result(exc.cmd_id, name, "rejected", exc.reason)]
        except Exception as exc:  # a defect must not stop the bridge: answer, log, go on
            self.commands_failed += 1
            log.warning("%s: command %s failed: %r", self.endpoint.name, name, exc,
                        exc_info=log.isEnabledFor(logging.DEBUG))
            return [_result(command_id(payload), name, "rejected",
                            f"internal error ({type(exc).__name__})")]
        if _refused(paced, command):  # the bus refused its first frame: that is its answer
            self.commands_rejected += 1
            return paced
        self.commands_sent += 1
        return [_result(command.cmd_id, name, "accepted", None, frames=len(command.frames)),
                *paced]

    def abort(self) -> list[Publication]:
        """The bridge stops: the pacer's commands not answered yet, answered ``aborted``; from
        now on no command is sent."""
        self.stopping = True
        return self.pacer.abort()

    def paced(self, published: list[Publication]) -> list[Publication]:
        """``published`` (the telemetry's, for one frame) and the pacer's answers: an ODOM_ACK
        frees its frame's slot in the window, and the next command frames go out."""
        return [*published, *self.pacer.pump(time.monotonic(), published)]

    def _submit(self, command: Command, remaining_s: float | None = None) -> list[Publication]:
        """Queue ``command`` on the pacer and send what the window takes now: the pacer's
        answers (``rejected`` for ``command`` when the bus refused its first frame), or
        CommandRejected (the queue full, no SecOC freshness). ``remaining_s``: what its expiry
        rules left it (``host.mqtt.expiry.Fresh``): it expires in the pacer's queue then, if
        that comes before the pacer's own ``expiry_s``."""
        signer = self.endpoint.signer
        if signer is not None and signer.next_fv is None:  # before any frame: all or nothing
            raise CommandRejected(
                "SecOC: no ODOM_FRESHNESS from the firmware yet (it sends one every second)",
                command.cmd_id,
            )
        now_s = time.monotonic()
        queued_s = now_s if remaining_s is None else \
            min(now_s, now_s + remaining_s - self.pacer.expiry_s)
        if not self.pacer.submit(command, command.name, queued_s):
            raise CommandRejected(
                f"bridge busy: {self.pacer.max_queued} commands already wait for the bus: "
                "not run", command.cmd_id)
        return self.pacer.send_now(time.monotonic())

    def _send_frame(self, command: Command, frame: Frame) -> int:
        """Put one command frame (and its ODOM_AUTH) on the bus: the mailbox slots taken."""
        bus = self.endpoint.bus
        signer = self.endpoint.signer
        ack = PendingAck(command.cmd_id, command.name, frame.final, frame.data, command)
        self.telemetry.expect_ack(frame.can_id, frame.counter, ack)
        self.telemetry.command_sent(frame.can_id, frame.data)  # a set-pose, a config followed
        try:
            bus.send(can.Message(arbitration_id=frame.can_id, is_extended_id=False,
                                 data=frame.data))
        except can.CanError as exc:
            del self.telemetry.pending[(frame.can_id, frame.counter)]
            raise CommandRejected(f"bus refused the frame: {exc}", command.cmd_id) from None
        if signer is None or not signer.is_secured(frame.can_id):
            return 1
        auth = signer.sign(frame.can_id, frame.data)
        try:
            bus.send(can.Message(arbitration_id=signer.auth_frame_id,
                                 is_extended_id=False, data=auth))
            self.telemetry.command_sent(signer.auth_frame_id, auth)
        except can.CanError as exc:
            raise CommandRejected(f"bus refused ODOM_AUTH: {exc}", command.cmd_id) from None
        return 2


def _id_and_data(frame: Received) -> tuple[int, bytes]:
    """A frame's identifier and payload, a ``DataFrame`` tuple's or a ``Message``'s."""
    if type(frame) is tuple:
        return frame[1], frame[2]
    assert isinstance(frame, can.Message)
    return frame.arbitration_id, bytes(frame.data)


def _refused(answers: list[Publication], command: Command) -> bool:
    """``answers`` (the pacer's) refuse ``command`` itself (the bus refused its frame)."""
    return any(p.get("result") == "rejected" and p.get("id") == command.cmd_id
               for _, p in answers)


def _result(
    cmd_id: Any, name: str, result: str, reason: str | None, **extra: Any
) -> Publication:
    return (topics.RESULT_LEAF, topics.stamp(
        {"id": cmd_id, "command": name, "result": result, "reason": reason, **extra}
    ))


class Bridge:
    """CAN <-> MQTT for ``robots`` (see the module docstring)."""

    def __init__(self, robots: Sequence[RobotEndpoint], *, config: BridgeConfig,
                 end_rule: EndJudge | None = None, gate: ReleaseGate | None = None) -> None:
        """``end_rule``: how each robot is judged when its watch ends, the verdict its
        ``offline`` status carries (``watch_verdict``; ``odocan bridge``'s ``EndRule``, ``odocan
        fleet``'s ``FleetEndRule``); None: none. ``gate``: a real-time fleet's releases
        (``sim.releasegate``): no slice or periodic turn starts just before one."""
        self.config = config
        self.end_rule = end_rule
        self.gate = gate
        names = [r.name for r in robots]
        # one thread and one connection read every robot's commands (``host.mqtt.cmdreader``)
        self.commands = CommandReader(
            robots=names, broker=config.broker,
            client_id=reader_client_id(config.client_prefix, names),
            keepalive_s=config.keepalive_s, connect_timeout_s=config.connect_timeout_s,
            session_expiry_s=config.command_expiry_s, capacity=COMMAND_QUEUE)
        self.robots = [_Robot(r, config, self.commands.robots[r.name]) for r in robots]
        self.queue: asyncio.Queue[Batch] = asyncio.Queue(maxsize=config.queue_batches)
        self.frames_dropped = 0
        self.frames_in = 0
        self.frames_failed = 0  # frames whose handling raised (a defect): counted, logged once
        self._pending: Batch = []  # the batch being handled, slice by slice (``_consume``)
        self._pending_at = 0  # its first frame not handled yet
        self.stalls = StallWatch(lambda: any(r.link.connected.is_set() for r in self.robots))
        self.hold = FrameHold(len(self.robots), config.hold_s) if config.hold_s > 0 else None
        for index, robot in enumerate(self.robots):  # its held frames judged first
            robot.link.on_command = partial(self._flushed, index, robot.on_command)
            robot.link.last_status = partial(self._flushed, index, robot.last_status)

    @property
    def links(self) -> list[RobotLink]:
        """Each robot's MQTT link, in robot order."""
        return [r.link for r in self.robots]

    def offer(self, batch: Batch) -> None:
        """Queue one batch of frames (event-loop thread only); dropped and counted when full."""
        try:
            self.queue.put_nowait(batch)
        except asyncio.QueueFull:
            self.frames_dropped += len(batch)

    async def run(self, *, stop: asyncio.Event) -> None:
        """Serve until ``stop`` is set; every link publishes ``offline`` and disconnects.

        ``BrokerError`` (not wrapped in a group) when a link's first connection fails."""
        try:
            async with asyncio.TaskGroup() as tg:
                for robot in self.robots:
                    tg.create_task(robot.link.run(stop=stop),
                                   name=f"mqtt-link-{robot.link.robot}")
                frames = tg.create_task(self._consume(), name="can-frames")
                periodic = tg.create_task(self._periodic(
                    sleep=asyncio.sleep if self.gate is None else self.gate.sleep),
                    name="periodic")
                pacing = tg.create_task(self._pace(), name="command-pacing")
                stalls = tg.create_task(self.stalls.run(), name="loop-stalls")
                await stop.wait()
                await asyncio.sleep(0)
                self._drain()
                self._end_watch()  # before the links' offline, which carries the verdicts
                self._judge_end()  # once, before the links' offline, which carries it
                self._abort()  # queued before the links' offline: flushed with it
                frames.cancel()
                periodic.cancel()
                pacing.cancel()
                stalls.cancel()
        except BaseExceptionGroup as group:
            raise first_error(group) from None

    def counters(self) -> dict[str, Any]:
        """What was dropped, refused, expired or failed (the report's ``bridge`` entry)."""
        totals: Counter[str] = Counter()
        for robot in self.robots:
            totals.update(robot.link.counters())
            totals.update(robot.pacer.counters())
        return {
            "frames_in": self.frames_in,
            "frames_dropped": self.frames_dropped,
            "frames_failed": self.frames_failed,
            "commands_failed": sum(r.commands_failed for r in self.robots),
            **totals,
            **self.stalls.counters(),  # commands a broker held for us may be lost (stallwatch)
            "release_holds": 0 if self.gate is None else self.gate.holds,  # (sim.releasegate)
            "release_overruns": 0 if self.gate is None else self.gate.overruns,
        }

    async def _consume(self) -> None:
        """The batches, ``slice_step`` frames at a time, a loop turn after ``slice_frames`` judged
        (a hold lets frames go at once: 64 taken judged up to 514, ~6 ms, a late tick at 100
        robots); the rest waits in ``_pending`` (``_drain``'s at the end), in bus order."""
        size, judged = max(1, self.config.slice_frames), 0
        step = max(1, min(self.config.slice_step, size))
        while True:
            if not self._pending:
                judged = 0 if self.queue.empty() else judged  # empty: the get gives a turn
                self._pending, self._pending_at = await self.queue.get(), 0
            if self.gate is not None:
                await self.gate.clear()
            start = self._pending_at
            self._pending_at = start + step
            judged += self._handle(self._pending[start:self._pending_at])
            if self._pending_at >= len(self._pending):
                self._pending = []
            if judged >= size:
                judged = 0
                await asyncio.sleep(0)

    def _abort(self) -> None:
        """Every robot's commands not answered yet: ``aborted`` (``_Robot.abort``)."""
        for robot in self.robots:
            for leaf, payload in robot.abort():
                robot.link.publish(leaf, payload)

    def _end_watch(self) -> None:
        """The watch ends as the fleet's report ends it (``RobotTelemetry.end_watch``): a hold's
        frames judged (else up to ~1.5 s of the bus never was), their publications queued; each
        link's ``offline`` status then carries the robot's final verdicts."""
        for robot in self.robots:
            for leaf, payload in robot.telemetry.end_watch():
                robot.link.publish(leaf, payload)

    def _judge_end(self) -> None:
        """Each robot's verdict by ``end_rule``, its watch ended (``_end_watch``): its
        ``offline`` status carries it, the bridge's line says it (``end_verdicts``)."""
        if self.end_rule is None:
            return
        for robot in self.robots:
            robot.verdict = self.end_rule.judge(robot.telemetry, robot.endpoint.profile_name)

    def end_verdicts(self) -> list[tuple[str, EndVerdict]]:
        """(robot name, verdict) of every robot as ``run`` judged them at the watch's end (its
        ``offline`` statuses'); RuntimeError before, or without an ``end_rule``: none made up."""
        judged = [(r.endpoint.name, r.verdict) for r in self.robots]
        verdicts = [(name, v) for name, v in judged if v is not None]
        if len(verdicts) != len(judged):
            raise RuntimeError("the bridge's watch has not ended with an end_rule: no verdict")
        return verdicts

    def _drain(self) -> None:
        pending, self._pending = self._pending[self._pending_at:], []
        self._handle(pending)
        while not self.queue.empty():
            self._handle(self.queue.get_nowait())
        for index in range(len(self.robots)):
            self._flush(index)

    def _flush(self, index: int) -> None:
        """Robot ``index``'s held frames judged now, before its telemetry is read (framehold)."""
        if self.hold is not None and self.hold.held[index]:
            self._feed(self.hold.take_robot(index))

    def _flushed(self, index: int, then: Callable[..., Any], *args: Any) -> Any:
        self._flush(index)
        return then(*args)

    def _waits(self, index: int, t_s: float) -> bool:
        return not self.robots[index].pacer.busy and self.robots[index].telemetry.pose_waits(t_s)

    def _handle(self, batch: Batch) -> int:
        """``batch`` counted, held (``hold_s``) or judged (``_feed``); the frames judged."""
        self.frames_in += len(batch)
        judged = batch if self.hold is None else self.hold.take(batch, self._waits)
        self._feed(judged)
        return len(judged)

    def _feed(self, batch: Batch) -> None:
        """Feed each frame of ``batch`` to its robot's telemetry, queue what it publishes (and
        the pacer's answers while it is busy). Per frame of every robot: the robot's parts as
        ``_Robot`` holds them (its telemetry's plans: a frame of a DBC message goes to its
        identifier's plan, no ``feed_fields`` call around it), a fleet's ``(t, id, payload)``
        tuple taken apart, not spread (``feed_frame``'s fast path in line)."""
        robots = self.robots
        for index, frame in batch:
            robot = robots[index]
            if robot.signer is not None:
                can_id, data = _id_and_data(frame)
                if can_id == robot.signer.freshness_frame_id:
                    robot.signer.on_freshness(data)  # a bad frame is refused by its E2E check
            try:
                if type(frame) is tuple:
                    t_s, can_id, data = frame
                    plan = robot.plans.get(can_id)
                    publications = (plan(t_s, data) if plan is not None
                                    else robot.feed_fields(t_s, can_id, data, False))
                else:
                    publications = robot.telemetry.feed_frame(frame)
            except Exception as exc:  # a defect must not stop the bridge: count, log once
                if self.frames_failed == 0:
                    log.warning("%s: frame %s failed: %r", robot.endpoint.name, frame, exc,
                                exc_info=log.isEnabledFor(logging.DEBUG))
                self.frames_failed += 1
                continue
            if robot.pacer.busy:  # an ODOM_ACK frees the window: the next command frames
                publications = robot.paced(publications)
            for leaf, payload in publications:
                robot.link.publish(leaf, payload)

    async def _periodic(self, clock: Callable[[], float] = time.monotonic,
                        sleep: Callable[[float], Awaitable[None]] = asyncio.sleep) -> None:
        """``status`` (at once, then every ``status_period_s``) and ``rates`` (every
        ``rates_period_s``) of every robot, in turns spread over the period
        (``host.mqtt.periodic.publish_in_turns``)."""
        for robot in self.robots:  # online as soon as the link connects (retained)
            robot.link.publish(*robot.status())
        await publish_in_turns(len(self.robots),
                               (self.config.rates_period_s, self.config.status_period_s),
                               (self._publish_rates, self._publish_status), clock, sleep)

    def _publish_rates(self, index: int, now_s: float) -> None:
        self._flush(index)
        robot = self.robots[index]
        leaf, payload = robot.telemetry.rates(now_s)
        robot.link.publish(leaf, {**payload, "link": robot.link.counters(),
                                  "pacing": robot.pacer.counters()})

    def _publish_status(self, index: int, _now_s: float) -> None:
        self._flush(index)
        robot = self.robots[index]
        robot.link.publish(*robot.status())

    async def _pace(self) -> None:
        """Every ``pace_period_s``: the paced commands' timeouts and expiries, answered."""
        while True:
            await asyncio.sleep(self.config.pace_period_s)
            for index, robot in enumerate(self.robots):
                if robot.pacer.busy:
                    self._flush(index)
                    for leaf, payload in robot.paced([]):
                        robot.link.publish(leaf, payload)
