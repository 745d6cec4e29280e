"""A C firmware library older than ABI 3 has its wheel speed bound built in (4 m/s).

The board must refuse it, in one line naming the ABI and both speeds, for a robot that states
another maximum wheel speed (kobuki: 0.7 m/s), and take it for a robot at the old bound (pmir).
``--firmware auto`` (the CLI's default) then falls back to the Python firmware and says why.
The library is a stub of ABI 1 (the SecOC test's), built with the system's C compiler.
Skips with the reason when a C compiler is missing, and fails instead under CI=true.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from odocan.firmware.config import MAX_WHEEL_SPEED_DEFAULT_MM_S
from odocan.host.cli.app import main
from odocan.sim import cboard, transport
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.rig import firmware_params
from odocan.sim.robot import load
from tests.fleet_run_until import pace_never_late
from tests.requires import require_executables
from tests.test_c_secoc import STUB_ABI1


@pytest.fixture
def old_library(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An ABI 1 library, the one the board loads (``cboard.LIBRARY_ENV``)."""
    require_executables("cc", install="apt-get install gcc")
    source, lib = tmp_path / "abi1.c", tmp_path / "libabi1.so"
    source.write_text(STUB_ABI1)
    subprocess.run(["cc", "-shared", "-fPIC", str(source), "-o", str(lib)], check=True)
    monkeypatch.setenv(cboard.LIBRARY_ENV, str(lib))
    return lib


def test_an_old_library_is_refused_for_a_robot_with_another_speed_bound(
    old_library: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    kobuki = firmware_params(load("kobuki"), "exact")
    assert kobuki.max_wheel_speed_mm_s != MAX_WHEEL_SPEED_DEFAULT_MM_S
    with pytest.raises(ConfigurationError, match="ABI version 1, bounded at 4000 mm/s"):
        cboard.check_speed_abi(cboard.load_library(), kobuki)
    assert main(["run", "--firmware", "c", "--robot", "kobuki", "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: the C firmware {old_library} has ABI version 1, bounded at "
                          "4000 mm/s; the robot's max_wheel_speed is 700 mm/s (ABI 3)")
    assert err.count("\n") == 1
    wire = transport._wires.get("vcan0")  # the rig released the buses it had opened
    assert wire is None or not wire.handles


def test_an_old_library_is_taken_for_a_robot_at_the_old_bound(old_library: Path) -> None:
    pmir = firmware_params(load("pmir"), "exact")
    assert pmir.max_wheel_speed_mm_s == MAX_WHEEL_SPEED_DEFAULT_MM_S
    cboard.check_speed_abi(cboard.load_library(), pmir)  # no refusal


@pytest.mark.parametrize("command", [
    ["run", "--robot", "kobuki", "--duration", "1"],
    ["fleet", "-n", "1", "--robot", "kobuki", "--duration", "1", "--max-miss-ratio", "1"],
])
def test_auto_falls_back_to_python_when_the_old_library_cannot_run_the_robot(
    old_library: Path, command: list[str], capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Before: auto chose the library (it loads), then the board refused it: exit 2. (The
    fleet on ``PacedClock``: a loaded machine's halt could leave its robot UNJUDGED, exit 1.)"""
    pace_never_late(monkeypatch)
    assert main(command) == 0  # the fleet's miss ratio is not this test's: load
    said = "".join(capsys.readouterr())  # run: the title; fleet: its start line (stderr)
    assert re.search(r"(python firmware|firmware python) \(auto: the C firmware is "
                     r"unavailable: the C firmware ", said)
    assert "ABI version 1, bounded at 4000 mm/s" in said
