"""Wait, from outside, until an ``odocan fleet`` process judged a pose of every robot.

A test that signalled the fleet a fixed second after its start line checked a "partial run PASS"
that needs judged poses: on a loaded machine the workers stalled 1.4 s at their first ticks,
the SIGTERM came before any pose was paired with its reference, and each robot FAILed "no
on-board pose paired with the reference" (made exactly: the workers SIGSTOPped 1.4 s at the
start line, then the SIGTERM). Here the test waits for each robot's first ``error`` publication
(an on-board pose compared with the reference of its encoder frame: a judged sample) on the
fleet's own broker, ``BOUND_S`` at most.
"""

from __future__ import annotations

import asyncio
import re
import subprocess

import aiomqtt
import pytest

from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import BrokerURL

BOUND_S = 60.0
URL = re.compile(r"telemetry on (mqtts?://\S+?)[;,]?(\s|$)")


def url_of(start_line: str) -> BrokerURL:
    """The broker URL the fleet's start line names."""
    found = URL.search(start_line)
    assert found, start_line
    return BrokerURL.parse(found.group(1))


def wait_until_judged(proc: subprocess.Popen[str], start_line: str, robots: list[str]) -> None:
    """Until each of ``robots`` published its first ``error`` (``BOUND_S`` at most; a test
    failure, the fleet killed, when not)."""

    async def watch() -> set[str]:
        seen: set[str] = set()
        async with aiomqtt.Client(**url_of(start_line).client_kwargs()) as sub:
            await sub.subscribe(topics.topic("+", "error"), qos=0)
            async with asyncio.timeout(BOUND_S):
                async for message in sub.messages:
                    seen.add(message.topic.value.split("/")[1])
                    if seen >= set(robots):
                        break
        return seen

    try:
        asyncio.run(watch())
    except (TimeoutError, aiomqtt.MqttError) as exc:
        proc.kill()
        pytest.fail(f"no judged pose of every robot within {BOUND_S:g} s ({exc!r}): "
                    f"{proc.communicate()}")
