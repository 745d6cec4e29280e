"""The MQTT bridge against real brokers: mosquitto (users, ACL, restart) and the embedded amqtt.

Each command test listens on the robot's virtual CAN channel: what the bridge sends is what
reaches the bus, and nothing invalid does.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from itertools import count
from pathlib import Path
from typing import Any

import aiomqtt
import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import topics
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.sim import robot
from odocan.sim.fleet import FleetConfig
from odocan.sim.rig import LockstepRig, RigConfig
from tests.conftest_mqtt import (  # noqa: F401 (fixtures)
    Mosquitto,
    broker_of,
    client,
    collect,
    durable_mosquitto,
    mosquitto,
)
from tests.fleet_run_until import BOUND_S, stop_fleet_when

BROKERS = ("mosquitto", "amqtt")
ROBOT = "robot001"
_channels = count()
PMIR = robot.load("pmir")
GEOMETRY = Geometry.of(PMIR)


@asynccontextmanager
async def running_bridge(
    url: BrokerURL, **config: Any
) -> AsyncIterator[tuple[Bridge, can.BusABC]]:
    """A bridge for ROBOT on a fresh virtual channel, and a listener on that channel."""
    channel = f"test-mqtt-{os.getpid()}-{next(_channels)}"
    send_bus = can.Bus(interface="virtual", channel=channel)
    listener = can.Bus(interface="virtual", channel=channel)
    bridge = Bridge([RobotEndpoint(ROBOT, send_bus, GEOMETRY, counter_bits=PMIR.counter_bits)],
                    config=BridgeConfig(broker=url, client_prefix=f"test-{channel}", **config))
    stop = asyncio.Event()
    task = asyncio.create_task(bridge.run(stop=stop), name="bridge")
    try:
        async with asyncio.timeout(10):
            await bridge.links[0].connected.wait()
        yield bridge, listener
    finally:
        stop.set()
        await asyncio.wait_for(task, 10)
        send_bus.shutdown()
        listener.shutdown()


def bus_frames(bus: can.BusABC) -> list[can.Message]:
    """Every frame waiting on ``bus``."""
    frames = []
    while (msg := bus.recv(0)) is not None:
        frames.append(msg)
    return frames


async def command_results(
    url: BrokerURL, commands: list[tuple[str, bytes]], expected: int
) -> list[dict[str, Any]]:
    """Publish ``commands`` (QoS 1) as ``url``'s user; the first ``expected`` results."""
    async with client(url) as sub:
        await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
        for name, payload in commands:
            await sub.publish(topics.topic(ROBOT, f"cmd/{name}"), payload, qos=1)
        got = await collect(sub, lambda g: len(g) >= expected)
    return [payload for _, payload in got]


BAD_COMMANDS = [
    ("set_pose", b"{not json", "malformed JSON"),
    ("set_pose", b"[1, 2]", "must be a JSON object"),
    ("set_pose", b'{"id": "m", "x_m": 1.0, "y_m": 2.0}', "missing field 'heading_rad'"),
    ("set_pose", b'{"id": "u", "x_m": 1, "y_m": 2, "heading_rad": 0, "z_m": 3}',
     "unknown field 'z_m'"),
    ("set_pose", b'{"id": "r", "x_m": 300000.0, "y_m": 0, "heading_rad": 0}', "out of range"),
    ("set_pose", b'{"id": "t", "x_m": "1", "y_m": 0, "heading_rad": 0}', "must be a number"),
    ("config", b'{"id": "c", "counts_per_rev": 4096, "wheel_radius_left_m": 5.0, '
     b'"wheel_radius_right_m": 0.05, "wheelbase_m": 0.3, "counter_bits": 32, '
     b'"integrator": "exact"}', "wheel_radius_left_m=5.0 out of range"),
    ("config", b'{"id": "i", "counts_per_rev": 4096, "wheel_radius_left_m": 0.05, '
     b'"wheel_radius_right_m": 0.05, "wheelbase_m": 0.3, "counter_bits": 32, '
     b'"integrator": "simpson"}', "integrator='simpson' is not one of"),
    ("nav_goal", b'{"id": "n", "x_m": 1.0, "y_m": 2.0, "goal_id": 300}', "goal_id=300"),
    ("teleport", b'{"id": "x"}', "unknown command 'teleport'"),
]


