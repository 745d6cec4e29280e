"""``odocan replay LOG``: a recorded drive re-run against the current firmware, and the player.

The logs come from ``odocan run --log`` (a short seeded run); replaying one with the same firmware
must give back the run's very on-board poses, frame for frame.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.sim.robot import load
from tests.independent_checker import Robot, check
from tests.synth_log import ENCODER_PERIOD_S, synthesize, wandering_drive
from tests.test_cli_run import assert_usage_error, run_cli

NO_PAGE = ("odocan replay: {}: judged as robot 'pmir' (the default: no PROFILE page in its first "
           "8192 frames; give --robot)\n")  # host.cli.robotchoice: said once the log is judged

POSE_IDS = {0x200, 0x201, 0x202}
SAME_AS_RUN = (
    "robot",
    "integrator",
    "onboard_vs_reference",
    "onboard_vs_truth",
    "final_onboard_pose",
    "samples",
    "passed",
)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 6 s random drive (seed 5, exact integrator): its log and its report."""
    folder = tmp_path_factory.mktemp("replay")
    paths = {"log": folder / "run.log", "report": folder / "run.json"}
    argv = ["run", "--duration", "6", "--seed", "5", "--log", str(paths["log"]),
            "--report", str(paths["report"])]
    assert main(argv) == 0
    return paths


def frames_of(path: Path, ids: set[int] | None = None) -> list[tuple[float, int, bytes]]:
    """(timestamp, ID, payload) of every frame of a log (of ``ids`` only, when given)."""
    return [(round(m.timestamp, 6), m.arbitration_id, bytes(m.data)) for m in can.LogReader(path)
            if ids is None or m.arbitration_id in ids]


