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

from odocan.host.mqtt.stallwatch import STALL_S, WATCH_PERIOD_S
from tests.conftest_mqtt import broker_of
from tests.test_mqtt_bridge import BROKERS, running_bridge

BLOCK_S = STALL_S + 0.5  # the loop blocked this long: one stall, at least this minus a period


@pytest.mark.parametrize("kind", BROKERS)
def test_a_stalled_bridge_loop_is_counted_and_said(
    kind: str, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The block is one stall as long as it (a loaded machine may stall the loop more: those
    are counted too, and the line is said once all the same)."""
    seen: list[tuple[float, float]] = []  # (late s, monotonic s when counted) of every stall

    async def scenario() -> tuple[dict[str, int], float]:
        async with broker_of(kind, tmp_path) as brokers, \
                running_bridge(brokers.bridge) as (bridge, _):
            counted = bridge.stalls.stalled

            def spied(late_s: float, stopped: bool = False) -> None:
                seen.append((late_s, time.monotonic()))
                counted(late_s, stopped)

            bridge.stalls.stalled = spied  # type: ignore[method-assign]
            await asyncio.sleep(0.3)
            time.sleep(BLOCK_S)  # the loop blocked (a fleet's tick, a GC pause, a host)
            resumed_s = time.monotonic()
            await asyncio.sleep(0.3)
            return dict(bridge.counters()), resumed_s

    with caplog.at_level(logging.WARNING, logger="odocan.mqtt"):
        counters, resumed_s = asyncio.run(scenario())
    # the watch's first wake after the block is late by the block (less one period at most)
    after = [late_s for late_s, at_s in seen if at_s >= resumed_s]
    assert after, (resumed_s, seen)
    assert after[0] >= BLOCK_S - WATCH_PERIOD_S, (resumed_s, seen)
    assert counters["loop_stalls"] >= len(seen) >= 1, counters  # (any before the spy: counted)
    assert counters["loop_stalled_ms"] >= 1000 * (BLOCK_S - WATCH_PERIOD_S), counters
    said = [r.getMessage() for r in caplog.records if "event loop did not run" in r.getMessage()]
    assert len(said) == 1, said  # said once, however many stalls
    assert "command reader's queue" in said[0]
