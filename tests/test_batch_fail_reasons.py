"""``odocan analyze LOG...``'s closing lines count the failed logs by their reasons (issue #11).

A log made by a firmware integrating one way (its ODOM_STATUS says ``euler``) and judged with
``--integrator exact`` FAILs for the mismatch alone (``host.judge.diagnosis.mark_integrator``),
its poses within the tolerance of the exact reference on a short square drive; the batch named
the mismatch under its row but its closing line said "2 of 3 logs out of tolerance", counting
it with the log whose X is 10 mm off. Each reason now has its line: the logs out of tolerance,
the logs with an integrator mismatch (a log with both is in both).

The independent proof: the euler log's single ``analyze --integrator exact`` report puts its
poses within one LSB of the reference (its FAIL is the mismatch's), and the tampered logs' X is
10 mm off from 1 s on (``tests.judges_cli.raise_x_10_mm``, re-signed by cantools).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.judge.analysis import Tolerance
from tests.judges_cli import raise_x_10_mm
from tests.test_cli_run import run_cli


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """good.log (exact), euler.log (euler), tampered.log (exact, X 10 mm off), euler_off.log
    (euler, X 10 mm off): 3 s square drives."""
    from odocan.host.cli.app import main

    root = tmp_path_factory.mktemp("reasons")
    for name, integrator in (("good", "exact"), ("euler", "euler")):
        assert main(["run", "--scenario", "square", "--duration", "3", "--integrator",
                     integrator, "--log", str(root / f"{name}.log")]) == 0
    assert raise_x_10_mm(root / "good.log", root / "tampered.log", 1.0) > 50
    assert raise_x_10_mm(root / "euler.log", root / "euler_off.log", 1.0) > 50
    return root


def test_the_euler_log_is_within_tolerance_of_the_exact_reference(
    logs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report_path = tmp_path / "euler.json"
    code, out, _ = run_cli(capsys, "analyze", str(logs / "euler.log"), "--integrator", "exact",
                           "--report", str(report_path))
    assert code == 1, out
    report = json.loads(report_path.read_text())
    vs_ref, tolerance = report["onboard_vs_reference"], Tolerance()
    assert vs_ref["max_position_error_m"] <= tolerance.position_m, vs_ref
    assert vs_ref["max_heading_error_rad"] <= tolerance.heading_rad, vs_ref
    assert report["integrator_mismatch"]["passed_otherwise"] is True, report
    assert "integrator mismatch" in out, out


@pytest.mark.parametrize("stream", ["never", "always"])
def test_the_batch_counts_failures_by_their_reasons(
    logs: Path, stream: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run_cli(capsys, "analyze", str(logs), "--integrator", "exact",
                             "--stream", stream, "--jobs", "1")
    assert code == 1, (out, err)
    named = {name: str(logs / f"{name}.log") for name in ("euler", "euler_off", "tampered")}
    assert err.splitlines() == [
        f"FAIL: 2 of 4 logs out of tolerance: {named['euler_off']}, {named['tampered']}",
        f"FAIL: 2 of 4 logs with an integrator mismatch (--integrator exact, not their "
        f"firmware's): {named['euler']}, {named['euler_off']}",
    ], err
    assert "1 PASS, 3 FAIL, 0 unreadable" in out, out


def test_a_batch_without_a_mismatch_says_only_the_tolerance(
    logs: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--integrator`` not given: each log judged with its own (no mismatch line)."""
    code, out, err = run_cli(capsys, "analyze", str(logs), "--jobs", "1")
    assert code == 1, (out, err)
    off = ", ".join(str(logs / f"{name}.log") for name in ("euler_off", "tampered"))
    assert err.splitlines() == [f"FAIL: 2 of 4 logs out of tolerance: {off}"], err
