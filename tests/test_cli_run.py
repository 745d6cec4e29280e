"""``odocan run``: summary, report contract, plots, exit codes and bad input (cantools style).

Every test calls ``host.cli.main(argv)`` and checks stdout, stderr and the exit code. Runs are
kept to a few simulated seconds (about 0.05 s of wall time each).
"""

from __future__ import annotations

import json
import math
import re
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from tests.dbc_typed import decode, load_can_dbc

LSB_POSITION_M = 1e-4
LSB_HEADING_RAD = 2 * math.pi / 65536
ROBOT_KEYS = {
    "name": str,
    "counts_per_rev": int,
    "wheel_radius_left_m": float,
    "wheel_radius_right_m": float,
    "wheelbase_m": float,
    "counter_bits": int,
    "max_wheel_speed_m_s": float,
}
ERROR_KEYS = (
    "max_position_error_m",
    "max_heading_error_rad",
    "final_position_error_m",
    "final_heading_error_rad",
)
E2E_KEYS = ("ok", "lost", "repeated", "crc_errors", "wrong_sequence")


def assert_usage_error(capsys: pytest.CaptureFixture[str], code: int, *words: str) -> str:
    """Exit 2, nothing on stdout, exactly one line ``error: ...`` on stderr naming ``words``."""
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    assert "Traceback" not in err
    for word in words:
        assert word in lines[0], (word, lines[0])
    return lines[0]


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    """``main(argv)`` and what it printed."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


SUMMARY_HEAD = """\
odocan run: random on pmir, exact integrator
  robot      pmir, 500 counts/rev, 16-bit counters
  geometry   wheel radii 0.075/0.075 m, wheelbase 0.3 m
  run        integrator exact, scenario random, seed 4
  time       3.00 s simulated in <WALL> s (<FACTOR>x real time)
  start      exact from power-up: (0, 0, 0) at the frame the firmware primed on
  judged     150 of 150 on-board poses compared with the reference (100 %)
  distance   0.115 m travelled
  final pose x -0.0128 m, y 0.0282 m, heading 0.8420 rad (48.24 deg)

  message          frames   E2E ok   lost   repeated   CRC err   wrong seq
  ────────────────────────────────────────────────────────────────────────
"""
SUMMARY_TAIL = """\

  on-board vs   max position   final position   max heading   final heading
  ─────────────────────────────────────────────────────────────────────────
  reference        0.0665 mm        0.0298 mm   0.0476 mrad     0.0169 mrad
  truth            0.9000 mm        0.5000 mm   2.5886 mrad     1.8216 mrad

