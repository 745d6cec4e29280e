"""``odocan experiment seed002``: seed 002's Tables 1 and 2 with the firmware navigating.

The full experiment (10 + 10 runs, about 230 s simulated) runs once through ``host.cli.main``;
the physics checks run a few runs each through ``host.experiments.seed002``. Expected figures:

* the firmware ends a goal within POSITION_TOL (5 mm) of it, decelerating by its P law, so the
  robot stops a few mm short: 1 m within 1 cm, 80 cm sides within 1 cm;
* without errors and misalignment the truth is the on-board path: deviations ~0, turns ~90 deg;
* with E_d = 1.002 (right wheel larger) a side the firmware believes straight is an arc turning
  left by beta = L * 2 (E_d - 1) / (E_d + 1) / b_actual (0.8 m: 0.30 deg), so the chord deviates
  by beta/2 to the left; with E_b = 1.01 each 90-degree turn is really 90/E_b = 89.11 deg, and
  the traced corner adds the side's beta: 89.41 deg.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from typing import Any

import pytest

from odocan.host.cli import app as cli
from odocan.host.experiments import seed002
from odocan.host.judge.reference import Geometry
from odocan.sim.errors import ErrorModel
from odocan.sim.robot import load

PMIR = load("pmir")
OUR_COMMANDS = ("experiment", "umbmark", "calibrate")


def test_our_subcommands_are_registered() -> None:
    assert set(OUR_COMMANDS) <= set(cli.SUBCOMMANDS)


def assert_usage_error(capsys: pytest.CaptureFixture[str], code: int, *words: str) -> None:
    """Exit 2, nothing on stdout, exactly one line ``error: ...`` on stderr naming ``words``."""
    out, err = capsys.readouterr()
    assert code == 2, (code, out, err)
    assert out == "", (code, out, err)
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    for word in words:
        assert word in lines[0], (word, lines[0])


@pytest.fixture(scope="module")
def seed002_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, str, dict[str, Any]]:
    """``odocan experiment seed002 --report PATH`` with every default: code, stdout, report."""
    path = tmp_path_factory.mktemp("seed002") / "report.json"
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = cli.main(["experiment", "seed002", "--report", str(path)])
    return code, stdout.getvalue(), json.loads(path.read_text())


def _mean(values: list[float]) -> float:
    return math.fsum(values) / len(values)


def test_tables_are_laid_out_like_the_papers(seed002_run: tuple[int, str, dict[str, Any]]) -> None:
    code, out, report = seed002_run
    assert code == 0
    assert out.endswith("seed002: PASS\n")
    assert report["passed"] is True
    assert report["faults"] == []
    lines = out.splitlines()
    assert "ed=1.002, eb=1.01, slip=0.005" in lines[0]
    assert "N(0, 1 deg)" in lines[0]
    t1 = next(i for i, line in enumerate(lines) if line.startswith("Table 1."))
    t2 = next(i for i, line in enumerate(lines) if line.startswith("Table 2."))
    assert "1 m straight, 10 runs" in lines[t1]
    assert "80 cm square" in lines[t2]
    for start, end, header in ((t1, t2, ("Distance travelled (cm)", "Deviation angle (deg)")),
                               (t2, len(lines), ("Side length (cm)", "Deviation angle (deg)",
                                                 "Turn angle (deg)"))):
        block = lines[start:end]
        assert all(any(h in line for line in block) for h in header)
        rows = [line.split() for line in block if line.split() and line.split()[0].isdigit()]
        assert [r[0] for r in rows] == [str(i) for i in range(1, 11)]
        assert all(len(r) == 1 + len(header) for r in rows)
        assert sum(line.split()[0] == "Mean" for line in block if line.split()) == 1


def test_report_contract_and_plausible_values(seed002_run: tuple[int, str, dict[str, Any]]) -> None:
    _, _, report = seed002_run
    assert report["error_model"] == {"ed": 1.002, "eb": 1.01, "slip": 0.005,
                                     "misalign_std_deg": 1.0}
    straight, square = report["straight_1m"]["runs"], report["square_80cm"]["runs"]
    assert len(straight) == 10
    assert len(square) == 10
    for run in straight:
        assert {"distance_m", "deviation_deg"} <= run.keys()
        assert abs(run["distance_m"] - 1.0) < 0.01
    for run in square:
        assert {"side_m", "deviation_deg", "turn_deg"} <= run.keys()
        assert abs(run["side_m"] - 0.8) < 0.01
        assert abs(run["turn_deg"] - 90.0) < 3.0
        assert len(run["sides_m"]) == 4
        assert len(run["turns_deg"]) == 3
    for table, runs, keys in (("straight_1m", straight, ("distance_m", "deviation_deg")),
                              ("square_80cm", square, ("side_m", "deviation_deg", "turn_deg"))):
        for key in keys:
            assert report[table]["mean"][key] == pytest.approx(_mean([r[key] for r in runs]))
    # the misalignment is what makes the straight runs' deviations differ (paper: 0 .. 10 deg)
    deviations = [r["deviation_deg"] for r in straight]
    assert max(deviations) - min(deviations) > 1.0


def _config(errors: ErrorModel, runs: int = 3, seed: int = 0) -> seed002.Seed002Config:
    return seed002.Seed002Config(PMIR, errors, misalign_deg=0.0, seed=seed, runs=runs)


def test_without_errors_the_truth_is_the_paths_shape() -> None:
    result = seed002.run_seed002(_config(ErrorModel()))
    for s in result.straight:
        assert abs(s.deviation_deg) < 0.01
        assert abs(s.distance_m - 1.0) < 0.01
    for q in result.square:
        assert abs(q.deviation_deg) < 0.25
        assert abs(q.turn_deg - 90.0) < 0.25
        assert all(abs(d) < 0.25 for d in q.deviations_deg)


def test_systematic_errors_deviate_left_and_shorten_the_turns() -> None:
    errors = ErrorModel(ed=1.002, eb=1.01)
    result = seed002.run_seed002(_config(errors))
    b_actual = PMIR.wheelbase_m * errors.eb
    beta_1m = math.degrees(1.0 * 2 * (errors.ed - 1) / (errors.ed + 1) / b_actual)
    beta_side = beta_1m * seed002.SQUARE_SIDE_M
    for s in result.straight:
        assert s.deviation_deg == pytest.approx(beta_1m / 2, abs=0.05)
    for q in result.square:
        assert q.turn_deg == pytest.approx(90.0 / errors.eb + beta_side, abs=0.15)


def test_same_seed_same_tables_and_the_seed_matters() -> None:
    errors = ErrorModel(ed=1.002, eb=1.01, slip=0.005)
    config = seed002.Seed002Config(PMIR, errors, misalign_deg=1.0, seed=4, runs=2)
    first = seed002.report(seed002.run_seed002(config))
    assert seed002.report(seed002.run_seed002(config)) == first
    other = seed002.Seed002Config(PMIR, errors, misalign_deg=1.0, seed=5, runs=2)
    assert seed002.report(seed002.run_seed002(other)) != first


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["experiment", "seed003"], ["seed003"]),
        (["experiment", "seed002", "--errors", "ed=3"], ["ed=3.0", "outside"]),
        (["experiment", "seed002", "--errors", "speed=1"], ["unknown key"]),
        (["experiment", "seed002", "--runs", "0"], ["--runs"]),
        (["experiment", "seed002", "--misalign", "-1"], ["--misalign"]),
        (["experiment", "seed002", "--seed", "-1"], ["--seed"]),
        (["experiment", "seed002", "--robot", "nosuch"], ["nosuch"]),
        (["experiment", "seed002", "--report", "/nonexistent/dir/r.json"], ["--report"]),
        (["experiment", "seed002", "--runs", "two"], ["--runs"]),
    ],
)
def test_bad_options_are_one_line_exit_2(
    capsys: pytest.CaptureFixture[str], argv: list[str], words: list[str]
) -> None:
    assert_usage_error(capsys, cli.main(argv), *words)


def test_runs_option_sets_the_rows(capsys: pytest.CaptureFixture[str]) -> None:
    code = cli.main(["experiment", "seed002", "--runs", "2", "--errors", "", "--misalign", "0"])
    out, err = capsys.readouterr()
    assert code == 0
    assert err == ""
    rows = [line.split()[0] for line in out.splitlines() if line.split()]
    assert rows.count("1") == 2
    assert rows.count("2") == 2
    assert "3" not in rows
    assert rows.count("Mean") == 2


def test_every_run_is_judged_and_a_wrong_firmware_fails(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The runs are valid (the firmware at its goal, its on-board end = the float64 reference on
    the logged counts); judged against another robot's geometry, the same drives are not, and
    the command exits 1 with one reason per run."""
    config = _config(ErrorModel(ed=1.002), runs=1)
    assert seed002.run_seed002(config).faults() == []
    kobuki = load("kobuki")
    monkeypatch.setattr(Geometry, "of", classmethod(lambda cls, robot: cls(
        kobuki.counts_per_rev, kobuki.wheel_radius_left_m, kobuki.wheel_radius_right_m,
        kobuki.wheelbase_m)))
    code = cli.main(["experiment", "seed002", "--runs", "1", "--errors", "", "--misalign", "0"])
    out = capsys.readouterr().out
    verdict = out[out.index("seed002: FAIL"):].splitlines()
    assert code == 1
    assert len(verdict) == 3
    assert verdict[1].startswith("  - straight run 1: the on-board end is ")
    assert verdict[2].startswith("  - square run 1: the on-board end is ")
