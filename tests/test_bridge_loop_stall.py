"""A bridge whose event loop stalled says so: commands a broker held for it may be lost.

Measured with a 1 500 ``set_pose`` flood on mosquitto (issue #13.4; ``host.mqtt.stallwatch``):
with the bridge's loop blocked 6 s, 1 020 of 1 500 commands were answered and mosquitto logged
"Outgoing messages are being dropped for client <the bridge>"; the bridge answered every command
it received, and had no count, line or field saying it had not read for 6 s. Now a loop turn
that comes a second or more late while connected is counted (``loop_stalls``,
``loop_stalled_ms``) and said once (a warning naming the command reader's queue, where commands
now wait: ``tests/test_bridge_cmd_stall.py``). Real brokers.
"""

from __future__ import annotations

import asyncio
import logging
import time
from pathlib import Path

import pytest

from odocan.host.mqtt.stallwatch import STALL_S
from tests.conftest_mqtt import broker_of
from tests.test_mqtt_bridge import BROKERS, running_bridge


@pytest.mark.parametrize("kind", BROKERS)
def test_a_stalled_bridge_loop_is_counted_and_said(
    kind: str, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    async def scenario() -> dict[str, int]:
        async with broker_of(kind, tmp_path) as brokers, \
                running_bridge(brokers.bridge) as (bridge, _):
            await asyncio.sleep(0.3)
            time.sleep(STALL_S + 0.5)  # the loop blocked (a fleet's tick, a GC pause, a host)
            await asyncio.sleep(0.3)
            return dict(bridge.counters())

    with caplog.at_level(logging.WARNING, logger="odocan.mqtt"):
        counters = asyncio.run(scenario())
    assert counters["loop_stalls"] == 1, counters
    assert counters["loop_stalled_ms"] >= 1000 * STALL_S, counters
    said = [r.getMessage() for r in caplog.records if "event loop did not run" in r.getMessage()]
    assert len(said) == 1, said
    assert "command reader's queue" in said[0]