@pytest.mark.parametrize("kind", BROKERS)
def test_invalid_commands_are_rejected_and_never_reach_the_bus(kind: str, tmp_path: Path) -> None:
    async def scenario() -> None:
        async with broker_of(kind, tmp_path) as brokers, running_bridge(brokers.bridge) as (
            bridge, listener
        ):
            commands = [(name, payload) for name, payload, _ in BAD_COMMANDS]
            results = await command_results(brokers.operator, commands, len(commands))
            assert bus_frames(listener) == []
            for (_, _, reason), result in zip(BAD_COMMANDS, results, strict=True):
                assert result["result"] == "rejected"
                assert reason in result["reason"], result
            assert bridge.robots[0].commands_rejected == len(BAD_COMMANDS)
            # the listener does hear a valid command: 4 frames, values as commanded
            good = b'{"id": "ok", "x_m": 1.5, "y_m": -2.0, "heading_rad": -0.5}'
            (result,) = await command_results(brokers.operator, [("set_pose", good)], 1)
            assert (result["id"], result["result"], result["frames"]) == ("ok", "accepted", 4)
            await asyncio.sleep(0.05)
            frames = [fr.unpack_odom_set_pose(m.data) for m in bus_frames(listener)]
            assert [(f.field, f.value) for f in frames] == [
                (fr.SetPoseField.X, 15000), (fr.SetPoseField.Y, -20000),
                (fr.SetPoseField.HEADING, 60321), (fr.SetPoseField.APPLY, 0),
            ]

    asyncio.run(scenario())


