"""A fleet robot's retained ``offline`` status carries its verdict (issue #11;
``host.mqtt.fleetjudge``), as ``odocan bridge``'s does (``tests/test_bridge_exit.py``).

Before (main): ``odocan fleet``'s statuses had no ``watch_verdict``: a dashboard reading a fleet
robot's retained status after the run could not tell whether its pose was right. Now each one
carries the verdict of that robot in the fleet's report (one judgement, made when the watch
ended), the worst wrong episode on a FAIL, and the deadline figures of the loop that ran it.

A real fleet (``run_fleet``, python firmware, in real time) on the embedded broker; a client
subscribes once it ended and reads each robot's retained status. Wrong or right by what is
injected: the firmware's ODOM_POSE_X 0.3 mm (three LSB) off its own pose from ~0.5 s on
(``test_fleet_verdict``'s fault), or nothing.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import pytest

from odocan.firmware import frames as fw_frames
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.broker import BrokerURL, EmbeddedBroker
from odocan.host.mqtt.fleetjudge import DEFAULT_MAX_MISS_RATIO, end_verdict, loop_figures
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.host.mqtt.options import PASSWORD_ENV
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.fleet import FleetConfig
from odocan.sim.realtime import DeadlineStats
from tests.conftest_mqtt import Mosquitto, client, mosquitto  # noqa: F401 (fixture)
from tests.fleet_run_until import pace_never_late
from tests.test_bridge_exit import RETAINED_WAIT_S, _retained_status
from tests.test_cli_run import run_cli
from tests.test_fleet_verdict import WRONG_100UM

ROBOTS = 2
WRONG_AFTER = 50  # ODOM_POSE_X frames of the whole fleet (2 robots at 50 Hz): ~0.5 s


def _inject_wrong_x(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every firmware's ODOM_POSE_X ``WRONG_100UM`` LSB off its pose after ``WRONG_AFTER``."""
    real = fw_frames.pack_odom_pose_x
    sent = [0]

    def off(counter: int, enc: int, x_100um: int, heading_bam16: int, errors: Any) -> bytes:
        sent[0] += 1
        late = sent[0] > WRONG_AFTER
        return real(counter, enc, x_100um + (WRONG_100UM if late else 0), heading_bam16, errors)

    monkeypatch.setattr(fw_frames, "pack_odom_pose_x", off)


