"""The committed golden vectors are the reference: the firmware must reproduce them bit for bit.

The files under tests/files/vectors/ were written once by ``odocan vectors`` and reviewed; a change
in the firmware's numerics, in the vector format or in the simulated drive that feeds them fails
here until the files are regenerated on purpose (see that folder's README).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main

GOLDEN = Path(__file__).parent / "files" / "vectors"
SETS = sorted(p.name for p in GOLDEN.iterdir() if p.is_dir())


def test_every_robot_and_integrator_has_a_committed_set() -> None:
    assert sorted(f"{r}_{i}" for r in ("kobuki", "pmir") for i in ("euler", "exact", "rk2")) == SETS


@pytest.mark.parametrize("name", SETS)
def test_the_firmware_regenerates_the_committed_files_byte_for_byte(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    robot, integrator = name.split("_")
    argv = ["vectors", "--robot", robot, "--integrator", integrator, "--duration", "3",
            "--seed", "7", "--out", str(tmp_path)]
    assert main(argv) == 0
    capsys.readouterr()
    committed = sorted(p.name for p in (GOLDEN / name).iterdir())
    assert sorted(p.name for p in tmp_path.iterdir()) == committed
    for file in committed:
        assert (tmp_path / file).read_bytes() == (GOLDEN / name / file).read_bytes(), file


@pytest.mark.parametrize("name", SETS)
def test_the_csv_files_say_what_the_json_says(name: str) -> None:
    """A C port most likely reads the CSVs: they must carry the same integers as the JSON."""
    data = json.loads((GOLDEN / name / "vectors.json").read_text())
    for case in data["cases"]:
        with (GOLDEN / name / f"{case['name']}.csv").open(newline="") as f:
            rows = [{k: int(v) for k, v in row.items()} for row in csv.DictReader(f)]
        assert len(rows) == len(case["rows"]) > 1
        assert rows == case["rows"]
