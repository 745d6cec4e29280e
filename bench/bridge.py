"""The bridge under stress (#13.4): poses during a command flood, stale telemetry after an outage.

One robot's lockstep frames are offered to the bridge at the bus's pace (100 frames-ticks/s) while

* ``flood``: an operator publishes 1 000 ``set_pose`` commands at QoS 1 at once; printed: the
  poses received per second while their results were owed (10/s are due), the last result's delay;
* ``outage`` (mosquitto only): the broker is stopped for 2 s and started again; printed: poses
  made during the outage that were published after it (stale: must be 0), poses not kept, time
  from the broker's start to the bridge's next pose;
* ``restart``/``killed`` (mosquitto only): an operator with a persistent v5 session sends 40
  commands, the broker is stopped (SIGTERM) or killed (SIGKILL) and started, 40 more: how many of
  the commands the broker acknowledged were answered on ``cmd/result``; killed twice: a mosquitto
  saving only at exit (it loses the operator's session) and one saving at every change.

    .venv/bin/python bench/bridge.py [--flood 1000]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import getpass
import json
import logging
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import aiomqtt
import can
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import topics
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import LOOPBACK, BrokerURL, EmbeddedBroker, free_loopback_port
from odocan.sim import robot
from odocan.sim.rig import LockstepRig, RigConfig

ROBOT = "robot001"
PMIR = robot.load("pmir")


class Mosquitto:
    """An anonymous mosquitto on a fixed free port, restartable (None when not installed)."""

    def __init__(self, workdir: Path, durable: bool = False) -> None:
        """``durable``: save the state at every change (``autosave_on_changes``), not at exit."""
        self.exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        self.url = BrokerURL(host=LOOPBACK, port=free_loopback_port())
        self.conf = workdir / "bench.conf"
        self.conf.write_text(f"listener {self.url.port} {LOOPBACK}\nallow_anonymous true\n"
                             f"persistence true\npersistence_location {workdir}/\nlog_dest none\n"
                             + ("autosave_on_changes true\nautosave_interval 1\n" if durable
                                else "")
                             + f"user {getpass.getuser()}\n")  # as root: keep access to workdir
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen([self.exe, "-c", str(self.conf)],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(0.3)

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.terminate()
            self.proc.wait(10)
            self.proc = None


def ticks_of(seconds: float) -> list[list[can.Message]]:
    """A lockstep drive's frames, one list per 10 ms tick."""
    ticks: dict[int, list[can.Message]] = {}

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            ticks.setdefault(round(msg.timestamp * 100), []).append(msg)

    with LockstepRig(RigConfig(robot=PMIR, seed=3, channel=f"bench-bridge-{os.getpid()}"),
                     [Keep()]) as rig:
        rig.run(seconds)
    return [ticks[k] for k in sorted(ticks)]


async def feed(bridge: Bridge, ticks: list[list[can.Message]], stop: asyncio.Event) -> None:
    """One tick of frames every 10 ms, round and round, with increasing timestamps."""
    offset_s = 0.0
    while not stop.is_set():
        for frames in ticks:
            bridge.offer([(0, can.Message(timestamp=m.timestamp + offset_s,
                                          arbitration_id=m.arbitration_id,
                                          is_extended_id=False, data=m.data)) for m in frames])
            await asyncio.sleep(0.01)
            if stop.is_set():
                return
        offset_s += len(ticks) * 0.01


@asynccontextmanager
async def bridged(url: BrokerURL, ticks: list[list[can.Message]]) -> AsyncIterator[Bridge]:
    with can.Bus(interface="virtual", channel=f"bench-bridge-cmd-{time.time_ns()}") as bus:
        endpoint = RobotEndpoint(ROBOT, bus, Geometry.of(PMIR), counter_bits=PMIR.counter_bits)
        bridge = Bridge([endpoint], config=BridgeConfig(
            broker=url, client_prefix=f"bench-{time.time_ns()}"))
        stop = asyncio.Event()
        task = asyncio.create_task(bridge.run(stop=stop))
        await bridge.links[0].connected.wait()
        feeder = asyncio.create_task(feed(bridge, ticks, stop))
        try:
            yield bridge
        finally:
            stop.set()
            await feeder
            await task


async def flood(url: BrokerURL, ticks: list[list[can.Message]], n: int) -> str:
    async with bridged(url, ticks), aiomqtt.Client(**url.client_kwargs()) as sub:
        await sub.subscribe(topics.topic(ROBOT, "pose"), qos=0)
        await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
        await asyncio.sleep(0.5)
        body = b'{"x_m": 1, "y_m": 1, "heading_rad": 0}'
        t0 = time.time()
        await asyncio.gather(*(sub.publish(topics.topic(ROBOT, "cmd/set_pose"), body, qos=1)
                               for _ in range(n)))
        results: list[float] = []
        poses: list[float] = []
        async with asyncio.timeout(120):
            async for message in sub.messages:
                stamp = json.loads(message.payload)["unix_s"]  # type: ignore[arg-type]
                (results if message.topic.value.endswith("result") else poses).append(stamp)
                if len(results) >= n:
                    break
    span_s = max(results) - min(results)
    during = sum(min(results) <= t <= max(results) for t in poses)
    return (f"{n} results over {span_s:.2f} s (last {max(results) - t0:.2f} s after the flood "
            f"began); poses meanwhile {during} = {during / max(span_s, 1e-9):.1f}/s (10/s due)")


