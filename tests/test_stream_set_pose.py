"""The streamed judge cuts a life where a set-pose or a config was applied (issue #11, #14.1:
``host.judge.stream_cuts``), as the whole log's judge does (``host.judge.setposes``, ``.configs``):
the report of ``analyze_file`` is ``analyze(read_log)``'s, every key and every float bit for bit,
at an awkward chunk size and at the whole log. Lockstep runs of pmir on the circle with the host
tool's ODOM_SET_POSE frames on the bus: one set-pose, several (one a bare APPLY), set-poses on
both sides of a firmware reboot, a bare APPLY right after a 2 s MCU stall latched
POSE_UNCERTAIN, and a firmware that applies the set-pose 1 mm off (a FAIL both ways); the
config drive of tests/test_analyze_config.py (a NACKed APPLY, then an ACKed one; and a firmware
that ignores the one it ACKed: a FAIL both ways) and a config that changes the integrator.

Independent of the judges: what the log must hold is read back with cantools (the ACKs of the
APPLYs), and the wrong firmware's offset is checked against the float64 arc from the pose set."""

from __future__ import annotations

import json
import math
import uuid
from functools import cache
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.firmware.odometry import Odometry
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.protocol.heard import Recorder
from odocan.host.protocol.session import CommandSession
from odocan.sim.board import TICK_S, FirmwareBoard
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests import host_frames as hf
from tests.fault_rig import open_virtual
from tests.test_analyze_config import KOBUKI, _config, _drive
from tests.test_health_rig import circle_rig

CHUNKS = [97, 1 << 20]
PMIR = load("pmir")
DB = database()
FULL = ((fr.SetPoseField.X, 12345), (fr.SetPoseField.Y, -6789),
        (fr.SetPoseField.HEADING, 10000), (fr.SetPoseField.APPLY, 0))  # 1.2345 m, -0.6789 m
BARE = ((fr.SetPoseField.APPLY, 0),)
OFF_Q40_M = 1 << 30  # the wrong firmware's X after a set-pose: 2^-10 m (~1 mm) off
DRIVES: dict[str, dict[str, Any]] = {
    "one": {"seconds": 5.0, "sends": {250: FULL}},
    "several": {"seconds": 6.0, "sends": {150: FULL, 300: BARE, 420: FULL}},
    "reboot": {"seconds": 5.0, "sends": {150: FULL, 350: FULL}, "reboot": 250},
    "uncertain": {"seconds": 8.0, "sends": {502: BARE}, "halt": (300, 500)},
    "wrong": {"seconds": 5.0, "sends": {250: FULL}, "wrong": True},
}


@cache
def drive_log(which: str, folder: Path) -> Path:
    """The candump log of ``DRIVES[which]``: each send's frames one tick apart from its tick,
    their E2E COUNTER running on; the firmware rebooted or halted where it says."""
    spec = DRIVES[which]
    heard: list[can.Message] = []
    ticks = {k + j: frame for k, frames in spec["sends"].items() for j, frame in enumerate(frames)}
    with pytest.MonkeyPatch.context() as patch, circle_rig() as rig:
        if spec.get("wrong"):
            apply = Odometry.set_pose
            patch.setattr(Odometry, "set_pose", lambda self, x, y, h: apply(
                self, x + OFF_Q40_M, y, h))
        rig.observers.append(lambda _k, frames: heard.extend(frames))
        tool = open_virtual(rig.channel)
        halt = spec.get("halt", (0, 0))
        rig.halted = lambda k: halt[0] <= k < halt[1]
        sent = [0]

        def host(k: int) -> None:
            if k == spec.get("reboot"):
                rig.board = FirmwareBoard(rig.fw_bus, rig.params, rig.clock)
            if k in ticks:
                field, value = ticks[k]
                data = hf.pack_odom_set_pose(sent[0] & 0xF, field, value, ErrorMask())
                sent[0] += 1
                tool.send(can.Message(arbitration_id=fr.ODOM_SET_POSE_ID, data=data,
                                      is_extended_id=False, timestamp=k * TICK_S))

        rig.before_board.append(host)
        try:
            rig.run(spec["seconds"])
        finally:
            tool.shutdown()
    return _written(heard, folder / f"{which}.log")


def _written(messages: list[can.Message], path: Path) -> Path:
    path.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                            f"{bytes(m.data).hex().upper()}\n" for m in messages))
    return path


def _applies_acked(path: Path, request_id: int) -> list[bool]:
    """Per ODOM_ACK of an APPLY (FIELD/PARAM 15) of ``request_id`` in the log: ACK or not
    (cantools)."""
    said = []
    ack = DB.get_message_by_name("ODOM_ACK")
    for msg in can.LogReader(str(path)):
        if msg.arbitration_id == ack.frame_id:
            signals = DB.decode_message(msg.arbitration_id, bytes(msg.data), decode_choices=False)
            assert isinstance(signals, dict)
            if signals["REQUEST_ID"] == request_id and signals["REQUEST_FIELD"] == 15:
                said.append(signals["RESULT"] == 0)
    return said


def _reasons(path: Path) -> list[str]:
    """The REASON of every ODOM_STATUS summary (page 0) in the log (cantools)."""
    status = DB.get_message_by_name("ODOM_STATUS")
    said = []
    for msg in can.LogReader(str(path)):
        if msg.arbitration_id == status.frame_id:
            raw = DB.decode_message(msg.arbitration_id, bytes(msg.data), decode_choices=False)
            named = DB.decode_message(msg.arbitration_id, bytes(msg.data))
            assert isinstance(raw, dict)
            assert isinstance(named, dict)
            if raw["PAGE"] == 0:
                said.append(str(named["REASON"]))
    return said


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("stream_set_pose")


