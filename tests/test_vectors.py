"""Golden vectors: written by `odocan vectors`, re-read from CSV and JSON, reproduced exactly."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import pytest

from odocan.firmware.config import RobotParams, derive_constants
from odocan.firmware.errors import ErrorMask
from odocan.host.cli.app import main
from odocan.host.judge import vectors


@pytest.mark.parametrize("integrator", ["euler", "rk2", "exact"])
def test_vectors_round_trip_and_reproduce(integrator: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / integrator
    assert main(["vectors", "--integrator", integrator, "--duration", "3", "--out", str(out)]) == 0
    assert "wrote 6 files" in capsys.readouterr().out
    data = vectors.read_json(out / "vectors.json")
    assert data["integrator"] == integrator
    params = RobotParams(**data["params"])
    constants = derive_constants(params, ErrorMask())
    assert data["constants"]["m_per_count_left_q48_m"] == constants.m_per_count_left_q48_m
    assert data["constants"]["bam64_per_count_right"] == constants.bam64_per_count_right
    for case in data["cases"]:
        assert vectors.read_csv(out / f"{case['name']}.csv") == case["rows"]
        assert case["rows"][-1]["distance_q40_m"] > 0 or case["name"] == "spin_in_place"
    assert vectors.verify(data) == []
    assert main(["vectors", "--out", str(out), "--check"]) == 0


def test_a_single_changed_integer_is_caught(tmp_path: Path, capsys) -> None:
    assert main(["vectors", "--duration", "1", "--out", str(tmp_path)]) == 0
    path = tmp_path / "vectors.json"
    data = json.loads(path.read_text())
    data["cases"][1]["rows"][5]["y_q40_m"] += 1
    path.write_text(json.dumps(data))
    assert vectors.verify(vectors.read_json(path)) == [data["cases"][1]["name"]]
    assert main(["vectors", "--out", str(tmp_path), "--check"]) == 1
    assert "mismatch in: counter_wrap" in capsys.readouterr().out


def test_the_cases_cover_wraps_and_both_special_cases() -> None:
    cases = {c.name: c for c in vectors.edge_cases(16)}
    wrap = cases["counter_wrap"].counts
    assert any(b[0] < a[0] for a, b in itertools.pairwise(wrap)), "the left counter wraps"
    rows = vectors.run_case(
        RobotParams(500, 75_000_000, 75_000_000, 300_000_000, 16, 2), cases["spin_in_place"]
    )
    assert rows[-1]["x_q40_m"] == rows[-1]["y_q40_m"] == 0
    assert rows[-1]["heading_bam64"] != 0


def test_bad_input_is_one_line(tmp_path: Path, capsys) -> None:
    assert main(["vectors", "--duration", "-1", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == "error: argument --duration: must be in [0.01, 3600], got -1\n"
    assert main(["vectors", "--out", str(tmp_path / "missing"), "--check"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ")
    assert err.count("\n") == 1


@pytest.mark.parametrize(
    ("row", "column", "delta"), [(2, "x_q40_m", 1), (3, "heading_bam64", -1), (1, "right_count", 1)]
)
def test_an_edited_integer_in_a_csv_fails_the_check(
    tmp_path: Path, capsys, row: int, column: str, delta: int
) -> None:
    assert main(["vectors", "--duration", "1", "--out", str(tmp_path)]) == 0
    path = tmp_path / "big_steps.csv"
    rows = vectors.read_csv(path)
    rows[row][column] += delta
    lines = [",".join(vectors.CSV_COLUMNS)] + [",".join(str(r[c]) for c in vectors.CSV_COLUMNS)
                                               for r in rows]
    path.write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    assert main(["vectors", "--out", str(tmp_path), "--check"]) == 1
    assert capsys.readouterr().out == "mismatch in: big_steps.csv\n"


def test_a_missing_or_truncated_csv_fails_the_check(tmp_path: Path, capsys) -> None:
    assert main(["vectors", "--duration", "1", "--out", str(tmp_path)]) == 0
    (tmp_path / "straight.csv").unlink()
    spin = tmp_path / "spin_in_place.csv"
    spin.write_text("".join(spin.read_text().splitlines(keepends=True)[:-1]))  # a step less
    capsys.readouterr()
    assert main(["vectors", "--out", str(tmp_path), "--check"]) == 1
    assert capsys.readouterr().out == "mismatch in: spin_in_place.csv, straight.csv\n"