async def outage(broker: Mosquitto, ticks: list[list[can.Message]]) -> str:
    async with bridged(broker.url, ticks) as bridge:
        broker.stop()
        t_down = time.time()
        await asyncio.sleep(2.0)
        t_up = time.time()
        broker.start()
        async with asyncio.timeout(30):
            while not bridge.links[0].connected.is_set():
                await asyncio.sleep(0.01)
        async with aiomqtt.Client(**broker.url.client_kwargs()) as sub:
            await sub.subscribe(topics.topic(ROBOT, "pose"), qos=0)
            stamps: list[float] = []
            async with asyncio.timeout(30):
                async for message in sub.messages:
                    stamps.append(json.loads(message.payload)["unix_s"])  # type: ignore[arg-type]
                    if len(stamps) >= 20:
                        break
        stale = sum(t_down <= t < t_up for t in stamps)
        return (f"stale poses published after the outage {stale} of the first {len(stamps)}; "
                f"poses not kept while away {bridge.links[0].telemetry_offline}; first pose "
                f"{min(stamps) - t_up:.2f} s after the broker's start")


def operator(url: BrokerURL, name: str) -> aiomqtt.Client:
    """An operator with a persistent MQTT v5 session (results queue for it while it is away)."""
    props = Properties(PacketTypes.CONNECT)  # type: ignore[no-untyped-call]
    props.SessionExpiryInterval = 300
    return aiomqtt.Client(**url.client_kwargs(), identifier=f"bench-{name}-{os.getpid()}",
                          protocol=aiomqtt.ProtocolVersion.V5, clean_start=False,
                          properties=props)


async def answered(broker: Mosquitto, ticks: list[list[can.Message]], kill: bool) -> str:
    """40 commands, the broker restarted (``kill``: SIGKILL), 40 more: how many of those the
    broker acknowledged were answered within 10 s."""
    answers: set[int] = set()
    acked: list[int] = []

    async def listen(sub: aiomqtt.Client) -> None:
        with contextlib.suppress(aiomqtt.MqttError):
            async for message in sub.messages:
                answers.add(json.loads(message.payload)["id"])  # type: ignore[arg-type]
        while not sub._queue.empty():  # received and acknowledged before the connection broke
            answers.add(json.loads(sub._queue.get_nowait().payload)["id"])  # type: ignore[arg-type]

    async def send(sub: aiomqtt.Client, ids: range) -> None:
        with contextlib.suppress(aiomqtt.MqttError):
            for k in ids:
                body = json.dumps({"id": k, "x_m": 0, "y_m": 0, "heading_rad": 0}).encode()
                await sub.publish(topics.topic(ROBOT, "cmd/set_pose"), body, qos=1)
                acked.append(k)

    async with bridged(broker.url, ticks) as bridge:
        async with operator(broker.url, "killed" if kill else "restart") as sub:
            await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
            reader = asyncio.create_task(listen(sub))
            await send(sub, range(40))
            if kill and broker.proc is not None:
                broker.proc.kill()
                broker.proc.wait()
                broker.proc = None
            else:
                broker.stop()
            await reader
        broker.start()
        async with asyncio.timeout(30):
            while bridge.links[0].connects < 2:
                await asyncio.sleep(0.05)
        async with operator(broker.url, "killed" if kill else "restart") as sub:
            await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
            reader = asyncio.create_task(listen(sub))
            await send(sub, range(40, 80))
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(10):
                    while not set(acked) <= answers:
                        await asyncio.sleep(0.05)
            reader.cancel()
    lost = sorted(set(acked) - answers)
    return f"{len(set(acked) & answers)} of {len(acked)} acknowledged commands answered " \
           f"(unanswered: {lost[:10]}{' ...' if len(lost) > 10 else ''})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flood", type=int, default=1000)
    args = parser.parse_args()
    logging.getLogger("mqtt").setLevel(logging.ERROR)  # the operator's aiomqtt: 1 000 waits
    ticks = ticks_of(5.0)
    print(f"bridge bench: load {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory() as tmp:
        mosquitto = Mosquitto(Path(tmp)) if Path(Mosquitto(Path(tmp)).exe).exists() else None
        if mosquitto is not None:
            mosquitto.start()
            try:
                print("mosquitto flood: " + asyncio.run(flood(mosquitto.url, ticks, args.flood)))
                print("mosquitto outage: " + asyncio.run(outage(mosquitto, ticks)))
                print("mosquitto restart (SIGTERM): "
                      + asyncio.run(answered(mosquitto, ticks, kill=False)))
                print("mosquitto killed (SIGKILL), saving only at exit: "
                      + asyncio.run(answered(mosquitto, ticks, kill=True)))
            finally:
                mosquitto.stop()
        (Path(tmp) / "durable").mkdir()
        durable = Mosquitto(Path(tmp) / "durable", durable=True) if mosquitto else None
        if durable is not None:
            durable.start()
            try:
                print("mosquitto killed (SIGKILL), saving at every change: "
                      + asyncio.run(answered(durable, ticks, kill=True)))
            finally:
                durable.stop()

    async def embedded() -> str:
        async with EmbeddedBroker() as broker:
            return await flood(broker.url, ticks, args.flood)

    print("embedded amqtt flood: " + asyncio.run(embedded()))


if __name__ == "__main__":
    main()
