"""``--junit PATH`` on run, analyze, replay, experiment, umbmark (calibrate: test_calibrate_write)
and the ``inputs`` section of every JSON report. The XML is parsed back with ElementTree, the
inputs are checked against independently computed hashes."""

from __future__ import annotations

import hashlib
import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from odocan import __version__
from odocan.host.cli.app import main
from odocan.sim import robot
from odocan.sim.contract import DBC_PATH

CHECKS = ["onboard_vs_reference_position", "onboard_vs_reference_heading"]


def cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def parse_junit(path: Path) -> tuple[ET.Element, dict[str, ET.Element]]:
    """The testsuite element and its testcases by name (the counts checked against them)."""
    root = ET.parse(path).getroot()
    assert root.tag == "testsuites"
    (suite,) = root.findall("testsuite")
    cases = {case.get("name", ""): case for case in suite.findall("testcase")}
    assert int(suite.get("tests", "-1")) == len(cases) == len(suite.findall("testcase"))
    failed = [c for c in cases.values() if c.find("failure") is not None]
    assert int(suite.get("failures", "-1")) == len(failed) == int(root.get("failures", "-1"))
    return suite, cases


def figures(case: ET.Element) -> dict[str, str]:
    """``key = value`` lines of a testcase's failure text or system-out."""
    node = case.find("failure")
    node = node if node is not None else case.find("system-out")
    assert node is not None
    assert node.text
    return dict(line.split(" = ", 1) for line in node.text.splitlines())


