"""``odocan fleet --firmware auto`` (the default): the C port when its library builds and loads,
the Python firmware otherwise, with the reason in the start line; a firmware asked by name is
taken as asked (``--firmware c`` that cannot build stays one ``error:`` line, exit 2)."""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import build_parser
from odocan.host.cli.firmware_choice import FirmwareChoice, resolve_firmware
from odocan.host.cli.subparsers import fleet
from odocan.sim.cboard import LIBRARY_ENV
from odocan.sim.rig import firmware_params
from odocan.sim.robot import load
from tests.requires import require_executables

PMIR = firmware_params(load("pmir"), "exact")


def test_the_fleets_default_firmware_is_auto() -> None:
    args = build_parser().parse_args(["fleet"])
    assert args.firmware == "auto"


def test_auto_takes_the_c_firmware_when_it_builds_and_the_start_line_says_so(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    require_executables("make", "cc", install="apt-get install gcc make")
    monkeypatch.delenv(LIBRARY_ENV, raising=False)
    choice = resolve_firmware("auto", False, PMIR)
    assert choice.firmware == "c"
    fleet._say_started(2, None, choice.said)
    line = capsys.readouterr().err
    assert line.startswith("fleet: 2 robots running; firmware c (auto"), line


def test_auto_falls_back_to_python_naming_why(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    missing = tmp_path / "no_such_lib.so"
    monkeypatch.setenv(LIBRARY_ENV, str(missing))
    choice = resolve_firmware("auto", False, PMIR)
    assert choice.firmware == "python"
    assert choice.said.startswith("firmware python (auto: the C firmware is unavailable: ")
    assert str(missing) in choice.said


@pytest.mark.parametrize("asked", ["python", "c"])
def test_a_firmware_asked_by_name_is_taken_as_asked(
    asked: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(LIBRARY_ENV, str(tmp_path / "no_such_lib.so"))  # never loaded here
    choice = resolve_firmware(asked, False, PMIR)
    assert (choice, choice.said) == (FirmwareChoice(asked), f"firmware {asked}")
