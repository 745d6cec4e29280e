"""A pose naming an encoder frame ahead of every one the host heard before it is judged at the
frames it may name, whatever the cadence of the frames before it (issue #11: a PASS must never
hide a wrong pose; ``host.judge.aheadnamed``).

An outside trial set one pose pair's ENC_COUNTER one on and raised its X 10 mm: pmir figure8
seed 2 (``reboot=5,delay=0.1:7``), the pair at 6.001 s then named the frame sent at 6.010 s,
after an encoder frame 7 ms late (``namesahead``'s cadence condition off); kobuki figure8 seed
5 and random seed 9, the drive's last pair, naming a frame never sent. ``analyze`` left each
pair out ("judged 0.998") and PASSed, whole and streamed. The drives are the run's own
(lockstep: the same log each time); the tamper is the test's (cantools)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import can
import pytest
from cantools.autosar import compute_profile2_crc

from odocan.host.cli.app import main
from odocan.host.mqtt.endverdict import end_verdict
from tests.dbc_typed import dbc_attribute
from tests.judges_cli import live_judges
from tests.test_names_ahead import _db, _raw

PAIR = ("ODOM_POSE_X", "ODOM_POSE_Y")
TEN_MM_LSB = 100
BEYOND_M = 5e-3  # a FAIL by the position, by more than half the 10 mm raised

# name: (robot, scenario, seed, duration, faults, the pair tampered: index among each message's
# frames, -1 the last)
DRIVES: dict[str, tuple[str, str, int, int, str, int]] = {
    "pmir_delay": ("pmir", "figure8", 2, 12, "reboot=5,delay=0.1:7", 300),
    "kobuki_last": ("kobuki", "figure8", 5, 18, "stall=2:1,stall=6:0.5,reboot=9,drop=0.1", -1),
    "kobuki_refused_last": ("kobuki", "random", 9, 12, "reboot=3,reboot=7:1,delay=0.2:12", -1),
}


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[str, Path]:
    """(name, log) of one drive of ``DRIVES``, recorded by ``odocan run`` (asserted a PASS)."""
    name = str(request.param)
    robot, scenario, seed, duration, faults, _ = DRIVES[name]
    log = tmp_path_factory.mktemp(name) / "drive.log"
    assert main(["run", "--robot", robot, "--scenario", scenario, "--seed", str(seed),
                 "--duration", str(duration), "--faults", faults, "--log", str(log)]) == 0
    return name, log


def name_pair_ahead(src: Path, dst: Path, pair: int) -> float:
    """``dst``: ``src`` with the ``pair``-th ODOM_POSE_X and ODOM_POSE_Y (by their order among
    each message's frames; -1 the last) naming the encoder frame one on (ENC_COUNTER + 1) and
    X raised 10 mm, each re-signed (cantools). The time of the X changed."""
    db = _db()
    messages = {db.get_message_by_name(n).frame_id: db.get_message_by_name(n) for n in PAIR}
    msgs = list(can.LogReader(str(src)))
    places = {k: [i for i, m in enumerate(msgs) if m.arbitration_id == k] for k in messages}
    t_s = -1.0
    for k, message in messages.items():
        msg = msgs[places[k][pair]]
        raw = _raw(message.decode(bytes(msg.data), scaling=False, decode_choices=False))
        raw["ENC_COUNTER"] = (int(raw["ENC_COUNTER"]) + 1) % 16
        if message.name == "ODOM_POSE_X":
            raw["X"] = int(raw["X"]) + TEN_MM_LSB
            t_s = float(msg.timestamp)
        data = bytearray(message.encode(raw, scaling=False))
        ids = [int(v) for v in dbc_attribute(message, "E2EDataIDs").split(",")]
        data[0] = compute_profile2_crc(bytes(data), ids[data[1] & 0xF]) or 0
        msg.data = data
    with can.Logger(str(dst)) as out:
        for msg in msgs:
            out.on_message_received(msg)
    return t_s


def _analyses(log: Path, work: Path) -> list[tuple[str, int, dict[str, Any]]]:
    """(stream, exit code, report) of ``analyze`` whole and streamed."""
    out = []
    for stream in ("never", "always"):
        report = work / f"{log.stem}_{stream}.json"
        code = main(["analyze", str(log), "--stream", stream, "--report", str(report)])
        out.append((stream, code, json.loads(report.read_text())))
    return out


def _beyond_m(report: dict[str, Any]) -> float:
    return float(report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"])


def test_the_correct_drive_passes_every_analysis(drive: tuple[str, Path],
                                                 tmp_path: Path) -> None:
    """The untampered drive (delays, drops, stalls, reboots: off-cadence frames, refused ones)
    PASSes whole and streamed, no pose named ahead blamed."""
    _, log = drive
    for stream, code, report in _analyses(log, tmp_path):
        assert code == 0, (stream, report["onboard_vs_reference"], report["samples"])
        assert _beyond_m(report) <= 1e-4, stream
        assert "names_ahead" not in report


def test_a_pair_named_ahead_10_mm_off_fails_by_its_position(drive: tuple[str, Path],
                                                            tmp_path: Path) -> None:
    """The one pair named one frame on, X 10 mm off: FAIL by the position whole and streamed
    (it PASSed, the pair left out unjudged), its halves counted judged at the frames they may
    name (``names_ahead_judged``)."""
    name, log = drive
    tampered = tmp_path / "ahead.log"
    t_s = name_pair_ahead(log, tampered, DRIVES[name][5])
    assert t_s > 5.0
    for stream, code, report in _analyses(tampered, tmp_path):
        assert code == 1, (stream, report["onboard_vs_reference"])
        assert _beyond_m(report) > BEYOND_M, (stream, _beyond_m(report))
        assert report["samples"]["names_ahead_judged"] >= 1, (stream, report["samples"])


@pytest.mark.xfail(strict=True, reason="the live judges (monitor, bridge) leave a pose whose "
                   "name resolves to no frame heard before it out (livehalves._settle: seq < 0), "
                   "unjudged: pmir delay's pair at 6.001 s 10 mm off, the monitor OK and the "
                   "bridge PASS (analyze FAILs it 63.1 mm beyond); the live tracker keeps no "
                   "candidate frames' reference for it (aheadnamed's rule is analyze's only)")
def test_the_live_judges_fail_the_pair_named_ahead(tmp_path: Path) -> None:
    """The monitor and the bridge on the pmir drive with its pair at 6.001 s named ahead, 10 mm
    off: not OK, not PASS."""
    robot, scenario, seed, duration, faults, pair = DRIVES["pmir_delay"]
    log, tampered = tmp_path / "drive.log", tmp_path / "ahead.log"
    assert main(["run", "--robot", robot, "--scenario", scenario, "--seed", str(seed),
                 "--duration", str(duration), "--faults", faults, "--log", str(log)]) == 0
    name_pair_ahead(log, tampered, pair)
    monitor, bridge = live_judges(robot, tampered)
    bridge.end_watch()
    assert monitor.health(monitor.bus_time_s)["state"] != "OK"
    assert end_verdict(bridge).verdict != "PASS"
