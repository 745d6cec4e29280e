"""A retained ``status`` is old news: ``odocan monitor --mqtt`` must not take its arrival for a
sign of life.

A robot that stopped long ago leaves its retained ``status`` on the broker. A monitor started
later receives it at once; the fleet view used to stamp the robot ``updated_unix_s = now``, so
``--json`` said ``age_s`` 0.0x and ``stale: false`` for a robot silent for minutes (and a hung
robot with a retained ``online`` looked alive for 3 s). The age of a retained message is the one
its payload states (``unix_s``, the publisher's wall clock), or unknown.
"""

from __future__ import annotations

import asyncio
import io
import json
import time

import aiomqtt
import pytest
from rich.console import Console

from odocan.host.cli.app import main
from odocan.host.mqtt import topics
from odocan.host.mqtt.fleetview import RobotState, apply
from odocan.host.mqtt.shards import embedded_broker
from odocan.host.report.live import render_fleet, with_staleness
from tests.fleet_watch_until import BOUND_S, end_watch_once

AGO_S = 600.0


def test_a_retained_status_keeps_the_age_its_payload_states() -> None:
    table: dict[str, RobotState] = {}
    then = time.time() - AGO_S
    payload = json.dumps({"robot": "robot001", "state": "offline", "unix_s": then}).encode()
    assert apply(table, "odocan/robot001/status", payload, retained=True)
    assert table["robot001"].updated_unix_s == then
    assert not table["robot001"].online


def test_a_retained_status_without_a_time_is_never_heard_live() -> None:
    table: dict[str, RobotState] = {}
    assert apply(table, "odocan/robot001/status", b'{"state": "online"}', retained=True)
    assert table["robot001"].updated_unix_s == 0.0
    huge = b'{"state": "online", "unix_s": 1' + b"0" * 400 + b"}"  # an int beyond every float
    for bad in (b'{"state": "online", "unix_s": "x"}', b'{"state": "online", "unix_s": 1e999}',
                huge):
        assert apply(table, "odocan/robot001/status", bad, retained=True)
        assert table["robot001"].updated_unix_s == 0.0
    # a live message (not retained) is heard now
    assert apply(table, "odocan/robot001/pose", b'{"x_m": 1.0}')
    assert abs(table["robot001"].updated_unix_s - time.time()) < 5.0


def test_a_robot_never_heard_live_is_shown_stale_without_an_age() -> None:
    row = {"online": True, "pose": None, "error": None, "status": None, "rate_hz": None,
           "encoder_hz": None, "updated_unix_s": 0.0}
    shown = with_staleness({"robot001": row}, time.time())["robot001"]
    assert shown["age_s"] is None
    assert shown["stale"] is True
    console = Console(width=80, record=True, file=io.StringIO())
    console.print(render_fleet({"robot001": row}, source="mqtt://x", elapsed_s=1.0))
    line = next(x for x in console.export_text().splitlines() if "robot001" in x)
    assert "stale" in line
    assert "inf" not in line


async def _publish_retained(url: str, payload: dict[str, object]) -> None:
    from odocan.host.mqtt.broker import BrokerURL

    broker = BrokerURL.parse(url)
    async with aiomqtt.Client(**broker.client_kwargs(), identifier="test-retained") as client:
        await client.publish("odocan/robot001/status", json.dumps(payload), qos=1, retain=True)


def test_monitor_json_marks_a_long_gone_robot_stale(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Through a real broker and the CLI: the retained offline status of a robot that left
    AGO_S ago is reported with that age and stale. The monitor ends once it has the status
    (its 1.5 s, connection included, ended before it on a loaded machine)."""
    end_watch_once(monkeypatch, lambda watch: "robot001" in watch.table)
    with embedded_broker(None) as url:
        asyncio.run(_publish_retained(str(url), topics.status_payload("robot001", "offline")
                                      | {"unix_s": time.time() - AGO_S}))
        code = main(["monitor", "--mqtt", str(url), "--json", "--duration", BOUND_S])
    out = json.loads(capsys.readouterr().out)
    assert code == 0
    robot = out["robots"]["robot001"]
    assert robot["online"] is False
    assert robot["stale"] is True
    assert robot["age_s"] >= AGO_S