def check_inputs(section: dict[str, Any], robot_name: str = "pmir") -> None:
    """Profile with its hash, version and DBC hash, computed here independently."""
    profile = robot.load(robot_name)
    params = json.dumps(profile.firmware_params(), sort_keys=True).encode()
    assert section["robot"]["sha256"] == hashlib.sha256(params).hexdigest()
    assert section["robot"]["name"] == profile.name
    assert section["robot"]["wheelbase_nm"] == round(profile.wheelbase_m * 1e9)
    assert section["odocan_version"] == __version__
    assert section["dbc"]["sha256"] == hashlib.sha256(DBC_PATH.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def gap_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 12 s run with errors and a bus-off, logged."""
    log = tmp_path_factory.mktemp("junit") / "gap.log"
    code = main(["run", "--duration", "12", "--seed", "2", "--errors", "ed=1.002,eb=1.01",
                 "--faults", "busoff=4:1,seed=9", "--log", str(log)])
    assert code == 0
    return log


def test_run_junit_and_inputs(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    junit, report = tmp_path / "run.xml", tmp_path / "run.json"
    code, _, err = cli(capsys, "run", "--duration", "3", "--seed", "4", "--errors",
                       "ed=1.002,eb=1.01", "--faults", "drop=0.01,seed=3",
                       "--junit", str(junit), "--report", str(report))
    assert (code, err) == (0, "")
    suite, cases = parse_junit(junit)
    assert suite.get("name") == "run"
    assert list(cases)[:2] == CHECKS
    data = json.loads(report.read_text())
    fig = figures(cases["onboard_vs_reference_position"])
    assert float(fig["max_m"]) == data["onboard_vs_reference"]["max_position_error_m"]
    assert float(fig["limit_m"]) == 1e-4
    inputs = data["inputs"]
    check_inputs(inputs)
    assert inputs["integrator"] == "exact"
    assert inputs["errors"] == "ed=1.002,eb=1.01"
    assert inputs["faults"] == "drop=0.01,seed=3"
    assert inputs["seeds"] == {"rig": 4, "faults": 3, "firmware_faults": 4}


def test_analyze_fail_carries_the_figures(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, gap_log: Path
) -> None:
    """The wrong integrator: exit 1, the position testcase fails with measured and limit."""
    junit, report = tmp_path / "a.xml", tmp_path / "a.json"
    code, _, err = cli(capsys, "analyze", str(gap_log), "--integrator", "euler",
                       "--junit", str(junit), "--report", str(report))
    assert (code, err) == (1, "")
    _, cases = parse_junit(junit)
    failure = cases["onboard_vs_reference_position"].find("failure")
    assert failure is not None
    data = json.loads(report.read_text())
    measured = data["onboard_vs_reference"]["max_position_error_m"]
    assert measured > 1e-4
    assert str(measured) in failure.get("message", "")
    assert float(figures(cases["onboard_vs_reference_position"])["max_m"]) == measured
    inputs = data["inputs"]
    check_inputs(inputs)
    assert inputs["errors"] is None
    assert inputs["faults"] is None  # unknown for a log
    assert inputs["log"]["sha256"] == hashlib.sha256(gap_log.read_bytes()).hexdigest()
    assert inputs["integrator"] == "euler"


def test_analyze_pass(capsys: pytest.CaptureFixture[str], tmp_path: Path, gap_log: Path) -> None:
    junit = tmp_path / "a.xml"
    code, _, _ = cli(capsys, "analyze", str(gap_log), "--junit", str(junit))
    assert code == 0
    _, cases = parse_junit(junit)
    assert all(cases[name].find("failure") is None for name in CHECKS)


def test_replay_junit(capsys: pytest.CaptureFixture[str], tmp_path: Path, gap_log: Path) -> None:
    junit, report = tmp_path / "r.xml", tmp_path / "r.json"
    code, _, err = cli(capsys, "replay", str(gap_log), "--junit", str(junit),
                       "--report", str(report))
    assert err == ""
    suite, cases = parse_junit(junit)
    assert suite.get("name") == "replay"
    assert code == (1 if any(c.find("failure") is not None for c in cases.values()) else 0)
    check_inputs(json.loads(report.read_text())["inputs"])


def test_experiment_junit(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    junit, report = tmp_path / "e.xml", tmp_path / "e.json"
    code, _, err = cli(capsys, "experiment", "seed002", "--runs", "1", "--junit", str(junit),
                       "--report", str(report), "--errors", "ed=1.01")
    assert (code, err) == (0, "")
    _, cases = parse_junit(junit)
    data = json.loads(report.read_text())
    fig = figures(cases["straight_1m"])
    assert float(fig["mean_distance_m"]) == data["straight_1m"]["mean"]["distance_m"]
    assert fig["runs"] == "1"
    assert "square_80cm" in cases
    check_inputs(data["inputs"])
    assert data["inputs"]["errors"] == "ed=1.01"


def test_umbmark_junit_plot_and_inputs(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    junit, report, plot = tmp_path / "u.xml", tmp_path / "u.json", tmp_path / "u.png"
    code, _, err = cli(capsys, "umbmark", "--runs", "1", "--side", "1", "--seed", "3",
                       "--junit", str(junit), "--report", str(report), "--plot", str(plot))
    assert (code, err) == (0, "")
    _, cases = parse_junit(junit)
    data = json.loads(report.read_text())
    assert float(figures(cases["emax_syst"])["emax_syst_mm"]) == data["emax_syst_m"] * 1e3
    assert float(figures(cases["cg_cw"])["r_cg_mm"]) == data["cw"]["r_cg_m"] * 1e3
    check_inputs(data["inputs"])
    assert data["inputs"]["seeds"] == {"seed": 3}
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["run", "--duration", "1", "--junit", "/nonexistent/x.xml"], ["--junit", "/nonexistent"]),
        (["analyze", "x.log", "--junit", "/nonexistent/x.xml"], ["--junit"]),
        (["umbmark", "--plot", "u.gif"], ["--plot", ".gif"]),
        (["umbmark", "--junit", "/nonexistent/u.xml"], ["--junit"]),
        (["experiment", "seed002", "--junit", "/"], ["--junit", "directory"]),
        (["calibrate", "--write-robot", "p.json"], ["--write-robot", ".toml"]),
        (["umbmark", "--firmware-robot", "nosuch"], ["nosuch"]),
    ],
)
def test_bad_outputs_are_refused_up_front(
    capsys: pytest.CaptureFixture[str], argv: list[str], words: list[str]
) -> None:
    code, out, err = cli(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    for word in words:
        assert word in lines[0]
