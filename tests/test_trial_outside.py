"""What a user trying odocan from outside ran into, each case failing before its fix."""

from __future__ import annotations

import json
import re
import shlex
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from tests.test_outside_inputs import _one_error_line


@pytest.mark.parametrize("bitrate", ["10000", "20000"])
def test_a_bus_too_slow_for_the_rig_is_named_not_called_a_bug(
    bitrate: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """At 10 and 20 kbit/s the rig's 720 frames/s cannot get through (a pose message never
    does): the error says the bus is too slow, not 'a bug, please report it'."""
    err = _one_error_line(capsys, ["run", "-b", bitrate, "--duration", "1"])
    assert "a bug" not in err
    assert f"at {bitrate} bit/s the bus cannot carry the rig's traffic" in err
    assert "frames still queued at the end" in err


@pytest.fixture(scope="module")
def pmir_vectors(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """pmir's vectors (exact integrator), 0.5 s of the random scenario."""
    out = tmp_path_factory.mktemp("vectors")
    assert main(["vectors", "--out", str(out), "--duration", "0.5"]) == 0
    return out


@pytest.mark.parametrize(
    ("options", "why"),
    [
        (["--robot", "kobuki"], "is for robot pmir"),
        (["--integrator", "rk2"], "is for integrator exact"),
        (["--seed", "3"], "--seed: the cases are the vector file's"),
        (["--scenario", "spin", "--duration", "2"], "--scenario, --duration: the cases are"),
    ],
)
def test_vectors_check_refuses_options_it_would_ignore(
    pmir_vectors: Path, options: list[str], why: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """``vectors --check --robot kobuki`` of pmir's vectors said 'reproduced bit for bit' (exit
    0): --check re-runs the file's robot, integrator and cases and ignored the options."""
    err = _one_error_line(capsys, ["vectors", "--out", str(pmir_vectors), "--check", *options])
    assert why in err


@pytest.mark.parametrize("options", [[], ["--robot", "pmir"], ["--integrator", "exact"]])
def test_vectors_check_takes_options_that_match_the_file(
    pmir_vectors: Path, options: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["vectors", "--out", str(pmir_vectors), "--check", *options]) == 0
    assert "reproduced bit for bit" in capsys.readouterr().out


def test_calibrate_prints_the_umbmark_that_keeps_its_promise(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """calibrate --write-robot said 'use --robot kept.toml': with the same --errors that makes
    the corrected profile the simulated robot too, errors on top (kobuki: E_max 574 mm, not
    calibrate's 0.1 mm). The command it prints now gives calibrate's E_max after exactly."""
    kept, cal, check = tmp_path / "kept.toml", tmp_path / "cal.json", tmp_path / "check.json"
    assert main(["calibrate", "--robot", "kobuki", "--runs", "1", "--side", "2", "--errors",
                 "ed=1.002,eb=1.01", "--write-robot", str(kept), "--report", str(cal)]) == 0
    out = capsys.readouterr().out
    lines = [line.strip() for line in out.splitlines() if line.strip().startswith("odocan ")]
    assert len(lines) == 1, out
    argv = shlex.split(lines[0])[1:]
    assert main([*argv, "--report", str(check)]) == 0
    promised = json.loads(cal.read_text())["emax_after_m"]
    assert json.loads(check.read_text())["emax_syst_m"] == promised
    assert promised < json.loads(cal.read_text())["emax_before_m"] / 100


def test_run_refuses_a_bus_arg_without_a_bus_to_give_it_to(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``run --bus-arg foo`` (not even KEY=VALUE) ran and PASSed: the rig's own bus is
    in-process and takes no python-can arguments; only the -i/-c copy does."""
    err = _one_error_line(capsys, ["run", "--duration", "1", "--bus-arg", "port=47999"])
    assert "--bus-arg port=47999: only for the -i/-c bus" in err


def _relative_asc(absolute: Path, out: Path) -> None:
    """``absolute`` (python-can's ASC, ``timestamps absolute``) rewritten as CANalyzer writes
    with ``timestamps relative``: each event's time after the previous event's."""
    lines, previous = [], Decimal(0)
    for line in absolute.read_text().splitlines(keepends=True):
        if line.startswith("base "):
            line = line.replace("timestamps absolute", "timestamps relative")
        stamp = re.match(r"(\s*)(\d+\.\d+)(\s.*)", line, re.DOTALL)
        if stamp is not None:
            now = Decimal(stamp.group(2))
            line, previous = f"{stamp.group(1)}{now - previous:f}{stamp.group(3)}", now
        lines.append(line)
    out.write_text("".join(lines))


def test_an_asc_with_relative_timestamps_reads_as_its_absolute_twin(tmp_path: Path) -> None:
    """CANalyzer's 'timestamps relative' ASC was read as absolute times (python-can ignores the
    header): 499 of 1800 frames went back in time and analyze found no pose to pair."""
    absolute, relative = tmp_path / "abs.asc", tmp_path / "rel.asc"
    assert main(["run", "--duration", "2", "--log", str(absolute)]) == 0
    _relative_asc(absolute, relative)
    assert "timestamps relative" in relative.read_text()
    want, got = read_log(absolute), read_log(relative)
    assert len(got) == len(want) > 0
    assert np.array_equal(got.timestamp_s, want.timestamp_s)
    assert np.array_equal(got.can_id, want.can_id)
    assert main(["analyze", str(relative)]) == 0
