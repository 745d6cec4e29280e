"""``analyze`` follows an ODOM_CONFIG the firmware ACKs (issue #11 point 6; found by the trial).

On a lockstep drive of kobuki our firmware is sent a config it refuses (NACK: nothing changes),
then one it takes (wheelbase 0.23 -> 0.25 m, ACK). Before, ``analyze`` of the recording failed
the correct firmware (155 mm off, only "profile hash differs") and passed one that ACKs the
config but keeps integrating the old wheelbase. An independent float64 dead reckoning written
here (cantools decoding, the exact arc of each step, the wheelbase the firmware ACKed from the
APPLY on) says which firmware is right; the whole and the streamed ``analyze`` and the monitor
must agree with it.
"""

from __future__ import annotations

import json
import math
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import cast

import can
import pytest
from cantools.database.can import Database

import odocan.firmware.commands as fw_commands
from odocan.firmware.config import derive_constants
from odocan.host.cli.app import main
from odocan.host.io.logs import parse_candump
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.heard import Recorder
from odocan.host.protocol.session import CommandNotAcked, CommandSession
from odocan.sim import robot
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig

KOBUKI = robot.load("kobuki")
WIDER_M = 0.25  # the wheelbase the config applies (kobuki's is 0.23 m)


def _config(**changed: object) -> dict[str, object]:
    values: dict[str, object] = {
        "counts_per_rev": KOBUKI.counts_per_rev,
        "wheel_radius_left_m": KOBUKI.wheel_radius_left_m,
        "wheel_radius_right_m": KOBUKI.wheel_radius_right_m,
        "wheelbase_m": KOBUKI.wheelbase_m, "counter_bits": KOBUKI.counter_bits,
        "integrator": "exact"}
    return {**values, **changed}


def _drive(ignores_config: bool, monkeypatch: pytest.MonkeyPatch) -> list[can.Message]:
    """9 s of kobuki; at 2 s a config the firmware NACKs, at 3 s one it ACKs. ``ignores_config``:
    the firmware ACKs it (and reports its CRC) but keeps the old wheelbase's constants."""
    messages: list[can.Message] = []

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            messages.append(msg)

    heard = Recorder(database())
    config = RigConfig(robot=KOBUKI, seed=3, channel=f"test-config-{uuid.uuid4().hex}",
                       duration_s=60.0)
    rig = LockstepRig(config, [heard, Keep()])
    try:
        session = CommandSession(heard, rig.send, rig.run_until, ack_timeout_s=0.5)
        rig.run(2.0)
        with pytest.raises(CommandNotAcked):  # one count turns it 450 deg: refused
            session.configure(**_config(counts_per_rev=4, wheelbase_m=0.01))  # type: ignore[arg-type]
        rig.run(1.0)
        if ignores_config:
            derive, built = derive_constants, rig.board.ecu.params
            monkeypatch.setattr(fw_commands, "derive_constants",
                                lambda _params, errors: derive(built, errors))
        assert session.configure(**_config(wheelbase_m=WIDER_M))["RESULT"] == "ACK"  # type: ignore[arg-type]
        rig.run(6.0)
    finally:
        rig.close()
    return messages


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[bool, Path]]:
    """The drive's candump log, by whether the firmware ignores the config."""
    folder = tmp_path_factory.mktemp("config")
    with pytest.MonkeyPatch.context() as monkeypatch:
        paths = {}
        for ignores in (False, True):
            lines = [f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                     f"{bytes(m.data).hex().upper()}" for m in _drive(ignores, monkeypatch)]
            paths[ignores] = folder / f"config-{'ignored' if ignores else 'taken'}.log"
            paths[ignores].write_text("\n".join(lines) + "\n")
            monkeypatch.undo()
        yield paths


def _independent_worst_m(path: Path) -> float:
    """The largest distance between an on-board pose and a float64 dead reckoning of the
    encoder frames (cantools; exact arcs; kobuki's wheelbase, WIDER_M for the encoder frames
    after the APPLY its ACK accepts: the firmware drains its mailbox in bus order; pose 0 where
    the firmware primes, on the first encoder frame), each pose paired with the latest encoder
    frame of its ENC_COUNTER."""
    db = database()
    messages = list(parse_candump_messages(path))
    applied = _acked_apply(db, messages)
    per_count_m = 2 * math.pi * KOBUKI.wheel_radius_left_m / KOBUKI.counts_per_rev
    wheelbase_m, x, y, th = KOBUKI.wheelbase_m, 0.0, 0.0, 0.0
    previous: tuple[int, int] | None = None
    at_counter: dict[int, tuple[float, float]] = {}
    onboard_x: dict[int, float] = {}
    worst_m = 0.0
    for k, m in enumerate(messages):
        name = db.get_message_by_frame_id(m.arbitration_id).name
        s = _decoded(db, m)
        wheelbase_m = WIDER_M if k > applied else wheelbase_m
        if name == "WHEEL_ENCODERS":
            counts = (int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))
            if previous is not None:
                d_l, d_r = (((n - p + 0x8000) & 0xFFFF) - 0x8000 for n, p in zip(
                    counts, previous, strict=True))
                ds, dth = (d_l + d_r) * per_count_m / 2, (d_r - d_l) * per_count_m / wheelbase_m
                if abs(dth) < 1e-12:
                    x, y = x + ds * math.cos(th), y + ds * math.sin(th)
                else:
                    x += ds / dth * (math.sin(th + dth) - math.sin(th))
                    y -= ds / dth * (math.cos(th + dth) - math.cos(th))
                th += dth
            previous = counts
            at_counter[int(s["COUNTER"])] = (x, y)
        elif name == "ODOM_POSE_X":
            onboard_x[int(s["ENC_COUNTER"])] = float(s["X"])
        elif name == "ODOM_POSE_Y" and int(s["ENC_COUNTER"]) in onboard_x:
            ref_x, ref_y = at_counter[int(s["ENC_COUNTER"])]
            worst_m = max(worst_m, math.hypot(onboard_x.pop(int(s["ENC_COUNTER"])) - ref_x,
                                              float(s["Y"]) - ref_y))
    return worst_m


