"""The opt-in per-tick trace of a fleet worker (``host.mqtt.ticktrace``, ``ODOCAN_TICK_TRACE``)
and its reader (``bench/fleet_ticks.py``): a row a tick run, its parts timed, nothing without
the variable."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from pathlib import Path

import pytest

from odocan.host.mqtt import fleetrun
from odocan.host.mqtt.fleetrun import FleetRun
from odocan.host.mqtt.ticktrace import ENV
from odocan.sim import robot
from odocan.sim.fleet import FleetConfig

ROOT = Path(__file__).resolve().parent.parent
RUN = FleetRun(fleet=FleetConfig(robots=2, robot=robot.load("pmir"), seed=3, first=4),
               duration_s=0.2, bridge=False)


def test_a_traced_worker_writes_a_row_a_tick_with_each_parts_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(ENV, str(tmp_path / "trace"))
    report = asyncio.run(fleetrun.run_fleet(RUN))
    path = tmp_path / "trace" / "ticks-robot005.jsonl"  # the worker's first robot
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    assert report["ticks"] > 0
    assert [row["k"] for row in rows] == list(range(report["ticks"]))
    assert sum(row["late_ms"] > 5 for row in rows) == report["late_ticks"]
    for row in rows:
        assert row["step_cpu_us"] > 0  # two robots stepped: never free
        assert row["gc_cpu_us"] >= 0
        assert row["batch_cpu_us"] >= 0
        assert row["proc_cpu_us"] >= row["step_cpu_us"] * 0.5  # the process's CPU holds it
    assert "between_cpu_us" not in rows[0]  # no tick before the first
    assert all("between_cpu_us" in row for row in rows[1:])
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "fleet_ticks.py"),
                          str(tmp_path / "trace")], capture_output=True, text=True, check=True)
    assert f"ticks-robot005.jsonl: {len(rows) - 1} ticks" in out.stdout


def test_without_the_variable_nothing_is_traced(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv(ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    report = asyncio.run(fleetrun.run_fleet(RUN))
    assert report["ticks"] > 0
    assert list(tmp_path.iterdir()) == []


def test_the_reader_says_so_in_one_line_when_there_is_no_trace(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "fleet_ticks.py"), str(tmp_path)],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0
    assert "no ticks-" in out.stderr
    assert "Traceback" not in out.stderr