@pytest.mark.parametrize("kind", BROKERS)
def test_fleet_telemetry_and_retained_status(
    kind: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One real-time robot through the bridge: pose vs reference on the broker, status retained.
    The fleet drives until the operator got a pose, a reference and an error (a 1.5 s drive
    ended before the bridge had published the last two when its loop stalled 1.4 s)."""
    seen = asyncio.Event()
    stop_fleet_when(monkeypatch, seen)

    def leaves_seen(got: list[tuple[str, dict[str, Any]]]) -> bool:
        if {"pose", "reference", "error"} <= {t.split("/", 2)[2] for t, _ in got}:
            seen.set()
        return got[-1][1].get("state") == "offline"

    async def scenario() -> tuple[list[tuple[str, dict[str, Any]]], dict[str, Any]]:
        async with broker_of(kind, tmp_path) as brokers, client(brokers.operator) as sub:
            await sub.subscribe(f"odocan/{ROBOT}/#", qos=1)
            run = FleetRun(fleet=FleetConfig(robots=1, robot=PMIR, seed=3), duration_s=BOUND_S,
                           broker=brokers.bridge, client_prefix=f"test-fleet-{kind}")
            listening = asyncio.create_task(collect(sub, leaves_seen, BOUND_S + 30.0))
            report = await run_fleet(run)
            return await listening, report

    got, report = asyncio.run(scenario())
    by_leaf: dict[str, list[dict[str, Any]]] = {}
    for topic_name, payload in got:
        by_leaf.setdefault(topic_name.split("/", 2)[2], []).append(payload)
    assert {"pose", "reference", "error", "status"} <= set(by_leaf)
    assert by_leaf["status"][0]["state"] == "online"
    assert by_leaf["status"][-1] == {**by_leaf["status"][-1], "state": "offline",
                                     "reason": "bridge stopped"}
    for error in by_leaf["error"]:
        assert error["pose_vs_reference"]["dpos_m"] < 1e-3  # on-board vs float64: quantisation only
    pose = by_leaf["pose"][-1]
    assert {"x_m", "y_m", "heading_rad", "t_s", "unix_s", "counter", "enc_counter"} <= set(pose)
    frames = report["per_robot"][ROBOT]["frames"]
    # one encoder frame per release: each tick run, and each skipped one's sent late
    assert frames["WHEEL_ENCODERS"] == report["ticks"] + report["skipped_releases"]
    assert report["bridge"]["frames_in"] == report["per_robot"][ROBOT]["frames_total"]


def test_anonymous_clients_are_refused(mosquitto: Mosquitto) -> None:  # noqa: F811
    async def scenario() -> None:
        with pytest.raises(aiomqtt.MqttCodeError, match=r"[Nn]ot authori[sz]ed"):
            async with client(mosquitto.url(None)):
                pass

    asyncio.run(scenario())


def test_a_robot_cannot_command_another_robot(mosquitto: Mosquitto) -> None:  # noqa: F811
    async def scenario() -> list[dict[str, Any]]:
        async with running_bridge(mosquitto.url("bridge")) as (_, listener):
            async with client(mosquitto.url("robot002")) as intruder:
                await intruder.publish(  # acknowledged by the broker, delivered to no one
                    topics.topic(ROBOT, "cmd/set_pose"),
                    b'{"id": "intruder", "x_m": 9, "y_m": 9, "heading_rad": 0}', qos=1)
            good = b'{"id": "owner", "x_m": 1, "y_m": 1, "heading_rad": 0}'
            # The broker acknowledged the intruder's message before the owner's was published, so
            # had it been delivered, the bridge would have handled it first: once the owner's
            # result is in, any intruder frame is already on the bus (an event, not a delay).
            results = await command_results(mosquitto.url(ROBOT), [("set_pose", good)], 1)
            values = [fr.unpack_odom_set_pose(m.data).value for m in bus_frames(listener)]
            assert values == [10000, 10000, 0, 0]
            return results

    assert [r["id"] for r in asyncio.run(scenario())] == ["owner"]


class StatusSeqs(aiomqtt.Client):
    """A subscriber that keeps the ``seq`` of every ``online`` status its paho read (``seqs``).

    paho sends a QoS-1 message's PUBACK right after this callback, so these are the messages the
    broker counts as delivered to the session, and will never send again. Reading
    ``messages`` under a timeout is not that: a status paho read (and acknowledged) in the
    last instant before the timeout, or while the client disconnected, stayed in aiomqtt's
    queue unseen, or was taken off it by the cancelled wait, and looked lost (seen under load:
    ``before + 1`` missing, not superseded, read by the first subscriber's paho)."""

    def __init__(self, url: BrokerURL, seqs: list[int], **kwargs: Any) -> None:
        super().__init__(**url.client_kwargs(), **kwargs)
        self.seqs, self.grew = seqs, asyncio.Event()

    def _on_message(self, client: Any, userdata: Any, message: Any) -> None:
        payload = json.loads(message.payload)
        if payload["state"] == "online":
            self.seqs.append(payload["seq"])
            self.grew.set()


def test_no_qos1_message_lost_across_a_broker_restart(mosquitto: Mosquitto) -> None:  # noqa: F811
    """Status (QoS 1, seq) is published every 50 ms; the broker is down for 1 s meanwhile.
    Every status is received but those a newer one superseded while the bridge was offline
    (retained: the broker keeps only the latest; counted in ``status_superseded``).
    "Received": acknowledged by the subscriber's client (``StatusSeqs``), its session's
    account, whichever instant the subscriber disconnects at."""

    async def scenario() -> tuple[list[int], int, int, int]:
        url = mosquitto.url("bridge")
        seqs: list[int] = []

        async def listen(until_seq: int, timeout_s: float) -> None:
            """Until ``until_seq`` is received (``timeout_s``: a bound)."""
            async with StatusSeqs(url, seqs, identifier="test-restart-sub",
                                  clean_session=False) as sub:
                await sub.subscribe(topics.topic(ROBOT, "status"), qos=1)
                async with asyncio.timeout(timeout_s):
                    while not seqs or max(seqs) < until_seq:
                        sub.grew.clear()
                        await sub.grew.wait()

        async with running_bridge(url, status_period_s=0.05) as (bridge, _):
            # the session exists (a status came: a fixed 0.5 s could end, on a loaded machine,
            # before any had); messages queue for it from now on
            await listen(1, 10.0)
            before = max(seqs)
            mosquitto.stop()
            await asyncio.sleep(1.0)  # the bridge keeps producing status into its buffer
            produced = bridge.robots[0].telemetry.status_seq
            mosquitto.start()
            async with asyncio.timeout(15):
                while bridge.links[0].connects < 2:
                    await asyncio.sleep(0.05)
            await listen(produced + 5, 10.0)
            assert bridge.links[0].connects >= 2
        return seqs, before, produced, bridge.links[0].status_superseded

    received, before, produced, superseded = asyncio.run(scenario())
    seqs = sorted(set(received))
    missing = sorted(set(range(seqs[0], seqs[-1] + 1)) - set(seqs))
    assert 0 < len(missing) <= superseded, "a QoS-1 status was lost, not superseded"
    assert all(before < seq for seq in missing), missing  # only the outage's
    assert seqs[0] <= before < produced < seqs[-1]


@pytest.mark.parametrize("kind", BROKERS)
def test_last_will_marks_a_killed_bridge_offline(kind: str, tmp_path: Path) -> None:
    async def scenario() -> list[dict[str, Any]]:
        async with broker_of(kind, tmp_path) as brokers, client(brokers.operator) as sub:
            await sub.subscribe(topics.topic(ROBOT, "status"), qos=1)
            b = brokers.bridge
            creds = f"{b.username}:{b.password}@" if b.username else ""
            proc = subprocess.Popen(
                [sys.executable, "-m", "odocan", "bridge", "--name", ROBOT,
                 "--broker", f"mqtt://{creds}{b.host}:{b.port}", "-i", "virtual",
                 "-c", f"test-will-{os.getpid()}"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )
            try:
                got = await collect(sub, lambda g: g[-1][1]["state"] == "online", 20)
                proc.send_signal(signal.SIGKILL)
                got += await collect(sub, lambda g: g[-1][1]["state"] == "offline", 20)
            finally:
                proc.kill()
                proc.wait()
            return [payload for _, payload in got]

    statuses = asyncio.run(scenario())
    assert statuses[-1]["state"] == "offline"
    assert statuses[-1]["reason"] == "connection lost"


# --- a bridge that never starves (#13.4) and that no input stops (#10) ------------------------
def rig_ticks(seconds: float, seed: int = 11) -> list[list[can.Message]]:
    """A lockstep run's frames, one list per 10 ms tick (what a live bus delivers per tick)."""
    ticks: dict[int, list[can.Message]] = {}

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            ticks.setdefault(round(msg.timestamp * 100), []).append(msg)

    config = RigConfig(robot=PMIR, seed=seed, channel=f"test-mqtt-ticks-{next(_channels)}")
    with LockstepRig(config, [Keep()]) as rig:
        rig.run(seconds)
    return [ticks[k] for k in sorted(ticks)]


async def feed_frames(bridge: Bridge, ticks: list[list[can.Message]], done: asyncio.Event,
                      offered: list[tuple[float, float]] | None = None) -> None:
    """Offer one tick of frames every 10 ms (the bus's pace) until ``done``, round and round;
    timestamps keep increasing so the telemetry's publish rate applies. ``offered``, when given,
    gets (wall clock unix s, bus time s) of every tick offered: a loaded machine offers fewer
    than 100 a second."""
    period_s, offset_s = 0.01, 0.0
    while not done.is_set():
        for frames in ticks:
            shifted = [_shifted(m, offset_s) for m in frames]
            bridge.offer([(0, m) for m in shifted])
            if offered is not None and shifted:
                offered.append((time.time(), shifted[-1].timestamp))
            await asyncio.sleep(period_s)  # pacing only
            if done.is_set():
                return
        offset_s += len(ticks) * period_s


def _shifted(msg: can.Message, offset_s: float) -> can.Message:
    return can.Message(timestamp=msg.timestamp + offset_s, arbitration_id=msg.arbitration_id,
                       is_extended_id=False, data=msg.data)


# aiomqtt's bound on each of the flood's PUBACKs (its 10 s default: a loaded machine's 1 000
# QoS-1 publications at once took longer, "Operation timed out"; a bound, not a timing check)
FLOOD_PUBACK_S = 60.0


@pytest.mark.parametrize("kind", BROKERS)
def test_poses_keep_flowing_during_a_command_flood(kind: str, tmp_path: Path) -> None:
    """1 000 QoS-1 commands at once: their results wait for PUBACKs, the poses must not."""
    ticks = rig_ticks(2.0)
    flood = 1000

    async def scenario() -> tuple[list[float], list[float]]:
        async with broker_of(kind, tmp_path) as brokers, running_bridge(brokers.bridge) as (
            bridge, _
        ), client(brokers.operator, timeout=FLOOD_PUBACK_S) as sub:
            await sub.subscribe(topics.topic(ROBOT, "pose"), qos=0)
            await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
            done = asyncio.Event()
            feeder = asyncio.create_task(feed_frames(bridge, ticks, done, offered))
            await collect(sub, lambda g: sum(t.endswith("/pose") for t, _ in g) >= 3)
            good = b'{"x_m": 1, "y_m": 1, "heading_rad": 0}'
            await asyncio.gather(*(sub.publish(topics.topic(ROBOT, "cmd/set_pose"), good, qos=1)
                                   for _ in range(flood)))
            got = await collect(sub, lambda g: sum(t.endswith("/result") for t, _ in g) >= flood,
                                timeout_s=60)
            done.set()
            await feeder
        results = [p["unix_s"] for t, p in got if t.endswith("/result")]
        poses = [p["unix_s"] for t, p in got if t.endswith("/pose")]
        return results, poses

    offered: list[tuple[float, float]] = []
    results, poses = asyncio.run(scenario())
    during = [t for t in poses if results[0] <= t <= results[-1]]
    # 10 poses are due a second of BUS time (publish_hz): as many as the frames offered while
    # results were owed allow (a loaded machine offers fewer than 100 ticks a wall second:
    # wall-clock terms failed it, 8 poses for 9 due); with the old shared queue not one came
    bus_s = [bus for unix, bus in offered if results[0] <= unix <= results[-1]]
    span_s = bus_s[-1] - bus_s[0] if len(bus_s) > 1 else 0.0
    assert len(during) >= max(2, int(span_s * 10 * 0.5)), (len(during), span_s)


def test_every_command_the_broker_accepted_is_answered_across_a_broker_restart(
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    """An operator with a persistent MQTT v5 session sends commands before and after mosquitto
    restarts (SIGTERM: it saves its state); each one the broker acknowledged gets its answer on
    cmd/result (at least once)."""
    _every_acknowledged_command_is_answered(mosquitto, mosquitto.stop)


def test_every_command_the_broker_accepted_is_answered_across_a_broker_killed_with_9(
    durable_mosquitto: Mosquitto,  # noqa: F811
) -> None:
    """The same with mosquitto killed with -9 while answers are owed (the operator is away: its
    results wait in its session, or in the bridge). 1-2 of the 80 used to be lost, for two
    reasons: aiomqtt's message iterator drops a command it took off the queue when the bridge's
    session ends (fixed: ``RobotLink._next_message``), and a broker that saves only at exit comes
    back without the operator's session, so the results re-sent to it go to no one. A broker
    that must survive -9 saves at every change (docs/mqtt.md). It still acknowledges a command
    before it saves it, so the kill comes once it had time to save (``settle_s``): what it
    acknowledged is then its to keep, and every answer must arrive."""

    def kill() -> None:
        assert durable_mosquitto.proc is not None
        durable_mosquitto.proc.kill()
        durable_mosquitto.proc.wait()
        durable_mosquitto.proc = None

    _every_acknowledged_command_is_answered(durable_mosquitto, kill, settle_s=0.5)


class _Results:
    """What an operator heard on cmd/result: command id -> its results, in order."""

    def __init__(self) -> None:
        self.answers: dict[int, list[str]] = {}

    def keep(self, message: aiomqtt.Message) -> None:
        answer = json.loads(message.payload)
        self.answers.setdefault(answer["id"], []).append(answer["result"])

    async def listen(self, sub: aiomqtt.Client) -> None:
        with contextlib.suppress(aiomqtt.MqttError):
            async for message in sub.messages:
                self.keep(message)
        while not sub._queue.empty():  # received (and acknowledged) before the connection broke
            self.keep(sub._queue.get_nowait())


def _operator(broker: Mosquitto) -> aiomqtt.Client:
    """Robot001's operator with a persistent MQTT v5 session (300 s)."""
    from paho.mqtt.packettypes import PacketTypes
    from paho.mqtt.properties import Properties

    props = Properties(PacketTypes.CONNECT)
    props.SessionExpiryInterval = 300
    return client(broker.url(ROBOT), identifier=f"test-operator-{os.getpid()}",
                  protocol=aiomqtt.ProtocolVersion.V5, clean_start=False, properties=props)


async def _send_commands(sub: aiomqtt.Client, ids: range, accepted: list[int]) -> None:
    """``set_pose`` commands ``ids`` all at once (QoS 1, 30 s expiry); each id the broker
    acknowledged (PUBACK) goes into ``accepted``."""
    from paho.mqtt.packettypes import PacketTypes
    from paho.mqtt.properties import Properties

    expiry = Properties(PacketTypes.PUBLISH)
    expiry.MessageExpiryInterval = 30

    async def one(k: int) -> None:
        payload = json.dumps({"id": k, "x_m": k / 10, "y_m": 0, "heading_rad": 0}).encode()
        await sub.publish(topics.topic(ROBOT, "cmd/set_pose"), payload, qos=1,
                          properties=expiry)
        accepted.append(k)

    await asyncio.gather(*(one(k) for k in ids))  # all at once: answers are owed at the end


def _every_acknowledged_command_is_answered(
    broker: Mosquitto, stop_broker: Callable[[], None], settle_s: float = 0.0
) -> None:
    """40 commands at once, ``stop_broker()`` with answers owed, the broker started again, 40
    more: every command the broker acknowledged (PUBACK) is answered "accepted" or "expired".
    ``settle_s`` > 0: the operator leaves after its 40 and the broker stops that much later."""
    heard = _Results()
    answers, listen, operator, send = heard.answers, heard.listen, _operator, _send_commands

    async def scenario() -> list[int]:
        accepted: list[int] = []
        async with running_bridge(broker.url("bridge"), command_expiry_s=30) as (bridge, _):
            async with operator(broker) as sub:
                await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
                reader = asyncio.create_task(listen(sub))
                await send(sub, range(0, 40), accepted)
                if not settle_s:
                    stop_broker()  # with answers owed: queued in the bridge, in flight, or not
                owed = set(accepted) - set(answers)  # even delivered to the bridge yet
            await reader
            if settle_s:
                await asyncio.sleep(settle_s)
                stop_broker()
            broker.start()
            async with asyncio.timeout(20):
                while bridge.links[0].connects < 2:
                    await asyncio.sleep(0.05)
            async with operator(broker) as sub:  # the same session: results queued meanwhile
                reader = asyncio.create_task(listen(sub))
                await send(sub, range(40, 80), accepted)
                with contextlib.suppress(TimeoutError):  # the assertion below names the missing
                    async with asyncio.timeout(30):
                        while not set(accepted) <= set(answers):
                            await asyncio.sleep(0.05)
                reader.cancel()
        assert owed, "every answer came before the broker stopped: the restart proved nothing"
        assert bridge.links[0].sessions_lost == 0  # the broker kept the sessions: nothing lost
        return accepted

    accepted = asyncio.run(scenario())
    assert sorted(accepted) == list(range(80))
    assert set(accepted) - set(answers) == set()
    # no firmware on the bus: a command run ends ``timeout`` 2 s later, if the test is still there
    assert all(set(results) <= {"accepted", "expired", "timeout"}
               for results in answers.values()), answers


def test_no_stale_telemetry_is_replayed_after_an_outage(mosquitto: Mosquitto) -> None:  # noqa: F811
    ticks = rig_ticks(2.0)

    async def scenario() -> tuple[float, list[float], int]:
        url = mosquitto.url("bridge")
        async with running_bridge(url) as (bridge, _):
            done = asyncio.Event()
            feeder = asyncio.create_task(feed_frames(bridge, ticks, done))
            mosquitto.stop()
            await asyncio.sleep(1.0)  # the outage: poses keep being made, none may be kept
            back = time.time()
            mosquitto.start()
            async with asyncio.timeout(20):
                while not bridge.links[0].connected.is_set():
                    await asyncio.sleep(0.02)
            async with client(url) as sub:
                await sub.subscribe(topics.topic(ROBOT, "pose"), qos=0)
                got = await collect(sub, lambda g: len(g) >= 10)
            done.set()
            await feeder
            return back, [p["unix_s"] for _, p in got], bridge.links[0].telemetry_offline

    back, stamps, offline = asyncio.run(scenario())
    assert offline > 0  # poses were made during the outage ...
    assert min(stamps) >= back  # ... and none of them was published afterwards


@pytest.mark.parametrize("kind", BROKERS)
def test_a_cancelled_bridge_publishes_offline_first(kind: str, tmp_path: Path) -> None:
    async def scenario() -> list[dict[str, Any]]:
        async with broker_of(kind, tmp_path) as brokers, client(brokers.operator) as sub:
            await sub.subscribe(topics.topic(ROBOT, "status"), qos=1)
            with can.Bus(interface="virtual", channel=f"test-cancel-{next(_channels)}") as bus:
                endpoint = RobotEndpoint(ROBOT, bus, GEOMETRY, counter_bits=PMIR.counter_bits)
                bridge = Bridge([endpoint],
                                config=BridgeConfig(broker=brokers.bridge,
                                                    client_prefix=f"test-cancel-{kind}"))
                task = asyncio.create_task(bridge.run(stop=asyncio.Event()))
                got = await collect(sub, lambda g: g[-1][1]["state"] == "online")
                task.cancel()  # not a clean stop: an error elsewhere, a TaskGroup shutting down
                with contextlib.suppress(asyncio.CancelledError):
                    await task
                got += await collect(sub, lambda g: g[-1][1]["state"] == "offline")
            return [p for _, p in got]

    statuses = asyncio.run(scenario())
    assert statuses[-1]["reason"] == "bridge stopped"  # its own, not the broker's last will


@pytest.mark.parametrize("kind", BROKERS)
def test_hostile_payloads_through_a_real_broker_are_each_answered(
    kind: str, tmp_path: Path
) -> None:
    from tests.test_mqtt_robustness import _payload

    rng = random.Random(7)
    payloads = [_payload(rng) for _ in range(1000)]
    ticks = rig_ticks(1.0)

    async def scenario() -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        # no firmware answers here: the accepted commands' final answers (timeout, expired:
        # host.mqtt.pacing) are not this test's subject, and come after its 1000 answers
        async with broker_of(kind, tmp_path) as brokers, running_bridge(
            brokers.bridge, command_ack_timeout_s=600.0, command_expiry_s=600.0
        ) as (bridge, _):
            results = await command_results(
                brokers.operator, [("set_pose", p) for p in payloads], len(payloads))
            async with client(brokers.operator) as sub:
                await sub.subscribe(topics.topic(ROBOT, "pose"), qos=0)
                done = asyncio.Event()
                feeder = asyncio.create_task(feed_frames(bridge, ticks, done))
                poses = await collect(sub, lambda g: len(g) >= 3)
                done.set()
                await feeder
            assert bridge.robots[0].commands_failed == 0
        return results, [p for _, p in poses]

    results, poses = asyncio.run(scenario())
    assert len(results) == len(payloads)
    assert {r["result"] for r in results} <= {"accepted", "rejected"}
    assert len(poses) == 3  # and the bridge still publishes poses


@pytest.mark.parametrize("kind", BROKERS)
def test_a_command_older_than_the_expiry_is_answered_expired(kind: str, tmp_path: Path) -> None:
    async def scenario() -> list[dict[str, Any]]:
        async with broker_of(kind, tmp_path) as brokers, running_bridge(
            brokers.bridge, command_expiry_s=1e-9
        ) as (_, listener):
            good = b'{"id": "old", "x_m": 1, "y_m": 1, "heading_rad": 0}'
            results = await command_results(brokers.operator, [("set_pose", good)], 1)
            await asyncio.sleep(0.2)  # a frame sent anyway would be on the listener by now
            assert bus_frames(listener) == []
            return results

    (result,) = asyncio.run(scenario())
    assert (result["id"], result["result"]) == ("old", "expired")


@pytest.mark.parametrize("kind", BROKERS)
def test_a_retained_command_is_not_run(kind: str, tmp_path: Path) -> None:
    """A command someone published with retain would run at every reconnect, at any age."""

    async def scenario() -> list[dict[str, Any]]:
        async with broker_of(kind, tmp_path) as brokers, client(brokers.operator) as sub:
            await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
            old = b'{"id": "kept", "x_m": 1, "y_m": 1, "heading_rad": 0}'
            await sub.publish(topics.topic(ROBOT, "cmd/set_pose"), old, qos=1, retain=True)
            async with running_bridge(brokers.bridge) as (_, listener):
                got = await collect(sub, lambda g: len(g) >= 1)
                await asyncio.sleep(0.2)  # a frame sent anyway would be on the listener by now
                assert bus_frames(listener) == []
            return [payload for _, payload in got]

    (result,) = asyncio.run(scenario())
    assert (result["id"], result["result"]) == ("kept", "rejected")
    assert "retained" in result["reason"]


def test_a_broker_that_lost_its_state_is_reported(
    mosquitto: Mosquitto, caplog: pytest.LogCaptureFixture  # noqa: F811
) -> None:
    """mosquitto killed with -9 before it ever saved: our session is gone when we are back."""

    async def scenario() -> int:
        async with running_bridge(mosquitto.url("bridge"), command_expiry_s=30) as (bridge, _):
            assert mosquitto.proc is not None
            mosquitto.proc.kill()
            mosquitto.proc.wait()
            mosquitto.proc = None
            mosquitto.start()
            async with asyncio.timeout(20):
                while bridge.links[0].connects < 2:
                    await asyncio.sleep(0.05)
            return bridge.links[0].sessions_lost

    logger = logging.getLogger("odocan.mqtt")  # its parent may not propagate (the CLI's setup)
    logger.addHandler(caplog.handler)
    try:
        assert asyncio.run(scenario()) == 1
    finally:
        logger.removeHandler(caplog.handler)
    assert any("the broker no longer had this bridge's session" in r.getMessage()
               and "restarted without its persistence" in r.getMessage() for r in caplog.records)
