"""CI-ready outputs: JUnit XML that a CI server parses, and reports that name every input."""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from pathlib import Path

from odocan.host.report.junit import Check, junit_xml, write_junit
from odocan.host.report.provenance import inputs
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import load, profile_sha256


def test_junit_names_every_check_and_carries_the_figures_of_a_failure(tmp_path: Path) -> None:
    checks = [
        Check("onboard_vs_reference", True, figures={"max_position_error_m": 3e-05}),
        Check("onboard_vs_truth", False, "max position error 0.053 m > 0.01 m",
              {"max_position_error_m": 0.053, "limit_m": 0.01}),
        Check("e2e", True),
    ]
    path = tmp_path / "junit.xml"
    write_junit(path, "run", checks, time_s=1.5)
    root = ET.parse(path).getroot()
    (suite,) = root.findall("testsuite")
    assert (suite.get("name"), suite.get("tests"), suite.get("failures")) == ("run", "3", "1")
    cases = {case.get("name"): case for case in suite.findall("testcase")}
    assert list(cases) == ["onboard_vs_reference", "onboard_vs_truth", "e2e"]
    failure = cases["onboard_vs_truth"].find("failure")
    assert failure is not None
    assert failure.get("message") == "max position error 0.053 m > 0.01 m"
    assert "limit_m = 0.01" in (failure.text or "")
    assert cases["onboard_vs_reference"].find("failure") is None
    system_out = cases["onboard_vs_reference"].findtext("system-out")
    assert system_out is not None
    assert "max_position_error_m = 3e-05" in system_out


def test_junit_escapes_what_xml_cannot_hold_raw() -> None:
    text = junit_xml("analyze", [Check('a<b & "c"', False, "x < y & z")])
    case = ET.fromstring(text).find("testsuite/testcase")
    assert case is not None
    assert case.get("name") == 'a<b & "c"'


def test_the_inputs_name_the_robot_the_dbc_and_the_version() -> None:
    robot = load("kobuki")
    record = inputs(robot, integrator="rk2", errors="ed=1.002", faults="drop=0.01",
                    seeds={"sim": 3, "faults": 4})
    assert record["robot"]["name"] == "kobuki"
    assert record["robot"]["sha256"] == profile_sha256(robot)
    assert record["robot"]["wheelbase_nm"] == robot.firmware_params()["wheelbase_nm"]
    assert (record["integrator"], record["errors"], record["faults"]) == (
        "rk2", "ed=1.002", "drop=0.01")
    assert record["seeds"] == {"sim": 3, "faults": 4}
    assert record["dbc"]["sha256"] == hashlib.sha256(DBC_PATH.read_bytes()).hexdigest()
    assert isinstance(record["odocan_version"], str)
    assert record["odocan_version"]
