"""Every ODOM_TWIST frame is judged, not only the first naming an encoder frame (issue #11,
``host.judge.resentdistance``): after lost encoder frames (drop, burst, bus-off) the firmware
resends ODOM_TWIST naming the same ENC_COUNTER. The correct firmware's resends PASS (whole,
streamed and live alike); one resent DISTANCE moved by 20 mm (the CRC made good) FAILs in
``analyze``, ``analyze --stream always`` and the monitor. The edit is checked by hand in the
test: the frame edited is a resend (its predecessor's ENC_COUNTER, fewer than 8 encoder frames
on), its DISTANCE is 20 LSB off the unedited one and equal to its predecessor's before the edit
(a correct firmware's resend carries the first's DISTANCE: nothing moves it but an encoder
frame)."""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import parse_candump_line
from odocan.host.judge.monitor import BusMonitor
from odocan.sim import robot
from tests.test_trial_judge_holes import _crc

TWIST, ENCODERS, TWIST_SLOT = 0x202, 0x100, 5
OFFSETS = {"DISTANCE": (6, False), "LINEAR_VEL": (2, True), "ANGULAR_VEL": (4, True)}


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Runs of the correct firmware with many resends."""
    base = tmp_path_factory.mktemp("resentdist")
    runs = {"drop": "drop=0.3,seed=5", "burst": "burst=0.05:6,seed=3",
            "busoff": "busoff=4:1,drop=0.2,seed=9"}
    out: dict[str, Path] = {}
    for name, faults in runs.items():
        log = base / f"{name}.log"
        assert main(["run", "--robot", "kobuki", "--duration", "8", "--seed", "3",
                     "--faults", faults, "--log", str(log)]) == 0
        out[name] = log
    return out


def _payload(line: str) -> bytes:
    return bytes.fromhex(line.split()[2][4:])


def _resends(lines: list[str]) -> list[tuple[int, int]]:
    """(line, its predecessor's line) of ODOM_TWIST frames naming the previous one's
    ENC_COUNTER, fewer than 8 encoder frames after it."""
    found: list[tuple[int, int]] = []
    previous: tuple[int | None, int] = (None, -1)
    between = 0
    for i, line in enumerate(lines):
        frame = line.split()[2]
        if frame.startswith(f"{ENCODERS:03X}#"):
            between += 1
        elif frame.startswith(f"{TWIST:03X}#"):
            counter = _payload(line)[1] >> 4
            if counter == previous[0] and between < 8:
                found.append((i, previous[1]))
            previous, between = (counter, i), 0
    return found


def _field(data: bytes, name: str) -> int:
    offset, signed = OFFSETS[name]
    return int.from_bytes(data[offset:offset + 2], "little", signed=signed)


def _moved(line: str, name: str, lsb: int) -> str:
    """The twist frame of ``line`` with ``name`` moved by ``lsb``, its CRC made good."""
    stamp, channel, frame = line.split()[:3]
    data = bytearray.fromhex(frame[4:])
    offset = OFFSETS[name][0]
    value = (_field(bytes(data), name) + lsb) & 0xFFFF
    data[offset:offset + 2] = value.to_bytes(2, "little")
    data[0] = _crc(bytes(data), (TWIST_SLOT << 4) | (data[1] & 0xF))
    return " ".join([stamp, channel, f"{TWIST:03X}#{data.hex().upper()}", *line.split()[3:]])


def _live_passes(path: Path) -> bool:
    """The monitor fed the log frame by frame: its DISTANCE verdict."""
    monitor = BusMonitor(robot.load("kobuki"))
    msg = None
    for line in path.read_text().splitlines():
        msg = parse_candump_line(line.encode())
        if msg is not None:
            monitor.feed(msg, now_s=msg.timestamp)
    assert msg is not None
    return bool(monitor.snapshot(now_s=msg.timestamp)["distance"]["passed"])


WHOLE, STREAMED = ["analyze", "--stream", "never"], ["analyze", "--stream", "always"]


def _verdicts(path: Path) -> list[int]:
    return [main([*command, str(path), "--robot", "kobuki"]) for command in (WHOLE, STREAMED)]


def _edited(log: Path, tmp_path: Path, name: str, lsb: int, pick: int) -> Path:
    lines = log.read_text().splitlines()
    resends = [(k, p) for k, p in _resends(lines)
               if _payload(lines[k])[2:] == _payload(lines[p])[2:]]  # a correct resend
    assert resends, "the premise: the run resends ODOM_TWIST"
    k = resends[pick % len(resends)][0]
    edited = list(lines)
    edited[k] = _moved(lines[k], name, lsb)
    before, after = _payload(lines[k]), _payload(edited[k])
    assert after[1] == before[1]  # COUNTER and ENC_COUNTER as sent
    assert (_field(after, name) - _field(before, name)) % 0x10000 == lsb % 0x10000
    path = tmp_path / "edited.log"
    path.write_text("\n".join(edited) + "\n")
    return path


@pytest.mark.parametrize("run", ["drop", "burst", "busoff"])
def test_the_correct_resends_pass(logs: dict[str, Path], run: str) -> None:
    assert _resends(logs[run].read_text().splitlines())
    assert _verdicts(logs[run]) == [0, 0]
    assert _live_passes(logs[run])


@pytest.mark.parametrize("run", ["drop", "burst", "busoff"])
@pytest.mark.parametrize("pick", [0, 1])
def test_a_moved_resent_distance_fails_whole_streamed_and_live(
        logs: dict[str, Path], tmp_path: Path, run: str, pick: int) -> None:
    path = _edited(logs[run], tmp_path, "DISTANCE", 20, pick)
    assert (_verdicts(path), _live_passes(path)) == ([1, 1], False)