def _acked_apply(db: Database, messages: list[can.Message]) -> int:
    """The place of the ODOM_CONFIG APPLY (PARAM 15) that an ODOM_ACK accepts (RESULT 0)."""
    apply_at = -1
    for k, m in enumerate(messages):
        name = db.get_message_by_frame_id(m.arbitration_id).name
        s = _decoded(db, m)
        if name == "ODOM_CONFIG" and s["PARAM"] == 15:
            apply_at = k
        elif name == "ODOM_ACK" and s["REQUEST_FIELD"] == 15 and s["RESULT"] == 0:
            return apply_at
    raise AssertionError("no ACKed APPLY")


def _decoded(db: Database, m: can.Message) -> dict[str, float]:
    """The frame's raw signals (cantools)."""
    return cast(dict[str, float], db.decode_message(m.arbitration_id, bytes(m.data),
                                                    decode_choices=False))


def parse_candump_messages(path: Path) -> Iterator[can.Message]:
    for line in path.read_text().splitlines():
        stamp, _, frame = line.split()
        can_id, data = frame.split("#")
        yield can.Message(timestamp=float(stamp[1:-1]), arbitration_id=int(can_id, 16),
                          is_extended_id=False, data=bytes.fromhex(data))


def test_the_independent_checker_tells_the_two_firmwares_apart(logs: dict[bool, Path]) -> None:
    assert _independent_worst_m(logs[False]) < 0.1e-3  # within the pose's 0.1 mm LSB
    assert _independent_worst_m(logs[True]) > 50e-3


def test_analyze_judges_the_firmware_with_the_config_it_acked(logs: dict[bool, Path]) -> None:
    taken = analyze(parse_candump(logs[False].read_bytes()), KOBUKI)
    assert taken.passed, taken.report["onboard_vs_reference"]
    events = [e for e in taken.report["events"] if e["kind"] == "config"]
    assert [e["detail"] for e in events] == [
        "config applied: 2578 counts/rev, wheel radii 0.035/0.035 m, wheelbase 0.25 m, exact: "
        "reference restarted"]  # the ACKed one only: the NACKed config changed nothing
    assert 3.0 <= events[0]["t_s"] < 3.05  # the ACK, in the tick after the frames were sent
    assert taken.report["reboots"] == []
    ignored = analyze(parse_candump(logs[True].read_bytes()), KOBUKI)
    assert not ignored.passed
    assert ignored.report["onboard_vs_reference"]["max_position_error_m"] > 50e-3


@pytest.mark.parametrize("stream", ["never", "always"])
def test_the_cli_whole_and_streamed_agree(logs: dict[bool, Path], tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str], stream: str) -> None:
    """The PROFILE page after the APPLY names the applied robot: no mismatch said."""
    for ignores, code in ((False, 0), (True, 1)):
        report = tmp_path / f"{ignores}.json"
        assert main(["analyze", str(logs[ignores]), "--robot", "kobuki", "--stream", stream,
                     "--report", str(report)]) == code
        said = json.loads(report.read_text())
        assert "diagnosis" not in said or not any(
            "profile" in hint for hint in said["diagnosis"]), said["diagnosis"]
        assert [e["kind"] for e in said["events"]] == ["config"]
    capsys.readouterr()


def test_the_monitor_agrees(logs: dict[bool, Path]) -> None:
    """One judge: the live monitor fed the same frames says what analyze says."""
    for ignores in (False, True):
        monitor = BusMonitor(KOBUKI)
        for msg in parse_candump_messages(logs[ignores]):
            monitor.feed(msg, now_s=msg.timestamp)
        health = monitor.health(now_s=msg.timestamp)
        assert (health["pose_wrongs"]["episodes"] > 0) == ignores, health["why"]
        details = [e["detail"] for e in health["events"] if e["kind"] == "config"]
        assert details == ["config applied: 2578 counts/rev, wheel radii 0.035/0.035 m, "
                           "wheelbase 0.25 m, exact: reference restarted"]


def test_a_batch_judges_both_logs_alike(logs: dict[bool, Path], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    """``analyze`` of several logs (``host.cli.batch``): the same verdicts, no mismatch said."""
    assert main(["analyze", str(logs[False]), str(logs[True]), "--robot", "kobuki",
                 "--jobs", "1", "--report-dir", str(tmp_path)]) == 1
    for ignores in (False, True):
        said = json.loads((tmp_path / f"{logs[ignores].name}.json").read_text())
        assert said["passed"] is not ignores
        assert not any("profile" in hint for hint in said.get("diagnosis", [])), said["diagnosis"]
        assert [e["kind"] for e in said["events"]] == ["config"]
    capsys.readouterr()
