"""Every pose frame the firmware sends is judged, not only the first naming an encoder frame
(issue #11, ``host.judge.resent``): after lost encoder frames (drop, burst, bus-off), the
firmware resends its pose naming the same ENC_COUNTER. The correct firmware's resends PASS
(whole and streamed alike, and they agree); one resent half moved (X by 20 mm, Y by 20 mm, or
HEADING by 20 LSB, the CRC made good) FAILs in ``analyze``, ``analyze --stream always`` and
``replay``. The edit is checked by hand in the test: the frame edited is a resend (the
ENC_COUNTER of its kind's previous frame, fewer than 8 encoder frames on) and its pose is
off from the unedited one by the amount set."""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import parse_candump, parse_candump_line
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from tests.test_trial_judge_holes import _crc

POSE_IDS = {"X": 0x200, "Y": 0x201, "HEADING": 0x200}
DATA_ID_SLOT = {0x200: 3, 0x201: 4}  # the DBC's E2E slots: data IDs 48.., 64..
ENCODERS = 0x100


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, str]]:
    """Runs of the correct firmware with many resends, and the robot of each."""
    base = tmp_path_factory.mktemp("resent")
    runs = {"drop": "drop=0.3,seed=5", "burst": "burst=0.05:6,seed=3",
            "busoff": "busoff=4:1,drop=0.2,seed=9"}
    out: dict[str, tuple[Path, str]] = {}
    for name, faults in runs.items():
        log = base / f"{name}.log"
        assert main(["run", "--robot", "kobuki", "--duration", "8", "--seed", "3",
                     "--faults", faults, "--log", str(log)]) == 0
        out[name] = (log, "kobuki")
    return out


def _resends(lines: list[str], ident: int) -> list[int]:
    """Lines of ``ident`` frames with their kind's previous frame's ENC_COUNTER, fewer than 8
    encoder frames after it (the firmware ticked without a new one, or held its pose, and sent
    it again)."""
    found, previous, between = [], None, 0
    for i, line in enumerate(lines):
        frame = line.split()[2]
        if frame.startswith(f"{ENCODERS:03X}#"):
            between += 1
        elif frame.startswith(f"{ident:03X}#"):
            counter = bytes.fromhex(frame[4:])[1] >> 4
            if counter == previous and between < 8:
                found.append(i)
            previous, between = counter, 0
    return found


def _moved(line: str, field: str) -> str:
    """The pose frame of ``line`` with ``field`` moved (X, Y: 200 LSB = 20 mm; HEADING: 20
    LSB), its CRC made good."""
    stamp, channel, frame = line.split()[:3]
    ident, data = int(frame[:3], 16), bytearray.fromhex(frame[4:])
    if field == "HEADING":
        data[6:8] = ((int.from_bytes(data[6:8], "little") + 20) & 0xFFFF).to_bytes(2, "little")
    else:
        value = int.from_bytes(data[2:6], "little", signed=True) + 200
        data[2:6] = value.to_bytes(4, "little", signed=True)
    data[0] = _crc(bytes(data), (DATA_ID_SLOT[ident] << 4) | (data[1] & 0xF))
    return " ".join([stamp, channel, f"{ident:03X}#{data.hex().upper()}", *line.split()[3:]])


def _verdicts(log: Path, robot: str, commands: list[list[str]]) -> list[int]:
    return [main([*command, str(log), "--robot", robot]) for command in commands]


WHOLE, STREAMED = ["analyze", "--stream", "never"], ["analyze", "--stream", "always"]


@pytest.mark.parametrize("run", ["drop", "burst", "busoff"])
@pytest.mark.parametrize("field", ["X", "Y", "HEADING"])
def test_a_moved_resend_fails_and_the_correct_ones_pass(
    logs: dict[str, tuple[Path, str]], tmp_path: Path, run: str, field: str
) -> None:
    log, robot = logs[run]
    lines = log.read_text().splitlines()
    resends = _resends(lines, POSE_IDS[field])
    assert resends, "the premise: the run resends its pose"
    assert _verdicts(log, robot, [WHOLE, STREAMED]) == [0, 0]  # the correct firmware PASSes
    k = resends[len(resends) // 2]
    edited = list(lines)
    edited[k] = _moved(lines[k], field)
    before, after = (bytes.fromhex(x.split()[2][4:]) for x in (lines[k], edited[k]))
    offset = 6 if field == "HEADING" else 2
    width = 2 if field == "HEADING" else 4
    moved = (int.from_bytes(after[offset:offset + width], "little", signed=width == 4)
             - int.from_bytes(before[offset:offset + width], "little", signed=width == 4))
    assert moved == (20 if field == "HEADING" else 200)
    assert after[1] == before[1]  # COUNTER and ENC_COUNTER as sent
    path = tmp_path / "edited.log"
    path.write_text("\n".join(edited) + "\n")
    assert _verdicts(path, robot, [WHOLE, STREAMED]) == [1, 1]


def test_a_moved_resent_y_fails_the_replay(logs: dict[str, tuple[Path, str]],
                                           tmp_path: Path) -> None:
    log, robot = logs["drop"]
    lines = log.read_text().splitlines()
    k = _resends(lines, 0x201)[3]
    lines[k] = _moved(lines[k], "Y")
    path = tmp_path / "edited.log"
    path.write_text("\n".join(lines) + "\n")
    assert _verdicts(log, robot, [["replay"]]) == [0]
    assert _verdicts(path, robot, [["replay"]]) == [1]


@pytest.mark.parametrize("field", ["X", "Y"])
def test_the_live_judge_sees_a_moved_resend_as_analyze_does(
        logs: dict[str, tuple[Path, str]], field: str) -> None:
    """The monitor and the bridge (one tracker each, ``host.judge.liveresent``) see the resend
    20 mm off, as large as ``analyze`` sees it, and count the samples ``analyze`` counts."""
    log, robot_name = logs["drop"]
    lines = log.read_text().splitlines()
    k = _resends(lines, POSE_IDS[field])[3]
    lines[k] = _moved(lines[k], field)
    messages = [m for m in (parse_candump_line(x.encode()) for x in lines) if m is not None]
    profile = robot.load(robot_name)
    result = analyze(parse_candump(("\n".join(lines) + "\n").encode()), profile)
    offline = result.report["onboard_vs_reference"]
    assert offline["max_position_error_m"] > 0.015  # the 20 mm seen
    monitor = BusMonitor(profile)
    bridge = RobotTelemetry("r", Geometry.of(profile), result.report["integrator"],
                            counter_bits=profile.counter_bits, publish_hz=10)
    for msg in messages:
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(msg)
    for live in (monitor.tracker.vs_reference, bridge.tracker.vs_reference):
        assert live.samples == result.report["samples"]["onboard"]
        assert live.max_dpos_m == pytest.approx(offline["max_position_error_m"], abs=1e-12)
        assert live.max_dheading_rad == pytest.approx(offline["max_heading_error_rad"],
                                                      abs=1e-12)
