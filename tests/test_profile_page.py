"""ODOM_STATUS page 6 (PROFILE): the firmware says on the bus what it runs with (issue #11 point 4).

Each page is decoded here with cantools and its PROFILE_CRC checked against a CRC-32 written in
this test from the DBC comment's definition (not the firmware's nor the host's code), for both
shipped profiles, every integrator, a custom profile, the Python and the C firmware. Then the host:
a log judged with a wrong ``--robot`` is named in one line by ``analyze``, ``replay`` and the
monitor's model; the judges take the bus's speed bound (a correct firmware is not failed because
the command line's bound is another); a log without the page (an older firmware's) is judged as
before.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.sim import robot
from odocan.sim.robot import RobotProfile
from tests.dbc_typed import load_can_dbc, numbers
from tests.requires import require_executables

ROOT = Path(__file__).resolve().parent.parent
DB = load_can_dbc(ROOT / "dbc" / "odocan.dbc")
INTEGRATOR_CODES = {"euler": 0, "rk2": 1, "exact": 2}
CUSTOM = """name = "odd32"
counts_per_rev = 16777216
wheel_radius_left_m = 0.5
wheel_radius_right_m = 0.499999937
wheelbase_m = 1.75
counter_bits = 32
max_wheel_speed_m_s = 0.123
"""


def crc32_iso_hdlc(data: bytes) -> int:
    """CRC-32/ISO-HDLC as the DBC comment defines it: reflected polynomial 0xEDB88320, init and
    xorout 0xFFFFFFFF, bit by bit."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xEDB88320 if crc & 1 else crc >> 1
    return crc ^ 0xFFFFFFFF


def parameter_bytes(profile: RobotProfile, integrator: str) -> bytes:
    """The 20 bytes of the DBC comment, from the profile's float metres."""
    fields = [(profile.counts_per_rev, 4), (round(profile.wheel_radius_left_m * 1e9), 4),
              (round(profile.wheel_radius_right_m * 1e9), 4), (round(profile.wheelbase_m * 1e9), 4),
              (profile.counter_bits, 1), (INTEGRATOR_CODES[integrator], 1),
              (round(profile.max_wheel_speed_m_s * 1000), 2)]
    return b"".join(value.to_bytes(size, "little") for value, size in fields)


def profile_pages(log: Path) -> list[dict[str, float | int]]:
    """Every ODOM_STATUS PROFILE page of a candump log, decoded by cantools."""
    status = DB.get_message_by_name("ODOM_STATUS")
    pages = []
    for msg in can.LogReader(str(log)):
        if msg.arbitration_id == status.frame_id:
            signals = numbers(DB, status.frame_id, msg.data)
            if signals["PAGE"] == 6:
                pages.append({**signals, "t_s": msg.timestamp})
    return pages


def run_log(path: Path, robot_arg: str, integrator: str, *extra: str) -> Path:
    argv = ["run", "--robot", robot_arg, "--integrator", integrator, "--duration", "1.5",
            "--seed", "2", "--log", str(path), *extra]
    assert main(argv) == 0
    return path


def test_the_crc_of_the_test_is_crc32_iso_hdlc() -> None:
    assert crc32_iso_hdlc(b"123456789") == 0xCBF43926  # the catalogue's check value


