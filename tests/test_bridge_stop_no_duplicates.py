"""A bridge stopping under a command flood answers each command once, not its in-flight answers
twice (issue #13.4: the bridge's command answers under a flood).

Found measuring a flood of ``set_pose`` on mosquitto: stopped while answers were still going
out, the bridge sent 19-20 commands' ``accepted`` twice (100 and 400 commands). The QoS-1 sender
hands the oldest ``inflight`` (20) publications to paho and waits for their PUBACKs; stopping
cancels that wait, and the goodbye (which flushes the QoS-1 buffer on the same connection)
published the same 20 again as new messages: not QoS 1's at-least-once (a DUP retransmission
after a lost connection, which the operator cannot tell from a new answer either), but a second
copy the broker had no reason to get. On the same connection the goodbye now waits for their
PUBACKs instead. Real brokers, an aiomqtt operator, no firmware on the bus: every command is
``accepted``, then ``aborted`` when the bridge stops (one read while it stops: ``aborted`` only).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from odocan.host.mqtt import topics
from tests.conftest_mqtt import broker_of, client
from tests.test_mqtt_bridge import BROKERS, ROBOT, running_bridge

COMMANDS = 200  # answers in flight when the bridge stops (their ``accepted``)
FINAL = {"acked", "nacked", "expired", "rejected", "timeout", "aborted"}


def _set_pose(k: int) -> bytes:
    return json.dumps({"id": k, "x_m": k / 10, "y_m": 0.0, "heading_rad": 0.0}).encode()


async def _answers(kind: str, tmp_path: Path) -> dict[int, list[str]]:
    """Each command's answers as the operator got them, the bridge stopped at once after the
    flood was acknowledged by the broker."""
    got: list[dict[str, Any]] = []
    async with broker_of(kind, tmp_path) as brokers, client(brokers.operator) as sub:
        await sub.subscribe(topics.topic(ROBOT, topics.RESULT_LEAF), qos=1)
        async with running_bridge(brokers.bridge, command_ack_timeout_s=600.0,
                                  command_expiry_s=600.0):
            await asyncio.gather(*(sub.publish(topics.topic(ROBOT, "cmd/set_pose"),
                                               _set_pose(k), qos=1) for k in range(COMMANDS)))
        with contextlib.suppress(TimeoutError):  # what came is kept: the asserts say the rest
            async with asyncio.timeout(10.0):
                async for message in sub.messages:
                    got.append(json.loads(message.payload))
                    finals = {p["id"] for p in got if p["result"] in FINAL}
                    if len(finals) >= COMMANDS:
                        break
            await asyncio.sleep(0.5)  # a late second copy would come now
            while True:  # what the broker still holds for us
                async with asyncio.timeout(0.5):
                    got.append(json.loads((await anext(sub.messages)).payload))
    answers: dict[int, list[str]] = {}
    for payload in got:
        answers.setdefault(payload["id"], []).append(payload["result"])
    return answers


@pytest.mark.parametrize("kind", BROKERS)
def test_a_bridge_stopped_under_a_flood_sends_each_answer_once(
    kind: str, tmp_path: Path
) -> None:
    answers = asyncio.run(_answers(kind, tmp_path))
    assert len(answers) > COMMANDS // 2  # the premise: the flood reached the bridge
    twice = {k: results for k, results in answers.items()
             if max(Counter(results).values()) > 1}
    assert not twice, f"{len(twice)} commands answered twice: {list(twice.items())[:3]}"
    for k, results in answers.items():  # (one that came while it stopped: ``aborted`` only)
        assert results[-1] in FINAL, (k, results)
        assert sum(r in FINAL for r in results) == 1, (k, results)
