"""A flood of commands does not hold the bridge's event loop: poses and keepalive go on (#13.4).

Found by the last pass: 1 500 ``set_pose`` at once starved the telemetry (no pose for 7.4 s of
CPU, the MQTT keepalive missed). The bridge's MQTT client reads every packet the socket holds in
one readable event (``host.mqtt.client.LinkClient._read_all``), so a flood lands in its queue
hundreds at a time, and the link handled them all in one loop turn (measured here before the
fix: 909 commands in one turn, each validated, encoded and paced). Counted here, never timed: a
task that counts the loop's turns, and the commands the link runs in each; real mosquitto, an
aiomqtt operator, the bridge fed a lockstep drive's frames at the bus's pace.
"""

from __future__ import annotations

import asyncio
from collections import Counter
from typing import Any

from odocan.host.mqtt import topics
from odocan.host.mqtt.link import COMMANDS_PER_TURN
from tests.conftest_mqtt import Mosquitto, client, collect, mosquitto  # noqa: F401 (fixture)
from tests.test_mqtt_bridge import ROBOT, feed_frames, rig_ticks, running_bridge

FLOOD = 1500


def test_a_flood_of_commands_is_handled_a_few_a_loop_turn_and_poses_go_on(
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    ticks = rig_ticks(2.0)

    async def scenario() -> tuple[Counter[int], list[int]]:
        run_per_turn: Counter[int] = Counter()  # loop turn -> commands run in it
        pose_turns: list[int] = []  # the loop turn of each pose the bridge published
        turn = 0

        async def count_turns(stop: asyncio.Event) -> None:
            nonlocal turn
            while not stop.is_set():
                turn += 1
                await asyncio.sleep(0)

        url = mosquitto.url("bridge")
        async with running_bridge(url, command_expiry_s=600.0) as (bridge, _), \
                client(mosquitto.url(ROBOT)) as sub:
            link = bridge.links[0]
            on_command, publish = link.on_command, link.publish

            def counted(name: str, payload: bytes, verdict: Any = "run") -> Any:
                run_per_turn[turn] += verdict == "run"
                return on_command(name, payload, verdict)

            def published(leaf: str, payload: dict[str, Any]) -> None:
                if leaf == "pose":
                    pose_turns.append(turn)
                publish(leaf, payload)

            link.on_command, link.publish = counted, published  # type: ignore[method-assign]
            await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
            done, stop = asyncio.Event(), asyncio.Event()
            feeder = asyncio.create_task(feed_frames(bridge, ticks, done))
            turns = asyncio.create_task(count_turns(stop))
            good = b'{"x_m": 1, "y_m": 1, "heading_rad": 0}'
            await asyncio.gather(*(sub.publish(topics.topic(ROBOT, "cmd/set_pose"), good, qos=1)
                                   for _ in range(FLOOD)))
            await collect(sub, lambda g: len(g) >= FLOOD, timeout_s=60)  # each answered once
            stop.set()
            done.set()
            await asyncio.gather(feeder, turns)
        return run_per_turn, pose_turns

    run_per_turn, pose_turns = asyncio.run(scenario())
    ran = sorted(t for t, n in run_per_turn.items() if n)
    assert sum(run_per_turn.values()) > COMMANDS_PER_TURN * 10  # a flood did arrive to be run
    assert max(run_per_turn.values()) <= COMMANDS_PER_TURN, run_per_turn.most_common(3)
    during = [t for t in pose_turns if ran[0] <= t <= ran[-1]]
    assert len(during) > 0, (len(pose_turns), ran[0], ran[-1])  # poses went on meanwhile
