"""Without ``--robot``, the live judges (``odocan monitor``, ``odocan bridge``) take the robot
the firmware's first PROFILE page fits, as ``analyze`` does (``host.judge.liverobot``).

Found in an outside trial (issue #11): ``odocan monitor --require-firmware`` watching a kobuki
sim and firmware exited 1 with "pose was wrong ... 1706 mm; judged as robot 'pmir' (--robot)"
while ``analyze`` of its own ``--log`` PASSed: a correct firmware blamed for a missing option.
The robot each page names is checked here against the test's own CRC-32 of the DBC comment's
parameter bytes (``tests.test_profile_page``), not the product's ``profile_crc``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.liverobot import UNJUDGED_WHY
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.watchend import end_watch
from odocan.host.judge.watchverdict import failures
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.busfacts import PROFILE_PAGE
from odocan.sim import robot
from odocan.sim.contract import database
from tests.test_cli_monitor import BOUND, Source, sources
from tests.test_cli_run import run_cli
from tests.test_profile_page import crc32_iso_hdlc, parameter_bytes
from tests.test_robot_from_log import ODD

NAME = "robot007"
FROM_PAGE = {"name": "kobuki", "source": "PROFILE page", "page_fits": ["kobuki"],
             "unjudged": None}


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """3 s lockstep drives of kobuki and of a custom profile ``odd`` (no shipped robot's)."""
    folder = tmp_path_factory.mktemp("live_robots")
    odd = folder / "odd.toml"
    odd.write_text(ODD)
    made = {"odd.toml": odd}
    for name, arg in (("kobuki", "kobuki"), ("odd", str(odd))):
        made[name] = folder / f"{name}.log"
        assert main(["run", "--robot", arg, "--duration", "3", "--seed", "2", "--log",
                     str(made[name])]) == 0
    return made


def test_the_kobuki_logs_page_is_kobukis_by_the_tests_own_crc(logs: dict[str, Path]) -> None:
    """The drive's PROFILE pages carry kobuki's CRC (the premise of the tests below)."""
    status = database().get_message_by_name("ODOM_STATUS")
    pages: list[Any] = [status.decode(bytes(msg.data), decode_choices=False)
                        for msg in can.LogReader(str(logs["kobuki"]))
                        if msg.arbitration_id == status.frame_id]
    crcs = {int(s["PROFILE_CRC"]) for s in pages if int(s["PAGE"]) == PROFILE_PAGE}
    assert crcs == {crc32_iso_hdlc(parameter_bytes(robot.load("kobuki"), "exact"))}


def watched(log: Path, given: str | None) -> tuple[BusMonitor, list[str]]:
    """``log`` fed to the monitor's model (``given``: ``--robot``; None: not given), its watch
    ended; the model and its FAIL lines."""
    model = BusMonitor(robot.load(given or "pmir"), from_page=given is None)
    for msg in can.LogReader(str(log)):
        model.feed(msg, now_s=msg.timestamp)
    model.release_held()
    end_watch(model.tracker, model.distance)
    return model, failures(model.tracker, model.distance, model.twist, model.sources, "")


def test_the_monitor_judges_a_kobuki_as_kobuki_without_robot(logs: dict[str, Path]) -> None:
    model, fails = watched(logs["kobuki"], None)
    assert fails == []
    assert model.tracker.vs_reference.samples > 100  # the drive was judged, not skipped
    assert model.robot.as_dict() == FROM_PAGE
    assert model.robot.said("odocan monitor") == (
        "odocan monitor: robot 'kobuki' (from the firmware's PROFILE page)")
    last_s = max(msg.timestamp for msg in can.LogReader(str(logs["kobuki"])))
    snapshot = model.snapshot(last_s)
    assert snapshot["robot"] == FROM_PAGE
    assert snapshot["health"]["state"] == "OK", snapshot["health"]
    assert snapshot["status"]["profile_mismatch"] is None


def test_the_monitor_given_pmir_still_diagnoses_the_kobuki(logs: dict[str, Path]) -> None:
    model, fails = watched(logs["kobuki"], "pmir")
    assert fails, "the kobuki judged as pmir"
    assert fails[0].startswith("the on-board pose was wrong"), fails
    assert model.robot.as_dict() == {"name": "pmir", "source": "--robot", "page_fits": [],
                                     "unjudged": None}
    assert "parameters of robot 'kobuki', not 'pmir'" in model.status["profile_mismatch"]


def test_the_monitor_does_not_judge_a_custom_profile_as_the_default(
        logs: dict[str, Path]) -> None:
    """A page no shipped robot fits: nothing judged with pmir (UNJUDGED, not a FAIL: a custom
    robot's firmware once FAILed as pmir, tests.test_live_robot_unjudged), the page's
    diagnosis still said in ``analyze``'s words."""
    model, fails = watched(logs["odd"], None)
    assert model.robot.as_dict() == {"name": "pmir", "source": "default", "page_fits": [],
                                     "unjudged": UNJUDGED_WHY}
    assert model.robot.said("odocan monitor") is None
    assert fails == []
    assert "profile hash differs" in model.status["profile_mismatch"]
    assert ", the default robot pmir 0x" in model.status["profile_mismatch"]  # analyze's words
    assert "--robot" not in model.status["profile_mismatch"]  # none was given


def bridged(log: Path, from_page: bool) -> RobotTelemetry:
    """``log`` fed to the bridge's telemetry built for pmir (``from_page``: no ``--robot``)."""
    pmir = robot.load("pmir")
    telemetry = RobotTelemetry(NAME, Geometry.of(pmir), "exact", counter_bits=pmir.counter_bits,
                               profile_name="pmir", from_page=from_page)
    for msg in can.LogReader(str(log)):
        telemetry.feed(msg)
    telemetry.end_watch()
    return telemetry


def test_the_bridge_judges_a_kobuki_as_kobuki_without_robot(logs: dict[str, Path]) -> None:
    telemetry = bridged(logs["kobuki"], from_page=True)
    verdict = end_verdict(telemetry, profile_name="pmir", require_firmware=True)
    assert verdict.verdict == "PASS", verdict.text
    status = telemetry.status()[1]
    assert status["robot_profile"] == FROM_PAGE
    assert status["profile"]["verdict"] == "OK", status["profile"]
    assert telemetry.tracker.vs_reference.samples > 100


def test_the_bridge_given_pmir_still_fails_and_names_kobuki(logs: dict[str, Path]) -> None:
    telemetry = bridged(logs["kobuki"], from_page=False)
    verdict = end_verdict(telemetry, profile_name="pmir")
    assert verdict.verdict == "FAIL"
    assert "judged as robot 'pmir' (--robot)" in verdict.reason
    assert telemetry.status()[1]["profile"]["robot"] == "kobuki"


def test_the_bridge_does_not_judge_a_custom_profile_as_the_default(
        logs: dict[str, Path]) -> None:
    telemetry = bridged(logs["odd"], from_page=True)
    status = telemetry.status()[1]
    assert status["robot_profile"] == {"name": "pmir", "source": "default", "page_fits": [],
                                       "unjudged": UNJUDGED_WHY}
    assert status["profile"]["verdict"] == "MISMATCH"
    assert ", the default robot pmir 0x" in status["profile"]["detail"]  # analyze's words
    verdict = end_verdict(telemetry, profile_name="pmir")
    assert verdict.verdict == "UNJUDGED", verdict.text
    assert "judged as robot" not in verdict.reason
    assert "--robot" not in verdict.reason.replace("give --robot", "")  # none was given


@pytest.fixture
def kobuki(monkeypatch: pytest.MonkeyPatch) -> Iterator[Source]:
    """A live kobuki rig (3 s: five PROFILE pages) for ``odocan monitor``."""
    yield from sources(monkeypatch, robot_name="kobuki", ticks=300, garbage=False)


def test_odocan_monitor_without_robot_passes_a_live_kobuki(
    kobuki: Source, capsys: pytest.CaptureFixture[str]
) -> None:
    """The trial's command, on a live kobuki rig: exit 0, the robot said and in the JSON."""
    code, out, err = run_cli(capsys, "monitor", "-i", "virtual", "-c", kobuki.channel,
                             "--duration", BOUND, "--json", "--require-firmware")
    assert code == 0, err  # its robot said, then the watch's PASS line
    lines = err.splitlines()
    assert lines[0] == "odocan monitor: robot 'kobuki' (from the firmware's PROFILE page)"
    assert len(lines) == 2, err
    assert lines[1].startswith("monitor: PASS: ")
    assert json.loads(out)["robot"] == FROM_PAGE


def test_the_screen_names_the_robot_the_page_chose() -> None:
    """The TUI's firmware line says a robot the page chose; the default pmir stays unsaid."""
    from odocan.host.report.tui import firmware_line

    status = {"state": "OK", "errors": [], "integrator": "EXACT", "uptime_s": 3}
    chosen = firmware_line({"status": status, "robot": FROM_PAGE}, 0.1).plain
    assert "robot kobuki (PROFILE page)" in chosen
    pmir = {"name": "pmir", "source": "PROFILE page", "page_fits": ["pmir"]}
    assert "robot" not in firmware_line({"status": status, "robot": pmir}, 0.1).plain


def test_odocan_bridge_without_robot_passes_a_kobuki(
    logs: dict[str, Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``odocan bridge`` (an embedded broker) hearing the kobuki drive: PASS, exit 0, the robot
    said before its verdict."""
    from tests.test_bridge_exit import _bridge_hears, _duration_reached
    from tests.test_stall_bound import _messages

    _bridge_hears(monkeypatch, _messages(logs["kobuki"]), _duration_reached)
    code, _, err = run_cli(capsys, "bridge", "-i", "virtual", "--duration", "600",
                           "--require-firmware")
    lines = err.splitlines()
    assert code == 0, err
    assert "bridge robot001: robot 'kobuki' (from the firmware's PROFILE page)" in lines, err
    assert lines[-1].startswith("bridge robot001: PASS: the on-board pose right in "), err