async def _fleet_and_statuses() -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Run the fleet on an embedded broker; its report and, read after it ended, each robot's
    retained status."""
    async with EmbeddedBroker() as broker:
        run = FleetRun(fleet=FleetConfig(robots=ROBOTS, robot=robot.load("pmir"), seed=9,
                                         firmware="python"),
                       duration_s=2.0, broker=broker.url, client_prefix="test-fleet-verdict")
        report = await run_fleet(run)
        statuses = await _retained_statuses(broker.url)
    return report, statuses


async def _retained_statuses(url: BrokerURL) -> dict[str, dict[str, Any]]:
    """Every robot's retained ``status`` (by its topic's robot) as a subscriber that comes
    after the fleet gets them."""
    statuses: dict[str, dict[str, Any]] = {}
    async with client(url) as sub:
        await sub.subscribe("odocan/+/status", qos=1)
        async with asyncio.timeout(RETAINED_WAIT_S):
            async for message in sub.messages:
                assert message.retain, message.topic  # kept by the broker, not sent live
                assert isinstance(message.payload, bytes)
                statuses[message.topic.value.split("/")[1]] = json.loads(message.payload)
                if len(statuses) == ROBOTS:
                    return statuses
    raise AssertionError(f"retained statuses of {sorted(statuses)} only")


def _check_loop(verdict: dict[str, Any], ratio: float, max_ratio: float) -> None:
    """The status's ``loop``: the report's figure, against the limit, said in the reason when
    it broke it."""
    loop = verdict["loop"]
    assert loop["deadline_miss_ratio"] == ratio, loop
    assert (loop["max_miss_ratio"], loop["missed"]) == (max_ratio, ratio > max_ratio), loop
    assert ("missed its deadlines" in verdict["reason"]) == loop["missed"], verdict


@pytest.mark.parametrize("wrong", [True, False])
def test_each_fleet_robots_retained_status_carries_its_report_verdict(
    wrong: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    pace_never_late(monkeypatch)  # a halt (a loaded machine) would judge only before it
    if wrong:
        _inject_wrong_x(monkeypatch)
    report, statuses = asyncio.run(_fleet_and_statuses())
    assert len(statuses) == ROBOTS
    for name, status in statuses.items():
        entry = report["per_robot"][name]
        assert (status["state"], status["reason"]) == ("offline", "bridge stopped"), status
        verdict = status.get("watch_verdict")
        assert isinstance(verdict, dict), status  # before: absent
        assert verdict["verdict"] == entry["verdict"] == ("FAIL" if wrong else "PASS"), \
            (verdict, entry)
        _check_loop(verdict, report["deadline_miss_ratio"], DEFAULT_MAX_MISS_RATIO)
        if wrong:
            assert verdict["reason"].startswith(entry["reason"]), (verdict, entry)
            assert "position vs reference" in verdict["reason"], verdict
            assert verdict["pose_error"] is not None, verdict
            assert verdict["pose_error"] == status["pose_wrongs"]["worst"], status
            assert verdict["pose_error"]["beyond_mm"] > 0.1, verdict  # one LSB
        else:
            samples = entry["pose_vs_reference"]["samples"]
            assert verdict["reason"].startswith(f"the on-board pose right in {samples} "), verdict
            assert verdict["pose_error"] is None, verdict


def test_the_cli_fleets_statuses_carry_its_max_miss_ratio(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    mosquitto: Mosquitto,  # noqa: F811
) -> None:
    """``odocan fleet --broker`` (mosquitto, which keeps the statuses after the fleet exits):
    the status's verdict is its ``--report``'s, its loop judged against ``--max-miss-ratio``."""
    url = mosquitto.url()
    monkeypatch.setenv(PASSWORD_ENV, url.password or "")
    pace_never_late(monkeypatch)  # a halt (a loaded machine) would leave the robot UNJUDGED
    path = tmp_path / "fleet.json"
    code, out, err = run_cli(capsys, "fleet", "-n", "1", "--duration", "1", "--seed", "4",
                             "--max-miss-ratio", "1", "--report", str(path), "--broker",
                             f"mqtt://{url.username}@{url.host}:{url.port}")
    assert code == 0, out + err
    report = json.loads(path.read_text())
    assert report["passed"] is True  # the run's verdict, on top
    assert report["failures"] == []
    verdict = asyncio.run(_retained_status(url, "robot001"))["watch_verdict"]
    assert verdict["verdict"] == report["per_robot"]["robot001"]["verdict"] == "PASS", verdict
    _check_loop(verdict, report["deadline_miss_ratio"], 1.0)


def test_a_passed_pose_whose_loop_missed_its_deadlines_says_both() -> None:
    """The pose's verdict stands (PASS: the firmware was right); the reason and ``loop`` say the
    loop broke ``--max-miss-ratio`` (the run fails for it, not the robot)."""
    profile = robot.load("pmir")
    telemetry = RobotTelemetry("robot001", Geometry.of(profile), "exact",
                               counter_bits=profile.counter_bits)
    entry = {"verdict": "PASS", "reason": None, "max_dpos_beyond_allowance_m": 0.0,
             "pose_vs_reference": {"samples": 900, "max_dpos_m": 4e-5, "max_dheading_rad": 0.0}}
    stats = DeadlineStats(TICK_S, TICK_S / 2, ticks=1000, late_ticks=12)
    verdict = end_verdict(entry, telemetry, loop_figures(stats, 0.001)).as_dict()
    assert verdict["verdict"] == "PASS"
    assert verdict["reason"].startswith("the on-board pose right in 900 samples"), verdict
    assert verdict["reason"].endswith(
        "; the loop that ran it missed its deadlines: deadline_miss_ratio 0.0120 > "
        "--max-miss-ratio 0.001 (the fleet's run fails for it)"), verdict
    assert verdict["loop"] == {"deadline_miss_ratio": 0.012, "max_miss_ratio": 0.001,
                               "missed": True, "skipped_releases": 0}
    assert verdict["pose_error"] is None


def test_a_failing_fleets_report_says_so_on_top(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """The report's ``passed`` and ``failures`` are the exit line's and code's (a run whose
    thresholds are broken: ``failures`` made to say so, the fleet itself on the embedded
    broker)."""
    broken = ["deadline_miss_ratio 0.5000 > --max-miss-ratio 0.001"]
    monkeypatch.setattr("odocan.host.cli.subparsers.fleet.failures", lambda *_: broken)
    path = tmp_path / "fleet.json"
    code, out, err = run_cli(capsys, "fleet", "-n", "1", "--duration", "1", "--report", str(path))
    assert code == 1, out + err
    assert broken[0] in out + err
    report = json.loads(path.read_text())
    assert report["passed"] is False
    assert report["failures"] == broken