PASS: on-board vs reference within 0.1 mm and 0.09587 mrad
"""


def test_run_prints_the_summary(capsys: pytest.CaptureFixture[str]) -> None:
    # the Python firmware's whole summary (the default, auto, may take C: its title says so)
    code, out, err = run_cli(capsys, "run", "--duration", "3", "--seed", "4",
                             "--firmware", "python")
    assert (code, err) == (0, "")
    out = re.sub(r"in \d+\.\d\d s \(\d+x", "in <WALL> s (<FACTOR>x", out)
    lines = [line.rstrip() for line in out.splitlines(keepends=False)]
    head, tail = SUMMARY_HEAD.splitlines(), SUMMARY_TAIL.splitlines()
    assert lines[: len(head)] == head
    assert lines[-len(tail) :] == tail
    rows = [line.split() for line in lines[len(head) : -len(tail)]]
    # The frames table: one row per message, every frame accepted by its E2E check, then the total.
    assert rows[0] == ["WHEEL_ENCODERS", "300", "300", "0", "0", "0", "0"]
    assert {row[0] for row in rows} >= {"MOTOR_CMD", "ODOM_POSE_X", "ODOM_POSE_Y", "SIM_TRUTH"}
    for row in rows[:-1]:
        assert row[1] == row[2], row
        assert row[3:] == ["0", "0", "0", "0"], row
    assert rows[-1] == ["total", str(sum(int(row[1]) for row in rows[:-1]))]


def test_run_report_has_the_contract_keys(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report_path = tmp_path / "report.json"
    code, _, err = run_cli(
        capsys,
        "run",
        "--scenario",
        "circle",
        "--duration",
        "4",
        "--integrator",
        "rk2",
        "--seed",
        "3",
        "--report",
        str(report_path),
    )
    assert (code, err) == (0, "")
    report = json.loads(report_path.read_text())
    assert set(report) >= {
        "robot",
        "integrator",
        "scenario",
        "seed",
        "sim_seconds",
        "wall_seconds",
        "realtime_factor",
        "frames",
        "onboard_vs_reference",
        "onboard_vs_truth",
        "final_onboard_pose",
        "e2e",
        "passed",
    }
    assert {key: type(report["robot"][key]) for key in ROBOT_KEYS} == ROBOT_KEYS
    assert report["robot"]["name"] == "pmir"
    assert (report["integrator"], report["scenario"], report["seed"]) == ("rk2", "circle", 3)
    assert report["sim_seconds"] == pytest.approx(4.0, abs=0.02)
    assert report["realtime_factor"] == pytest.approx(
        report["sim_seconds"] / report["wall_seconds"], rel=1e-6
    )
    assert report["frames"]["WHEEL_ENCODERS"] == 400
    assert all(isinstance(n, int) and n > 0 for n in report["frames"].values())
    reference, truth = report["onboard_vs_reference"], report["onboard_vs_truth"]
    for key in ERROR_KEYS:
        assert isinstance(reference[key], float), key
        assert isinstance(truth[key], float), key
    for key in ("max_position_error_m", "final_position_error_m"):
        assert 0 <= reference[key] <= LSB_POSITION_M
    for key in ("max_heading_error_rad", "final_heading_error_rad"):
        assert abs(reference[key]) <= LSB_HEADING_RAD
    assert abs(reference["final_heading_error_rad"]) <= reference["max_heading_error_rad"]
    assert report["onboard_vs_truth"]["distance_travelled_m"] > 0.5  # 0.5 m/s for ~3 s
    assert set(report["final_onboard_pose"]) == {"x_m", "y_m", "heading_rad",
                                                 "heading_unwrapped_rad"}
    assert set(report["e2e"]) >= {"WHEEL_ENCODERS"}
    for counts in report["e2e"].values():
        assert set(counts) >= set(E2E_KEYS)
    assert report["e2e"]["WHEEL_ENCODERS"]["lost"] == 0
    assert report["passed"] is True


@pytest.mark.parametrize("suffix", [".png", ".svg"])
def test_run_plot_writes_a_valid_image(
    suffix: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plot = tmp_path / f"run{suffix}"
    code, _, err = run_cli(capsys, "run", "--duration", "3", "--plot", str(plot))
    assert (code, err) == (0, "")
    data = plot.read_bytes()
    if suffix == ".png":
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        width, height = struct.unpack(">II", data[16:24])
        assert (width, height) == (1700, 950)  # 17 x 9.5 inches at 100 dpi
    else:
        root = ET.fromstring(data)
        assert root.tag == "{http://www.w3.org/2000/svg}svg"
        text = data.decode()
        for label in ("trajectory", "on-board - truth, position", "distance travelled (m)"):
            assert label in text or label.replace(" ", "") in text


def test_run_fails_with_an_absurd_tolerance(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(capsys, "run", "--duration", "3", "--tolerance", "1e-12")
    assert (code, err) == (1, "")
    assert out.splitlines()[-1] == (
        "FAIL: on-board vs reference within 1e-09 mm and 0.09587 mrad: not met"
    )


def test_run_tolerance_keys(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(capsys, "run", "--duration", "3", "--tolerance", "heading=1e-9,pos=1")
    assert code == 1
    assert out.splitlines()[-1].endswith("within 1000 mm and 1e-06 mrad: not met")


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_run_log_formats(suffix: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, report = tmp_path / f"run{suffix}", tmp_path / "run.json"
    code, _, err = run_cli(
        capsys, "run", "--duration", "2", "--log", str(log), "--report", str(report)
    )
    assert (code, err) == (0, "")
    frames = list(can.LogReader(log))
    assert len(frames) == sum(json.loads(report.read_text())["frames"].values())
    assert sum(msg.arbitration_id == 0x100 for msg in frames) == 200


def test_run_mirrors_frames_to_another_bus(capsys: pytest.CaptureFixture[str]) -> None:
    with can.Bus(interface="virtual", channel="odocan-test-mirror") as listener:
        code, out, err = run_cli(
            capsys, "run", "--duration", "0.3", "-i", "virtual", "-c", "odocan-test-mirror"
        )
        frames = []
        while (msg := listener.recv(0)) is not None:
            frames.append(msg)
    assert (code, err) == (0, "")
    total = re.search(r"\n  total +(\d+) *\n", out)
    assert total, out
    assert len(frames) == int(total.group(1))
    assert sum(msg.arbitration_id == 0x100 for msg in frames) == 30


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--scenario", "zigzag"], ["zigzag", "--scenario"]),
        (["--robot", "nosuchbot"], ["nosuchbot", "pmir"]),
        (["--robot", "/nonexistent/robot.toml"], ["/nonexistent/robot.toml"]),
        (["--integrator", "midpoint"], ["midpoint"]),
        (["--interface", "nosuchinterface"], ["nosuchinterface"]),
        (["--duration", "-1"], ["--duration", "-1"]),
        (["--duration", "0"], ["--duration"]),
        (["--duration", "nan"], ["--duration"]),
        (["--duration", "soon"], ["--duration", "soon"]),
        (["--seed", "x"], ["--seed"]),
        (["--errors", "ed=9"], ["ed=9"]),
        (["--errors", "wobble=1"], ["wobble"]),
        (["--log", "out.txt"], ["out.txt", ".log"]),
        (["--log", "/nonexistent/dir/out.log"], ["/nonexistent/dir"]),
        (["--plot", "out.pdf"], ["out.pdf", ".png"]),
        (["--report", "/nonexistent/dir/r.json"], ["/nonexistent/dir"]),
        (["--tolerance", "-1"], ["--tolerance"]),
        (["--tolerance", "pos=1e-4,yaw=1"], ["--tolerance"]),
        (["--bogus"], ["--bogus"]),
    ],
)
def test_run_bad_input_is_one_line(
    argv: list[str], words: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert_usage_error(capsys, main(["run", "--duration", "1", *argv]), *words)


def test_run_bad_input_traceback_with_debug(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--debug", "run", "--robot", "nosuchbot"]) == 2
    err = capsys.readouterr().err
    assert "ProfileError" in err
    assert "Traceback" in err
    assert "nosuchbot" in err


def test_run_from_a_profile_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    profile = tmp_path / "tiny.toml"
    profile.write_text(
        "counts_per_rev = 2048\nwheel_radius_left_m = 0.05\nwheel_radius_right_m = 0.0501\n"
        "wheelbase_m = 0.2\ncounter_bits = 32\n"
    )
    code, out, err = run_cli(capsys, "run", "--robot", str(profile), "--duration", "2")
    assert (code, err) == (0, "")
    assert out.splitlines()[1:3] == [
        "  robot      tiny, 2048 counts/rev, 32-bit counters",
        "  geometry   wheel radii 0.05/0.0501 m, wheelbase 0.2 m",
    ]


def test_run_interrupted_checks_what_ran(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from odocan.sim.rig import LockstepRig

    work = LockstepRig._work  # each tick's, however the run steps (a second at once or not)

    def work_until_ctrl_c(rig: LockstepRig, k: int) -> None:
        if rig.ticks == 150:
            raise KeyboardInterrupt
        work(rig, k)

    monkeypatch.setattr(LockstepRig, "_work", work_until_ctrl_c)
    code, out, err = run_cli(capsys, "run", "--duration", "100")
    assert (code, err) == (130, "interrupted after 1.5 s simulated\n")
    assert re.search(r"\n  WHEEL_ENCODERS +150 +150 ", out), out
    verdict = out.splitlines()[-1]
    assert verdict.startswith("STOPPED by SIGINT at 1.5 s of 100 s: partial drive PASS"), verdict


def test_run_random_drives_for_a_longer_duration(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "long.log"
    code, _, err = run_cli(capsys, "run", "--duration", "66", "--seed", "1", "--log", str(log))
    assert (code, err) == (0, "")
    db = load_can_dbc(Path(__file__).resolve().parents[1] / "dbc" / "odocan.dbc")
    speeds = {
        round(msg.timestamp, 2): decode(db, msg.arbitration_id, msg.data)
        for msg in can.LogReader(log)
        if msg.arbitration_id == db.get_message_by_name("MOTOR_CMD").frame_id
    }
    moving = [t for t, s in speeds.items() if s["LEFT_SPEED"] or s["RIGHT_SPEED"]]
    assert 64.9 <= max(moving) < 65.0  # the random program runs until 1 s before the end


def test_report_is_strict_json(tmp_path: Path) -> None:
    import numpy as np

    from odocan.host.jsonutil import write_report

    path = tmp_path / "r.json"
    write_report(path, {"a": np.float64(np.nan), "b": [np.int64(3), math.inf], "c": {"d": 1.5}})
    assert json.loads(path.read_text()) == {"a": None, "b": [3, None], "c": {"d": 1.5}}
