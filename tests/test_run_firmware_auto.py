"""``odocan run`` and ``odocan firmware`` default to ``--firmware auto``, as ``odocan fleet``: the
C port when its library builds and loads, bit-exact with the Python firmware (the same log, byte
for byte), and said in the summary (run's title, the report's ``inputs.firmware``, firmware's
last line); the Python firmware, and why, when the library is unavailable (a missing tool, or a
library of ABI 1 asked for a SecOC key)."""

from __future__ import annotations

import json
import subprocess
import uuid
from pathlib import Path

import pytest

from odocan.firmware import frames as fw_frames
from odocan.firmware.errors import ErrorMask
from odocan.host.cli.app import build_parser, main
from odocan.sim import cboard
from tests.requires import require_executables
from tests.test_c_secoc import STUB_ABI1
from tests.test_cli_run import run_cli
from tests.test_secoc_rig import KEY

TITLE = "odocan run: random on pmir, exact integrator"
TOOK_C = "c firmware (auto: it built and loaded; --firmware python for the Python one)"
NO_MAKE = "--firmware c: make not found on PATH (install make)"
FELL_BACK = f"python firmware (auto: the C firmware is unavailable: {NO_MAKE})"


@pytest.fixture
def c_builds(monkeypatch: pytest.MonkeyPatch) -> None:
    """Our C firmware, built on demand (not a ``$ODOCAN_FW_LIB`` of the environment's)."""
    require_executables("make", "cc", install="apt-get install gcc make")
    monkeypatch.delenv(cboard.LIBRARY_ENV, raising=False)


@pytest.fixture
def no_c(monkeypatch: pytest.MonkeyPatch) -> None:
    """The C library cannot be built: its builder raises as it does without make."""

    def no_make() -> Path:
        raise cboard.FirmwareBuildError(NO_MAKE)

    monkeypatch.delenv(cboard.LIBRARY_ENV, raising=False)
    monkeypatch.setattr(cboard, "_build_library", no_make)


@pytest.mark.parametrize("command", ["run", "firmware"])
def test_the_default_firmware_is_auto(command: str) -> None:
    assert build_parser().parse_args([command]).firmware == "auto"


@pytest.mark.usefixtures("c_builds")
def test_run_without_firmware_runs_c_and_logs_the_python_firmwares_bytes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    auto_log, python_log, report = tmp_path / "auto.log", tmp_path / "py.log", tmp_path / "r.json"
    drive = ["run", "--duration", "3", "--seed", "5"]
    code, out, err = run_cli(capsys, *drive, "--log", str(auto_log), "--report", str(report))
    assert (code, err) == (0, "")
    assert out.splitlines()[0] == f"{TITLE}, {TOOK_C}"
    assert json.loads(report.read_text())["inputs"]["firmware"] == {
        "name": "c", "auto": True,
        "why": "it built and loaded; --firmware python for the Python one"}
    code, out, err = run_cli(capsys, *drive, "--log", str(python_log), "--firmware", "python",
                             "--report", str(report))
    assert (code, err) == (0, "")
    assert out.splitlines()[0] == TITLE  # the Python one asked by name: the title as before
    assert json.loads(report.read_text())["inputs"]["firmware"] == {
        "name": "python", "auto": False, "why": ""}
    assert auto_log.stat().st_size > 20_000  # 3 s of every node's frames
    assert auto_log.read_bytes() == python_log.read_bytes()


@pytest.mark.usefixtures("c_builds")
def test_run_without_firmware_does_not_run_the_python_firmware(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Not the report's word alone: a Python firmware whose X is 2 LSB off FAILs when asked by
    name and leaves the default run (the C port) PASSing."""
    right = fw_frames.pack_odom_pose_x

    def two_lsb_off(counter: int, enc_counter: int, x_100um: int, heading_bam16: int,
                    errors: ErrorMask) -> bytes:
        return right(counter, enc_counter, x_100um + 2, heading_bam16, errors)

    monkeypatch.setattr(fw_frames, "pack_odom_pose_x", two_lsb_off)
    drive = ["run", "--duration", "2", "--seed", "5"]
    assert run_cli(capsys, *drive, "--firmware", "python")[0] == 1
    assert run_cli(capsys, *drive)[0] == 0


@pytest.mark.usefixtures("no_c")
def test_run_falls_back_to_python_naming_why(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "r.json"
    code, out, err = run_cli(capsys, "run", "--duration", "1", "--report", str(report))
    assert (code, err) == (0, "")
    assert out.splitlines()[0] == f"{TITLE}, {FELL_BACK}"
    assert json.loads(report.read_text())["inputs"]["firmware"] == {
        "name": "python", "auto": True, "why": f"the C firmware is unavailable: {NO_MAKE}"}
    code, out, err = run_cli(capsys, "run", "--duration", "1", "--firmware", "c")
    assert (code, out, err) == (2, "", f"error: {NO_MAKE}\n")  # asked by name: refused


@pytest.mark.usefixtures("c_builds")
def test_a_secoc_run_falls_back_when_the_c_library_takes_no_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A team's library of ABI 1 runs without a key but cannot verify SecOC: auto takes the
    Python firmware for a ``--secoc-key`` run (fleet's rule), and says why."""
    source, lib = tmp_path / "abi1.c", tmp_path / "libabi1.so"
    source.write_text(STUB_ABI1)
    subprocess.run(["cc", "-shared", "-fPIC", str(source), "-o", str(lib)], check=True)
    monkeypatch.setenv(cboard.LIBRARY_ENV, str(lib))
    key = tmp_path / "k.key"
    key.write_bytes(KEY)
    key.chmod(0o600)
    code, out, err = run_cli(capsys, "run", "--duration", "1", "--secoc-key", str(key))
    assert (code, err) == (0, "")
    assert out.splitlines()[0].startswith(
        f"{TITLE}, python firmware (auto: the C firmware is unavailable: --secoc-key: the C "
        f"firmware {lib} has ABI version 1"), out.splitlines()[0]


@pytest.mark.parametrize(("fixture", "words"), [("c_builds", TOOK_C), ("no_c", FELL_BACK)])
def test_the_firmware_node_says_its_auto_choice(
    fixture: str, words: str, request: pytest.FixtureRequest,
    capsys: pytest.CaptureFixture[str],
) -> None:
    request.getfixturevalue(fixture)
    channel = f"firmware-auto-{uuid.uuid4().hex}"
    assert main(["firmware", "-i", "virtual", "-c", channel, "--duration", "0.1"]) == 0
    err = capsys.readouterr().err
    assert err.startswith(f"odocan firmware: {words}, "), err
