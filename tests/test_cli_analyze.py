"""``odocan analyze LOG``: the offline check agrees with ``odocan run``; bad logs and DBCs.

The logs come from ``odocan run --log`` (one short run per format, same seed); analysing any of
them must give the very numbers the run itself reported.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cantools
import pytest

from odocan.host.cli.app import main
from tests.dbc_typed import load_can_dbc
from tests.test_cli_run import assert_usage_error, run_cli

DBC = Path(__file__).resolve().parents[1] / "dbc" / "odocan.dbc"
SAME_AS_RUN = (
    "robot",
    "integrator",
    "frames",
    "onboard_vs_reference",
    "onboard_vs_truth",
    "final_onboard_pose",
    "e2e",
    "passed",
)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same 5 s euler run logged as .log, .asc and .blf, and its report (key "report")."""
    folder = tmp_path_factory.mktemp("analyze")
    paths = {suffix: folder / f"run{suffix}" for suffix in (".log", ".asc", ".blf")}
    for suffix, path in paths.items():
        argv = [
            "run",
            "--duration",
            "5",
            "--seed",
            "9",
            "--integrator",
            "euler",
            "--log",
            str(path),
        ]
        if suffix == ".log":
            argv += ["--report", str(folder / "run.json")]
        assert main(argv) == 0
    paths["report"] = folder / "run.json"
    return paths


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_analyze_agrees_with_the_run(
    suffix: str, logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report_path = tmp_path / "analyze.json"
    code, out, err = run_cli(capsys, "analyze", str(logs[suffix]), "--report", str(report_path))
    assert (code, err) == (0, "")
    lines = out.splitlines()
    assert lines[0] == f"odocan analyze: {logs[suffix]}"
    assert lines[3] == "  run        integrator euler, scenario -, seed -"  # from ODOM_STATUS
    assert lines[-1].startswith("PASS: ")
    run_report = json.loads(logs["report"].read_text())
    report = json.loads(report_path.read_text())
    assert {k: report[k] for k in SAME_AS_RUN} == {k: run_report[k] for k in SAME_AS_RUN}
    assert report["wall_seconds"] is None
    assert report["scenario"] is None


def test_analyze_with_the_project_dbc_and_plot(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plot = tmp_path / "a.png"
    code, _, err = run_cli(
        capsys, "analyze", str(logs[".log"]), "--dbc", str(DBC), "--plot", str(plot)
    )
    assert (code, err) == (0, "")
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_analyze_fails_with_an_absurd_tolerance(
    logs: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run_cli(capsys, "analyze", str(logs[".blf"]), "--tolerance", "1e-12")
    assert (code, err) == (1, "")
    assert out.splitlines()[-1].startswith("FAIL: ")


def test_analyze_missing_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "none.log"
    assert_usage_error(capsys, main(["analyze", str(missing)]), str(missing))


def test_analyze_unreadable_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "dir.log"
    folder.mkdir()
    assert_usage_error(capsys, main(["analyze", str(folder)]), str(folder))


def test_analyze_log_without_permission(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    locked = tmp_path / "locked.log"
    locked.write_bytes(logs[".log"].read_bytes())
    locked.chmod(0)
    if os.geteuid() != 0:
        assert_usage_error(capsys, main(["analyze", str(locked)]), str(locked))
        return
    # Root reads files whatever their mode (and CI runs as root): drop the capabilities that let
    # it (util-linux's setpriv), so the command meets the permission error a user would.
    if shutil.which("setpriv") is None:
        pytest.fail("running as root without util-linux's setpriv: cannot drop CAP_DAC_OVERRIDE")
    done = subprocess.run(
        ["setpriv", "--bounding-set=-dac_override,-dac_read_search",
         sys.executable, "-m", "odocan", "analyze", str(locked)],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert done.returncode == 2, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("error: "), lines
    assert str(locked) in lines[0], lines


def test_analyze_malformed_log_names_the_line(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lines = logs[".log"].read_text().splitlines()
    lines[2] = "(0.000000) vcan0 this is not a frame"
    bad = tmp_path / "bad.log"
    bad.write_text("\n".join(lines) + "\n")
    assert_usage_error(capsys, main(["analyze", str(bad)]), f"{bad}:3:")


def test_analyze_unknown_log_format(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    odd = tmp_path / "frames.xyz"
    odd.write_text("nothing\n")
    assert_usage_error(capsys, main(["analyze", str(odd)]), str(odd))


def _write_dbc(db: cantools.database.can.Database, path: Path) -> Path:
    path.write_text(db.as_dbc_string())
    return path


def test_analyze_dbc_with_other_ids(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = load_can_dbc(DBC)
    db.get_message_by_name("WHEEL_ENCODERS").frame_id = 0x101
    db.refresh()
    other = _write_dbc(db, tmp_path / "other.dbc")
    code = main(["analyze", str(logs[".log"]), "--dbc", str(other)])
    assert_usage_error(capsys, code, "WHEEL_ENCODERS", "0x101", "does not match")


def test_analyze_dbc_with_other_data_ids(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = DBC.read_text()
    wheel = 'BA_ "E2EDataIDs" BO_ 256 "16,17,18,19,20,21,22,23,24,25,26,27,28,29,30,31";'
    assert wheel in text
    other = tmp_path / "ids.dbc"
    other_ids = ",".join(str(i) for i in range(160, 176))  # another message's data IDs
    other.write_text(text.replace(wheel, f'BA_ "E2EDataIDs" BO_ 256 "{other_ids}";'))
    code = main(["analyze", str(logs[".log"]), "--dbc", str(other)])
    assert_usage_error(capsys, code, "WHEEL_ENCODERS", "E2E", "does not match")


def test_analyze_counts_foreign_frames(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mixed = tmp_path / "mixed.log"
    mixed.write_text(logs[".log"].read_text() + "(9.000000) vcan0 123#0102\n" * 3)
    code, out, err = run_cli(capsys, "analyze", str(mixed))
    assert (code, err) == (0, "")
    assert "\n  unchecked  3 frames: unknown_id 3\n" in out


def test_analyze_dbc_without_the_pose(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = load_can_dbc(DBC)
    db.messages[:] = [m for m in db.messages if m.name != "ODOM_POSE_Y"]
    db.refresh()
    other = _write_dbc(db, tmp_path / "nopose.dbc")
    code = main(["analyze", str(logs[".log"]), "--dbc", str(other)])
    assert_usage_error(capsys, code, "does not define ODOM_POSE_Y")


def test_analyze_malformed_dbc(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.dbc"
    bad.write_text('VERSION ""\n\nBO_ xyz WHEEL_ENCODERS: 8 MOTOR_CTRL\n')
    code = main(["analyze", str(logs[".log"]), "--dbc", str(bad)])
    assert_usage_error(capsys, code, f"malformed DBC {bad}", "line 3")


def test_analyze_missing_dbc(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    missing = tmp_path / "none.dbc"
    code = main(["analyze", str(logs[".log"]), "--dbc", str(missing)])
    assert_usage_error(capsys, code, str(missing))


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--robot", "nosuchbot"], ["nosuchbot"]),
        (["--integrator", "midpoint"], ["midpoint"]),
        (["--plot", "p.gif"], ["p.gif"]),
        (["--tolerance", "pos=0"], ["--tolerance"]),
    ],
)
def test_analyze_bad_options(
    argv: list[str], words: list[str], logs: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    assert_usage_error(capsys, main(["analyze", str(logs[".log"]), *argv]), *words)


def test_analyze_needs_a_log(capsys: pytest.CaptureFixture[str]) -> None:
    assert_usage_error(capsys, main(["analyze"]), "LOG")