def test_replay_reproduces_the_run(
    recorded: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report_path, log_out = tmp_path / "replay.json", tmp_path / "replay.log"
    code, out, err = run_cli(capsys, "replay", str(recorded["log"]), "--report",
                             str(report_path), "--log", str(log_out))
    assert (code, err) == (0, "")
    run, replay = json.loads(recorded["report"].read_text()), json.loads(report_path.read_text())
    assert set(replay) >= set(run)  # the same report contract, plus the replay section
    for key in SAME_AS_RUN:
        assert replay[key] == run[key], key
    section = replay["replay"]
    assert section["encoder_frames_fed"] == section["ticks"] == 600
    assert section["ticks_without_frame"] == 0
    assert section["onboard_vs_log"] == {
        "samples": 300, "identical": 300, "identical_before_gap": 300,
        "max_position_diff_m": 0.0, "max_position_diff_raw_m": 0.0, "max_heading_diff_rad": 0.0,
        "before_first_gap": 300, "max_position_diff_before_gap_m": 0.0,
        "max_resent_position_diff_m": 0.0, "max_position_drift_between_gaps_m": 0.0,
        "max_position_jump_excess_m": 0.0, "max_jump_allowance_m": 0.0, "jumps_compared": 0,
        "logged": 300, "log_starts_mid_drive": False, "holes": [], "heading_offsets_bam16": [],
        "not_compared": {"unnamed": 0, "unpaired": 0},  # every pose of the log compared
        "lone_halves": {"x": 0, "y": 0, "not_compared": 0},  # a lossless bus: none
    }
    assert (section["passed"], section["faults"], section["unjudged"]) == (True, [], None)
    # Bit-identical pose and twist frames, at the same times; the log's truth frames kept.
    assert frames_of(log_out, POSE_IDS) == frames_of(recorded["log"], POSE_IDS)
    assert frames_of(log_out, {0x700}) == frames_of(recorded["log"], {0x700})
    assert replay["frames"] == {k: v for k, v in run["frames"].items() if k != "MOTOR_CMD"}
    lines = out.splitlines()
    assert lines[0] == ("replay: 600 encoder frames fed in 600 ticks; on-board vs the log's at "
                        "300 encoder frames: 300 identical, max difference 0.0000 mm, 0.0000 mrad")
    assert lines[1] == f"odocan replay: {recorded['log']} on pmir, exact integrator"
    assert lines[-1].startswith("PASS: ")


def test_two_replays_of_one_log_write_the_same_bytes(
    recorded: dict[str, Path], tmp_path: Path
) -> None:
    """Lockstep is deterministic down to the log's bytes, channel name included (it was named
    after an object's address and differed from run to run)."""
    outs = [tmp_path / f"replay{i}.log" for i in (1, 2)]
    for out in outs:
        subprocess.run([sys.executable, "-m", "odocan", "replay", str(recorded["log"]),
                        "--log", str(out)], check=True, capture_output=True)
    assert outs[0].read_bytes() == outs[1].read_bytes()
    assert outs[0].stat().st_size > 0


@pytest.mark.parametrize("integrator", ["euler", "rk2"])
def test_replay_with_another_integrator(
    integrator: str, recorded: dict[str, Path], tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Another integrator: other poses; the replay FAILs naming the mismatch (within the
    tolerance it passed, trial 39), which a warning names up front; beyond the tolerance the
    departure names it too."""
    report_path = tmp_path / "replay.json"
    code, out, err = run_cli(capsys, "replay", str(recorded["log"]), "--integrator", integrator,
                             "--report", str(report_path))
    report = json.loads(report_path.read_text())
    departs = report["replay"]["onboard_vs_log"]["max_position_diff_m"] > 1e-4
    assert (code, err) == (1, f"warning: integrator mismatch: {recorded['log']}'s "
                           f"ODOM_STATUS reports exact, --integrator asks {integrator}: this "
                           "replays a firmware other than the one that recorded it\n")
    assert report["passed"] is False
    assert report["replay"]["passed"] is (not departs)
    assert (f"FAIL: integrator mismatch: the log's ODOM_STATUS reports exact, not {integrator} "
            "(--integrator)") in out.splitlines()
    if departs:
        lines = out.splitlines()
        assert "and: the replayed firmware departs from the log's" in lines  # FAIL: above
        assert lines[-1] == (f"  - integrator mismatch: the log's ODOM_STATUS reports exact, the "
                             f"replay ran {integrator}")
    vs_log = report["replay"]["onboard_vs_log"]
    assert vs_log["samples"] == 300
    assert vs_log["identical"] < vs_log["samples"]  # another integrator: other poses ...
    assert vs_log["max_heading_diff_rad"] == 0.0  # ... but the heading is integrator-free
    errors = report["onboard_vs_reference"]  # and within tolerance of its own reference
    assert errors["max_position_error_m"] <= report["tolerance"]["position_m"]
    assert errors["max_heading_error_rad"] <= report["tolerance"]["heading_rad"]


def test_replay_keeps_gaps_as_ticks_without_a_frame(
    recorded: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lines = recorded["log"].read_text().splitlines()
    dropped = [i for i, line in enumerate(lines) if " 100#" in line][200:230]
    gap_log = tmp_path / "gap.log"
    gap_log.write_text("\n".join(ln for i, ln in enumerate(lines) if i not in set(dropped)) + "\n")
    report_path = tmp_path / "replay.json"
    code, _, err = run_cli(capsys, "replay", str(gap_log), "--report", str(report_path))
    assert (code, err) == (0, "")
    section = json.loads(report_path.read_text())["replay"]
    assert (section["encoder_frames_fed"], section["ticks"]) == (570, 600)
    assert section["ticks_without_frame"] == 30
    vs_log = section["onboard_vs_log"]
    assert vs_log["identical"] == 100  # every pose before the gap
    assert vs_log["max_heading_diff_rad"] == 0.0  # the heading is exact across the gap


def test_a_hole_of_16_periods_in_the_recording_names_no_frame_before_it(
    recorded: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A recording that lost every frame for 16 encoder periods (2.0015 s to 2.1605 s): the
    first frame after the hole is a pose naming the encoder frame 16 periods after the one the
    last pose before it named, with the same 4-bit COUNTER. Resolved against the latest encoder
    frame in the log (2.000 s, 16 periods old) it landed on that frame: the replay compared a
    pose with the one 160 ms before it, called it a resend that moved 10 mm, and blamed the
    build (FAIL). The judges' age rule (``samples.named_targets``) names no frame for it."""
    lines = recorded["log"].read_text().splitlines()
    stamp = [float(line.split(")")[0][1:]) for line in lines]
    hole_log = tmp_path / "hole.log"
    hole_log.write_text("".join(ln + "\n" for ln, t in zip(lines, stamp, strict=True)
                                if not 2.0015 < t < 2.1605))
    kept = [ln for ln, t in zip(lines, stamp, strict=True) if t > 2.1605]
    assert kept[0].startswith("(2.161000) vcan0 200#")  # a pose comes first after the hole
    report_path = tmp_path / "replay.json"
    code, out, err = run_cli(capsys, "replay", str(hole_log), "--report", str(report_path))
    assert (code, err) == (0, ""), out
    vs_log = json.loads(report_path.read_text())["replay"]["onboard_vs_log"]
    assert (vs_log["before_first_gap"], vs_log["identical"]) == (101, 101)
    assert vs_log["max_position_diff_before_gap_m"] == vs_log["max_resent_position_diff_m"] == 0
    assert vs_log["max_heading_diff_rad"] == 0.0


def test_replay_feeds_only_frames_that_pass_e2e(
    recorded: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lines = recorded["log"].read_text().splitlines()
    encoders = [i for i, line in enumerate(lines) if " 100#" in line]
    for i in encoders[100:103]:  # flip a payload bit: the CRC no longer matches
        head, data = lines[i].split("#")
        lines[i] = f"{head}#{data[:4]}{int(data[4], 16) ^ 1:X}{data[5:]}"
    bad = tmp_path / "crc.log"
    bad.write_text("\n".join(lines) + "\n")
    report_path = tmp_path / "replay.json"
    code, _, err = run_cli(capsys, "replay", str(bad), "--report", str(report_path))
    assert (code, err) == (0, "")
    section = json.loads(report_path.read_text())["replay"]
    # all 600 reach the replayed firmware, as they reached the recording one, whose own E2E
    # check drops the 3 the host's refused (``replay_track.late_frames``): 3 ticks without one
    assert (section["encoder_frames_fed"], section["encoder_frames_rejected"]) == (600, 3)
    assert section["encoder_frames_fed_late"] == 3
    assert section["ticks_without_frame"] == 3


def test_replay_plot(
    recorded: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plot = tmp_path / "replay.svg"
    code, _, err = run_cli(capsys, "replay", str(recorded["log"]), "--plot", str(plot))
    assert (code, err) == (0, "")
    assert plot.read_text().lstrip().startswith("<?xml")


def test_replay_fails_with_an_absurd_tolerance(
    recorded: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run_cli(capsys, "replay", str(recorded["log"]), "--tolerance", "1e-9")
    assert code == 1
    assert out.splitlines()[-1].startswith("FAIL: ")


def test_replay_interrupted_checks_what_ran(
    recorded: dict[str, Path], monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from odocan.sim.board import FirmwareBoard

    run_tick = FirmwareBoard.run_tick
    ticks = [0]

    def tick_until_ctrl_c(board: FirmwareBoard) -> None:
        if ticks[0] == 150:
            raise KeyboardInterrupt
        ticks[0] += 1
        run_tick(board)

    monkeypatch.setattr(FirmwareBoard, "run_tick", tick_until_ctrl_c)
    code, out, err = run_cli(capsys, "replay", str(recorded["log"]))
    assert (code, err) == (130, "interrupted after 1.5 s of the log\n")
    assert "on-board vs the log's at 75 encoder frames: 75 identical" in out
    assert re.search(r"\nSTOPPED by SIGINT at 1\.5 s of \d+(\.\d+)? s: partial drive PASS", out)


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["/nonexistent/drive.log"], ["/nonexistent/drive.log", "no such log file"]),
        (["{garbage}"], ["garbage.log:2:"]),
        (["{no_encoders}"], ["no WHEEL_ENCODERS frame"]),
        (["{log}", "--robot", "nosuchbot"], ["nosuchbot"]),
        (["{log}", "--integrator", "midpoint"], ["midpoint"]),
        (["{log}", "--log", "out.txt"], ["out.txt", ".log"]),
        (["{log}", "--plot", "out.pdf"], ["out.pdf", ".png"]),
        (["{log}", "--report", "/nonexistent/dir/r.json"], ["/nonexistent/dir"]),
        (["{log}", "-i", "virtual"], ["-i/--interface", "only with --realtime"]),
        (["{log}", "--speed", "2"], ["--speed", "only with --realtime"]),
        (["{log}", "--realtime", "-i", "nosuchinterface"], ["nosuchinterface"]),
        (["{log}", "--realtime", "-i", "virtual", "--speed", "0"], ["--speed"]),
        (["{log}", "--realtime", "-i", "virtual", "--report", "r.json"], ["--report"]),
        (["{log}", "--realtime", "-i", "virtual", "--only", "NOPE"], ["--only", "NOPE"]),
        ([], ["LOG"]),
    ],
)
def test_replay_bad_input_is_one_line(
    argv: list[str], words: list[str], recorded: dict[str, Path], tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    garbage = tmp_path / "garbage.log"
    garbage.write_text("(0.000000) vcan0 100#8F00000000000000\nthis is not candump\n")
    no_encoders = tmp_path / "no_encoders.log"
    no_encoders.write_text("".join(ln + "\n" for ln in recorded["log"].read_text().splitlines()
                                   if " 700#" in ln))
    paths = {"log": recorded["log"], "garbage": garbage, "no_encoders": no_encoders}
    argv = [a.format(**paths) if a.startswith("{") else a for a in argv]
    assert_usage_error(capsys, main(["replay", *argv]), *words)


def test_replay_realtime_plays_the_log_onto_a_bus(
    recorded: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    short = tmp_path / "short.log"  # the first half second
    short.write_text("".join(ln + "\n" for ln in recorded["log"].read_text().splitlines()
                             if float(ln[1:ln.index(")")]) < 0.5))
    expected = frames_of(short)
    heard: list[can.Message] = []
    with can.Bus(interface="virtual", channel="odocan-test-replay-rt") as listener:
        def listen() -> None:
            while len(heard) < len(expected) and (msg := listener.recv(5.0)) is not None:
                heard.append(msg)

        thread = threading.Thread(target=listen, name="listener")
        thread.start()
        code, out, err = run_cli(capsys, "replay", str(short), "--realtime", "-i", "virtual",
                                 "-c", "odocan-test-replay-rt", "--speed", "10")
        thread.join(10)
    assert (code, err) == (0, "")
    assert re.fullmatch(rf"replay: {len(expected)} of {len(expected)} frames played in "
                        r"\d+\.\d\d s \(10x the recorded timing\)\n", out), out
    assert [(m.arbitration_id, bytes(m.data)) for m in heard] == [f[1:] for f in expected]
    # Timing, loosely: the last frame comes after the first (the log spans 0.49 s).
    assert heard[-1].timestamp > heard[0].timestamp


def test_replay_realtime_only_some_messages(
    recorded: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    short = tmp_path / "short.log"
    short.write_text("".join(ln + "\n" for ln in recorded["log"].read_text().splitlines()[:100]))
    with can.Bus(interface="virtual", channel="odocan-test-replay-only") as listener:
        code, out, err = run_cli(capsys, "replay", str(short), "--realtime", "-i", "virtual",
                                 "-c", "odocan-test-replay-only", "--speed", "50",
                                 "--only", "WHEEL_ENCODERS,SIM_TRUTH")
        heard = []
        while (msg := listener.recv(0)) is not None:
            heard.append(msg)
    assert (code, err) == (0, "")
    expected = frames_of(short, {0x100, 0x700})
    assert [(m.arbitration_id, bytes(m.data)) for m in heard] == [f[1:] for f in expected]
    assert out.startswith(f"replay: {len(expected)} of {len(expected)} frames played")


def test_replay_a_log_without_firmware_frames(
    recorded: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A recording of the motor controller alone (encoders and truth): the firmware runs on it
    for the first time; the integrator is then the default, exact."""
    only = tmp_path / "motor_controller.log"
    only.write_text("".join(ln + "\n" for ln in recorded["log"].read_text().splitlines()
                            if " 100#" in ln or " 700#" in ln))
    report_path = tmp_path / "replay.json"
    code, out, err = run_cli(capsys, "replay", str(only), "--report", str(report_path))
    assert (code, err) == (0, NO_PAGE.format(only))  # no firmware frame: the default robot
    assert out.splitlines()[0] == "replay: the log has no on-board pose to compare with"
    report, run = json.loads(report_path.read_text()), json.loads(recorded["report"].read_text())
    assert report["integrator"] == "exact"
    assert report["final_onboard_pose"] == run["final_onboard_pose"]
    assert report["replay"]["onboard_vs_log"]["samples"] == 0


@pytest.fixture(scope="module")
def kobuki_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 6 s random drive of kobuki (seed 5)."""
    path = tmp_path_factory.mktemp("kobuki") / "k.log"
    assert main(["run", "--robot", "kobuki", "--duration", "6", "--seed", "5", "--log",
                 str(path)]) == 0
    return path


def test_replay_on_the_wrong_robot_fails_and_names_the_right_one(
    kobuki_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue #11: a kobuki log replayed on pmir used to print PASS, 14 m off (pmir was the
    default then; without --robot the log's PROFILE page now picks kobuki: test_robot_from_log)."""
    report_path = tmp_path / "replay.json"
    code, out, err = run_cli(capsys, "replay", str(kobuki_log), "--robot", "pmir",
                             "--report", str(report_path))
    said = ("profile mismatch: profile hash differs: the log's firmware runs with the parameters "
            "of robot 'kobuki', not 'pmir' (--robot)")  # its ODOM_STATUS PROFILE page says so
    assert (code, err) == (1, f"warning: {said}\n")  # up front, then as the departure's cause
    lines = out.splitlines()
    at = lines.index("FAIL: the replayed firmware departs from the log's")
    assert lines[at + 1].startswith("  - its position differs from the log's by up to ")
    assert lines[at + 2].startswith("  - its heading differs from the log's by up to ")
    assert lines[at + 3:] == [f"  - {said}", "  - robot mismatch: the log's poses fit robot "
                              "'kobuki', not 'pmir' (--robot)"]
    report = json.loads(report_path.read_text())
    assert report["passed"] is False
    assert report["replay"]["faults"] == [
        line[4:] for line in lines[at + 1:]]
    code, out, _ = run_cli(capsys, "replay", str(kobuki_log), "--robot", "kobuki")
    assert code == 0
    assert "departs" not in out


def test_replay_on_a_custom_robot_names_the_shipped_one_that_fits(
    kobuki_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A custom profile the log was not recorded with: the shipped one that fits is named."""
    custom = tmp_path / "odd.toml"
    custom.write_text('name = "odd"\ncounts_per_rev = 4000\nwheel_radius_left_m = 0.04\n'
                      'wheel_radius_right_m = 0.04\nwheelbase_m = 0.3\ncounter_bits = 32\n')
    code, out, _ = run_cli(capsys, "replay", str(kobuki_log), "--robot", str(custom),
                           "--integrator", "exact")
    assert code == 1
    assert out.splitlines()[-2:] == [
        "  - profile mismatch: profile hash differs: the log's firmware runs with the parameters "
        "of robot 'kobuki', not 'odd' (--robot)",
        "  - robot mismatch: the log's poses fit robot 'kobuki', not 'odd' (--robot)"]


def test_replay_reproduces_a_log_written_with_the_firmwares_integers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A log written directly (tests/synth_log.py: the firmware's Odometry and codec, the ECU's
    rounding) is what the ECU itself sends: replayed, every pose is identical, and the
    independent checker agrees; on another robot it departs and the right one is named."""
    profile = load("pmir")
    d_left, d_right = wandering_drive(profile, 1500, 0.01, seed=4)
    synth = synthesize(profile, "rk2", d_left, d_right)
    log = synth.write(tmp_path / "synth.log")
    report_path = tmp_path / "replay.json"
    code, _, err = run_cli(capsys, "replay", str(log), "--report", str(report_path))
    assert (code, err) == (0, NO_PAGE.format(log))
    vs_log = json.loads(report_path.read_text())["replay"]["onboard_vs_log"]
    assert vs_log["samples"] == vs_log["identical"] == 751
    assert check(log, Robot(**profile.firmware_params()), "rk2",
                 lambda t_s: synth.state[round(t_s / ENCODER_PERIOD_S)].pose).passed
    code, out, _ = run_cli(capsys, "replay", str(log), "--robot", "kobuki")
    assert code == 1
    assert out.splitlines()[-1] == (
        "  - robot mismatch: the log's poses fit robot 'pmir', not 'kobuki' (--robot)")