@pytest.mark.parametrize("chunk_frames", CHUNKS)
@pytest.mark.parametrize("which", list(DRIVES))
def test_the_streamed_report_cuts_at_set_poses_as_the_whole_log(
    folder: Path, which: str, chunk_frames: int
) -> None:
    path = drive_log(which, folder)
    applies = sum(frames[-1][0] == fr.SetPoseField.APPLY for frames in DRIVES[which]["sends"]
                  .values())
    assert _applies_acked(path, fr.ODOM_SET_POSE_ID) == [True] * applies  # all in the log
    want = analyze(read_log(path), PMIR, "exact").report
    got = analyze_file(path, PMIR, "exact", chunk_frames=chunk_frames)
    assert json.dumps(got) == json.dumps(want)
    events = [e for e in want["events"] if e["kind"] == "set_pose"]
    assert len(events) == applies
    assert want["passed"] is (which != "wrong")  # a correct firmware PASSes, the wrong FAILs
    if which == "reboot":
        assert len(want["reboots"]) == 1
    if which == "uncertain":  # the latch was on the bus, and the set-pose released it
        reasons = _reasons(path)
        assert "POSE_UNCERTAIN" in reasons
        assert reasons[-1] == "NONE"
    if which == "wrong":  # the firmware's X: the float64 pose set plus its offset
        error_m = want["onboard_vs_reference"]["max_position_error_m"]
        assert math.isclose(error_m, OFF_Q40_M / 2**40, rel_tol=0.05)


def _integrator_drive() -> list[can.Message]:
    """6 s of kobuki (exact); at 2 s a config of its own robot with the rk2 integrator."""
    messages: list[can.Message] = []
    heard = Recorder(DB)
    config = RigConfig(robot=KOBUKI, seed=5, channel=f"test-stream-config-{uuid.uuid4().hex}",
                       duration_s=60.0)
    rig = LockstepRig(config, [heard, _Keep(messages)])
    try:
        session = CommandSession(heard, rig.send, rig.run_until, ack_timeout_s=0.5)
        rig.run(2.0)
        assert session.configure(**_config(integrator="rk2"))["RESULT"] == "ACK"  # type: ignore[arg-type]
        rig.run(4.0)
    finally:
        rig.close()
    return messages


class _Keep(can.Listener):
    def __init__(self, into: list[can.Message]) -> None:
        self.into = into

    def on_message_received(self, msg: can.Message) -> None:
        self.into.append(msg)


@pytest.fixture(scope="module")
def config_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """tests/test_analyze_config.py's drive (kobuki: a NACKed config at 2 s, an ACKed one at
    3 s), ``taken`` or ``ignored`` by the firmware (it keeps the old wheelbase); ``rk2``: a
    config that changes the integrator (the life before it judged with the one ODOM_STATUS
    reported before the APPLY)."""
    folder = tmp_path_factory.mktemp("config")
    paths = {"rk2": _written(_integrator_drive(), folder / "config-rk2.log")}
    with pytest.MonkeyPatch.context() as monkeypatch:
        for ignores in (False, True):
            which = "ignored" if ignores else "taken"
            paths[which] = _written(_drive(ignores, monkeypatch), folder / f"config-{which}.log")
            monkeypatch.undo()
    return paths


@pytest.mark.parametrize("chunk_frames", CHUNKS)
@pytest.mark.parametrize("which", ["taken", "ignored", "rk2"])
def test_the_streamed_report_cuts_at_an_acked_config_as_the_whole_log(
    config_logs: dict[str, Path], which: str, chunk_frames: int
) -> None:
    path = config_logs[which]
    acked = [True] if which == "rk2" else [False, True]
    assert _applies_acked(path, DB.get_message_by_name("ODOM_CONFIG").frame_id) == acked
    want = analyze(read_log(path), KOBUKI).report
    got = analyze_file(path, KOBUKI, chunk_frames=chunk_frames)
    assert json.dumps(got) == json.dumps(want)
    assert [e["kind"] for e in want["events"]] == ["config"]  # the ACKed one only
    assert want["passed"] is (which != "ignored")
    if which == "rk2":  # the life before the config judged with exact, the one after with rk2
        assert want["integrator"] == "exact"
        assert "rk2" in want["events"][0]["detail"]


def test_odocan_analyze_streams_a_set_pose_log_without_reading_it_whole(
    folder: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str]
) -> None:
    """The command keeps a log with a set-pose in bounded memory (``--stream always``: the
    whole log is never read) and writes the whole-log path's report. A log with an applied
    config still goes whole in the command (its PROFILE pages: ``configs.later_mismatches``)."""
    path = drive_log("one", folder)
    whole, streamed = tmp_path / "whole.json", tmp_path / "streamed.json"
    argv = ["analyze", str(path), "--robot", "pmir", "--integrator", "exact", "--report"]
    assert main([*argv, str(whole), "--stream", "never"]) == 0

    def read_whole(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("the whole log was read")

    monkeypatch.setattr("odocan.host.io.logs.read_log", read_whole)
    assert main([*argv, str(streamed), "--stream", "always", "--chunk-frames", "97"]) == 0
    assert json.loads(streamed.read_text()) == json.loads(whole.read_text())
    capsys.readouterr()
