"""Every command the bridge took gets its final answer, also when the bridge stops; the pacer's
counts are published (issue #13.4, the bridge's command remainders).

Found by the last pass: commands waiting in the pacer's queue (or in flight, their ODOM_ACK not
heard yet) when the bridge stopped were answered ``accepted`` and never again: their senders
waited for an end that never came. And the pacer's counts (queued, refused, timed out) were
nowhere in ``rates`` nor in the report. Real brokers, an aiomqtt operator, no firmware on the
bus (so nothing is ever ACKed: what the bridge does with the commands is all the pacer's).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from pathlib import Path
from typing import Any

import pytest

from odocan.host.mqtt import topics
from tests.conftest_mqtt import broker_of, client, collect
from tests.test_mqtt_bridge import BROKERS, ROBOT, running_bridge

FINAL = {"acked", "nacked", "expired", "rejected", "timeout", "aborted"}


def _set_pose(k: int) -> bytes:
    return json.dumps({"id": k, "x_m": k / 10, "y_m": 0.0, "heading_rad": 0.0}).encode()


def _finals(got: list[tuple[str, dict[str, Any]]]) -> set[int]:
    """The command ids with a final answer in ``got``."""
    return {p["id"] for _, p in got if p.get("result") in FINAL}


async def _listen(sub: Any, got: list[tuple[str, dict[str, Any]]], done: Any,
                  timeout_s: float = 5.0) -> None:
    """Messages into ``got`` until ``done()`` or ``timeout_s`` (what came is kept: the
    assertions name what is missing)."""
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(timeout_s):
            async for message in sub.messages:
                got.append((message.topic.value, json.loads(message.payload)))
                if done():
                    return


@pytest.mark.parametrize("kind", BROKERS)
def test_commands_still_queued_when_the_bridge_stops_are_answered_aborted(
    kind: str, tmp_path: Path
) -> None:
    commands = 10  # 4 frames each: 2 in the 8-frame window, 8 waiting in the queue

    async def scenario() -> dict[int, list[dict[str, Any]]]:
        async with broker_of(kind, tmp_path) as brokers, client(brokers.operator) as sub:
            await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
            got: list[tuple[str, dict[str, Any]]] = []
            async with running_bridge(brokers.bridge, command_ack_timeout_s=600.0,
                                      command_expiry_s=600.0):
                for k in range(commands):
                    await sub.publish(topics.topic(ROBOT, "cmd/set_pose"), _set_pose(k), qos=1)
                got += await collect(sub, lambda g: len(g) >= commands)
            # stopped: each command's final answer came before the bridge disconnected
            await _listen(sub, got, lambda: _finals(got) >= set(range(commands)))
        answers: dict[int, list[dict[str, Any]]] = {}
        for _, payload in got:
            answers.setdefault(payload["id"], []).append(payload)
        return answers

    answers = asyncio.run(scenario())
    assert sorted(answers) == list(range(commands))
    for k, results in answers.items():  # (QoS 1: an answer may come twice, at least once)
        assert results[0]["result"] == "accepted", results
        finals = {r["result"] for r in results if r["result"] in FINAL}
        assert finals == {"aborted"}, (k, results)
    reasons = [next(r["reason"] for r in answers[k] if r["result"] in FINAL)
               for k in range(commands)]
    assert reasons[:2] == ["the bridge stopped before its ODOM_ACK was heard: its outcome is "
                           "unknown"] * 2
    assert reasons[2:] == ["the bridge stopped before it was sent: not run"] * 8


def test_the_pacer_s_counts_are_in_rates_and_in_the_report(tmp_path: Path) -> None:
    """One command in the window, two queued, two refused (queue of 2); no firmware: the three
    taken time out one after the other. ``rates`` says so, and so does ``counters``."""

    async def scenario() -> tuple[dict[str, Any], dict[str, Any]]:
        async with broker_of("mosquitto", tmp_path) as brokers, client(brokers.operator) as sub:
            await sub.subscribe(topics.topic(ROBOT, "rates"), qos=0)
            await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
            async with running_bridge(
                brokers.bridge, command_window_frames=4, command_queue=2,
                command_ack_timeout_s=0.1, command_expiry_s=600.0, rates_period_s=0.1,
            ) as (bridge, _):
                for k in range(5):
                    await sub.publish(topics.topic(ROBOT, "cmd/set_pose"), _set_pose(k), qos=1)

                def settled(got: list[tuple[str, dict[str, Any]]]) -> bool:
                    pacing = got[-1][1].get("pacing", {}) if got[-1][0].endswith("rates") else {}
                    return pacing.get("commands_timeout") == 3

                got = await collect(sub, settled, timeout_s=10.0)
                return got[-1][1]["pacing"], bridge.counters()

    pacing, counters = asyncio.run(scenario())
    expected = {"commands_queued": 0, "command_frames_in_flight": 0, "commands_refused": 2,
                "commands_queue_expired": 0, "commands_timeout": 3, "commands_aborted": 0}
    assert pacing == expected
    assert {k: counters[k] for k in expected} == {**expected, "commands_aborted": 0}