@pytest.mark.parametrize("integrator", ["euler", "rk2", "exact"])
@pytest.mark.parametrize("name", ["kobuki", "pmir", "odd32"])
def test_every_profile_page_carries_the_bound_and_the_crc_of_the_profile(
    name: str, integrator: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    robot_arg = name
    if name == "odd32":
        robot_arg = str(tmp_path / "odd32.toml")
        Path(robot_arg).write_text(CUSTOM)
    profile = robot.load(robot_arg)
    log = run_log(tmp_path / "drive.log", robot_arg, integrator)
    capsys.readouterr()
    pages = profile_pages(log)
    assert len(pages) == 2  # one rotation of six pages per 600 ms
    expected = crc32_iso_hdlc(parameter_bytes(profile, integrator))
    for page in pages:
        assert page["PROFILE_CRC"] == expected
        assert page["MAX_WHEEL_SPEED"] == pytest.approx(profile.max_wheel_speed_m_s, abs=1e-9)


@pytest.mark.parametrize("name", ["kobuki", "pmir"])
def test_the_c_firmware_sends_the_same_profile_page(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    require_executables("make", "cc", install="apt-get install gcc make")
    python_log = run_log(tmp_path / "py.log", name, "rk2")
    c_log = run_log(tmp_path / "c.log", name, "rk2", "--firmware", "c")
    capsys.readouterr()
    expected = crc32_iso_hdlc(parameter_bytes(robot.load(name), "rk2"))
    assert [p["PROFILE_CRC"] for p in profile_pages(c_log)] == [expected, expected]
    assert python_log.read_bytes() == c_log.read_bytes()


@pytest.fixture(scope="module")
def kobuki_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("profile") / "kobuki.log"
    assert main(["run", "--robot", "kobuki", "--duration", "3", "--log", str(path)]) == 0
    return path


def analyze_output(log: Path, robot_arg: str, capsys: pytest.CaptureFixture[str],
                   *extra: str) -> tuple[int, str]:
    capsys.readouterr()
    code = main(["analyze", str(log), "--robot", robot_arg, *extra])
    return code, capsys.readouterr().out


def test_analyze_names_another_robots_profile(
    kobuki_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out = analyze_output(kobuki_log, "pmir", capsys)
    assert code == 1
    said = [line for line in out.splitlines() if "profile mismatch" in line]
    assert said == ["  - profile mismatch: profile hash differs: the log's firmware runs with the "
                    "parameters of robot 'kobuki', not 'pmir' (--robot)"]


def test_analyze_names_the_speed_bound_and_the_integrator(
    kobuki_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    fast = tmp_path / "kobuki_fast.toml"
    kobuki = (ROOT / "odocan" / "sim" / "robots" / "kobuki.toml").read_text()
    fast.write_text(kobuki.replace("max_wheel_speed_m_s = 0.7", "max_wheel_speed_m_s = 4.0"))
    code, out = analyze_output(kobuki_log, str(fast), capsys)
    assert code == 0
    assert out.splitlines()[-1] == ("  - profile mismatch: the log's firmware runs with max wheel "
                                    "speed 0.7 m/s, --robot kobuki says 4 m/s")  # the file's name
    code, out = analyze_output(kobuki_log, "kobuki", capsys, "--integrator", "rk2")
    assert out.splitlines()[-1] == ("  - profile mismatch: the log's firmware runs with "
                                    "integrator exact, not rk2")
    code, out = analyze_output(kobuki_log, "kobuki", capsys)
    assert code == 0
    assert "mismatch" not in out


@pytest.fixture(scope="module")
def pmir_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("profile") / "pmir.log"
    assert main(["run", "--robot", "pmir", "--duration", "5", "--log", str(path)]) == 0
    return path


def slow_pmir(tmp_path: Path, max_wheel_speed_m_s: float) -> Path:
    """pmir's profile with another speed bound, named ``slow``."""
    slow = tmp_path / "slow.toml"
    pmir = (ROOT / "odocan" / "sim" / "robots" / "pmir.toml").read_text()
    slow.write_text(pmir.replace('name = "pmir"', 'name = "slow"').replace(
        "max_wheel_speed_m_s = 4.0", f"max_wheel_speed_m_s = {max_wheel_speed_m_s}"))
    return slow


def test_the_judge_takes_the_buss_speed_bound(
    pmir_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A pmir firmware (4 m/s bound) judged with a profile that says 0.1 m/s: the judge's own
    bound would refuse the genuine steps and FAIL a correct firmware; the bus's bound is used."""
    log, slow = pmir_log, slow_pmir(tmp_path, 0.1)
    for stream in ("never", "always"):  # the streamed judge reads the page from the log's head
        code, out = analyze_output(log, str(slow), capsys, "--stream", stream)
        assert code == 0, out
        assert out.splitlines()[-1] == ("  - profile mismatch: the log's firmware runs with max "
                                        "wheel speed 4 m/s, --robot slow says 0.1 m/s")


def batch_output(folder: Path, robot_arg: str, capsys: pytest.CaptureFixture[str],
                 *extra: str) -> tuple[int, list[str]]:
    """``analyze FOLDER`` (the batch, in this process): exit code and the summary's lines."""
    capsys.readouterr()
    code = main(["analyze", str(folder), "--robot", robot_arg, "--jobs", "1", *extra])
    return code, capsys.readouterr().out.splitlines()


def test_a_batch_names_the_one_log_of_another_robot(
    kobuki_log: Path, pmir_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``analyze logs/ --robot pmir`` over a pmir drive and a kobuki drive: the kobuki log's
    PROFILE page names it, as ``analyze LOG`` does (the batch used to say only what the pose
    fit found), in the summary and in its JSON report; the pmir log has nothing to say."""
    folder = tmp_path / "logs"
    folder.mkdir()
    shutil.copy(kobuki_log, folder / "kobuki.log")
    shutil.copy(pmir_log, folder / "pmir.log")
    code, lines = batch_output(folder, "pmir", capsys, "--report-dir", str(tmp_path / "json"))
    assert code == 1
    said = ("profile mismatch: profile hash differs: the log's firmware runs with the parameters "
            "of robot 'kobuki', not 'pmir' (--robot)")
    assert [line for line in lines if "profile mismatch" in line] == [
        f"  - {folder / 'kobuki.log'}: {said}"]
    reports = {Path(r["inputs"]["log"]["path"]).name: r for r in
               (json.loads(p.read_text()) for p in (tmp_path / "json").glob("*.json"))}
    assert reports["kobuki.log"]["diagnosis"][0] == said
    assert not reports["kobuki.log"]["passed"]
    assert reports["pmir.log"]["passed"]
    assert "diagnosis" not in reports["pmir.log"]


@pytest.mark.parametrize("stream", ["never", "always"])
def test_a_batch_takes_each_logs_speed_bound(
    pmir_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], stream: str
) -> None:
    """A pmir drive (4 m/s bound) in a folder judged with a 0.1 m/s profile: the batch judged
    it with the command line's bound, refused the genuine steps and failed a correct firmware;
    it takes the log's bound and says the mismatch, as ``analyze LOG`` does."""
    folder = tmp_path / "logs"
    folder.mkdir()
    shutil.copy(pmir_log, folder / "pmir.log")
    code, lines = batch_output(folder, str(slow_pmir(tmp_path, 0.1)), capsys, "--stream", stream)
    assert code == 0, lines
    assert lines[-2:] == [f"  - {folder / 'pmir.log'}: profile mismatch: the log's firmware runs "
                          "with max wheel speed 4 m/s, --robot slow says 0.1 m/s",
                          "1 PASS, 0 FAIL, 0 unreadable"]


def test_replay_names_another_robots_profile(
    kobuki_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["replay", str(kobuki_log), "--robot", "pmir"]) == 1
    captured = capsys.readouterr()
    said = ("profile mismatch: profile hash differs: the log's firmware runs with the parameters "
            "of robot 'kobuki', not 'pmir' (--robot)")
    assert f"  - {said}" in captured.out.splitlines()
    assert said in captured.err


def test_the_monitor_model_names_another_robots_profile(kobuki_log: Path) -> None:
    model = BusMonitor(robot.load("pmir"))
    for msg in can.LogReader(str(kobuki_log)):
        model.feed(msg)
    said = model.status["profile_mismatch"]
    assert said is not None
    assert "robot 'kobuki', not 'pmir'" in said
    assert [e["kind"] for e in model.events].count("profile") == 1
    right = BusMonitor(robot.load("kobuki"))
    for msg in can.LogReader(str(kobuki_log)):
        right.feed(msg)
    assert right.status["profile_mismatch"] is None
    assert right.status["max_wheel_speed_m_s"] == 0.7  # the bus's bound, which the judges take
    assert right.tracker.geometry.max_wheel_speed_mm_s == 700


def first_step_beyond(log: Path, profile: RobotProfile) -> float:
    """Bus time (s) of the first WHEEL_ENCODERS step beyond ``profile``'s speed bound over one
    10 ms period (its travel in counts, one count of slack, as the firmware's gate; the counts
    wrapping at the wire's width), by cantools."""
    encoders = DB.get_message_by_name("WHEEL_ENCODERS")
    bounds = [math.ceil(profile.max_wheel_speed_m_s * 0.01 * profile.counts_per_rev
                        / (2 * math.pi * radius_m)) + 1
              for radius_m in (profile.wheel_radius_left_m, profile.wheel_radius_right_m)]
    half = 1 << (min(profile.counter_bits, 24) - 1)  # the counts wrap at the wire's width
    prev: tuple[int, int] | None = None
    for msg in can.LogReader(str(log)):
        if msg.arbitration_id == encoders.frame_id:
            s = numbers(DB, encoders.frame_id, msg.data)
            counts = (int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))
            if prev is not None and any(abs((c - p + half) % (2 * half) - half) > b
                                        for c, p, b in zip(counts, prev, bounds, strict=True)):
                return float(msg.timestamp)
            prev = counts
    return math.inf


def test_the_monitor_takes_the_buss_bound_when_the_page_comes(
    pmir_log: Path, tmp_path: Path
) -> None:
    """A pmir firmware (4 m/s bound) watched by a monitor built for 0.25 m/s: the drive stays
    within 0.25 m/s until after the first PROFILE page (0.5 s) and goes beyond it then. The
    monitor's step gate kept the command line's bound until its next reference start (none on
    this drive): it refused the genuine steps from 0.58 s, re-primed on them 11 times, and
    said POSE WRONG, 253 mm, on a correct firmware. The gate takes the page's bound at once."""
    slow = robot.load(str(slow_pmir(tmp_path, 0.25)))
    pages = profile_pages(pmir_log)
    page_t_s = min(float(p["t_s"]) for p in pages)
    assert page_t_s < first_step_beyond(pmir_log, slow) < 1.0  # mid-drive, after the page
    model = BusMonitor(slow)
    last_t_s = 0.0
    for msg in can.LogReader(str(pmir_log)):
        model.feed(msg, now_s=msg.timestamp)
        last_t_s = msg.timestamp
    assert model.status["profile_mismatch"] == ("profile mismatch: the log's firmware runs with "
                                                "max wheel speed 4 m/s, --robot slow says 0.25 m/s")
    assert model.tracker.counter_restarts == 0
    assert model.tracker.vs_reference.max_dpos_m < POSITION_LSB_M
    assert model.health(last_t_s)["state"] == "OK"


def test_a_log_without_the_page_is_judged_as_before(
    kobuki_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An older firmware's log (the PROFILE pages cut out, ODOM_STATUS re-sequenced is not
    needed: the judges do not ask for its sequence): same verdicts, the pose fit still names the
    robot, no profile line."""
    old = tmp_path / "old.log"
    lines = kobuki_log.read_text().splitlines(keepends=True)
    kept = [line for line in lines if " 380#" not in line or line.split("#")[1][2] != "6"]
    assert len(lines) - len(kept) == 5
    old.write_text("".join(kept))
    code, out = analyze_output(old, "kobuki", capsys)
    assert code == 0
    assert "mismatch" not in out
    code, out = analyze_output(old, "pmir", capsys)
    assert code == 1
    assert "profile mismatch" not in out
    assert "  - robot mismatch: the log's poses fit robot 'kobuki', not 'pmir' (--robot)" in out
