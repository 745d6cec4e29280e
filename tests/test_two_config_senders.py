"""Two tools commanding one robot on ODOM_CONFIG (issue #11: "two sources on one ID are
reported").

Another tool (a script with its own ``CommandEncoder``: its own E2E COUNTER sequence) and the
bridge's ``cmd/config`` put their ODOM_CONFIG frames on the bus interleaved one for one, the
other tool's first or the bridge's first. Both configs are kobuki's robot but for the
wheelbase: 0.25 m the other tool's, 0.27 m the bridge's.

* **Both from COUNTER 0**: every second frame repeats the COUNTER the firmware has just
  accepted. The Profile 2 receiver drops it (E2E REPEATED): the firmware runs the first
  sender's config and never sees the second's; it answers the one frame of the second unlike
  the first's (WHEELBASE) NACK REPEATED (on main: nothing), the identical ones not at all.
* **The other tool's COUNTERs 3 ahead** (it sent five configs before): all 14 frames are taken,
  each tool's staged writes go into one staged set, and the first APPLY commits the later
  writes, the other tool's: the firmware runs the wheelbase of the sender whose frames came
  second.

Independent of the judges: the ODOM_ACKs decoded with cantools, and the float64 dead reckoning
of ``tests.test_bridge_config_nack`` says where the pose must be (which wheelbase it runs).

Found on main: the bridge answered its config ``acked`` in every case (the other tool's
ODOM_ACKs carry the REQUEST_COUNTERs it waits for), also when the firmware never took a frame
of it; nobody said "two senders"; the judges took the latest frame of a COUNTER as the one its
ACK answers, so with two frames of one COUNTER in flight the monitor FAILed the correct
firmware (bridge's frames first, COUNTERs 3 apart: POSE WRONG with 0.27 m) and so did the
bridge (the other tool's first, COUNTERs 3 apart; the bridge's first from COUNTER 0).

The bridge's own judges when both tools' frames of one COUNTER and one PARAM carry different
values: the bridge does not hear its own frames back, so the ACKs cannot tell it which of the
two the firmware took; the firmware's PROFILE page settles it (``host.judge.liveconfigdoubt``).
Found on main: with the other tool's frames first the bridge judged the correct firmware with
its own 0.27 m: POSE WRONG (52 mm), TWIST WRONG, profile MISMATCH. A firmware that says one
robot on its PROFILE page and runs another still FAILs.
"""

from __future__ import annotations

import dataclasses
import json
import math
import uuid
from pathlib import Path
from typing import Any, cast

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.config import derive_constants
from odocan.host.cli.app import main
from odocan.host.mqtt.bridge import _Robot
from odocan.host.protocol.commands import CommandEncoder
from odocan.host.protocol.heard import Recorder
from odocan.host.protocol.session import CommandNotAcked, CommandSession
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from tests.bridge_pair import KOBUKI, bridged_robot
from tests.test_bridge_config_nack import WIDER, _dead_reckoned_with
from tests.test_bridge_foreign_config import PERIODS, _events, _Watched, _wrongs

OTHER = {**WIDER, "id": "script"}  # wheelbase 0.25 m: the other tool's
MINE = {**WIDER, "id": "c1", "wheelbase_m": 0.27}  # the bridge's


def _other_frames(configs_before: int) -> list[tuple[int, bytes]]:
    """OTHER as the other tool puts it on the bus after ``configs_before`` configs of 7
    frames it sent before: its COUNTERs from 7 x that (mod 16)."""
    encoder = CommandEncoder()
    for _ in range(configs_before):
        encoder.encode("config", json.dumps(OTHER).encode())
    frames = encoder.encode("config", json.dumps(OTHER).encode()).frames
    return [(f.can_id, f.data) for f in frames]


class _Interleaved(_Watched):
    """Each frame the bridge sends reaches the bus right after one of the other tool's
    (``other_first``) or right before it."""

    def __init__(self, bridge: _Robot, listener: Any, other: list[tuple[int, bytes]],
                 other_first: bool) -> None:
        super().__init__(bridge, listener)
        self.other, self.other_first = list(other), other_first

    def command_frame(self, msg: can.Message) -> None:
        if self.other_first and self.other:
            self.other_tool([self.other.pop(0)])
        super().command_frame(msg)
        if not self.other_first and self.other:
            self.other_tool([self.other.pop(0)])


def _drive(channel: str, configs_before: int, other_first: bool) -> tuple[_Robot, _Interleaved]:
    with bridged_robot(channel) as (bridge, listener):
        board = _Interleaved(bridge, listener, _other_frames(configs_before), other_first)
        for _ in range(100):
            board.period()
        answer = bridge.on_command("config", json.dumps(MINE).encode())
        assert answer[0][1]["result"] == "accepted", answer
        for _ in range(PERIODS - 100):
            board.period()
    return bridge, board


def _runs_wheelbase(board: _Interleaved, wheelbase_m: float) -> None:
    """The firmware's last whole pose (cantools) is the float64 dead reckoning with kobuki's
    wheelbase up to its first applied APPLY and ``wheelbase_m`` from there, and not with the
    other config's."""
    applied = board.apply_periods[0]
    named = max(k for k, xy in board.poses.items() if len(xy) == 2)
    assert named >= PERIODS - 3
    for wb, right in ((wheelbase_m, True), (0.52 - wheelbase_m, False)):
        x_m, y_m = _dead_reckoned_with([KOBUKI.wheelbase_m] * (applied - 1)
                                       + [wb] * (named - applied + 1))
        off_m = math.hypot(board.poses[named]["X"] - x_m, board.poses[named]["Y"] - y_m)
        assert (off_m < 1e-3) is right, (wb, off_m)


def _judges_agree(bridge: _Robot, board: _Interleaved, wheelbase_m: float) -> None:
    """Both judges run the firmware's robot and FAIL nothing (the bridge's speed and DISTANCE
    judges and its PROFILE page check neither)."""
    assert board.monitor.tracker.geometry.wheelbase_m == wheelbase_m
    assert bridge.telemetry.tracker.geometry.wheelbase_m == wheelbase_m
    assert _wrongs(bridge, board) == (0, 0)
    _, status = bridge.telemetry.status()
    assert status["twist"]["passed"], status["twist"]
    assert status["distance"]["passed"], status["distance"]
    assert status["profile"]["verdict"] == "OK", status["profile"]


def _said(bridge: _Robot, board: _Interleaved, monitor_says: str, bridge_says: int = 1) -> None:
    """The bridge's own config ``contested`` (never ``acked``), and both judges' event
    (``bridge_says``: the bridge's, its config in doubt said too)."""
    assert [r["result"] for r in board.results] == ["contested"], board.results
    assert board.results[0]["reason"].startswith(
        "two senders on ODOM_CONFIG: another tool's frame (COUNTER ")
    monitor = [e["detail"] for e in board.monitor.events if e["kind"] == "two senders"]
    assert len(monitor) == 1, board.monitor.events
    assert monitor[0].startswith(f"two senders on ODOM_CONFIG: {monitor_says}")
    assert len(_events(bridge, "two senders")) == bridge_says


def _config_acks(board: _Interleaved) -> list[tuple[int, int]]:
    """cantools: (REQUEST_FIELD, RESULT) of every ODOM_ACK of an ODOM_CONFIG frame."""
    return [(int(s["REQUEST_FIELD"]), int(s["RESULT"])) for _, s in board.acks
            if s["REQUEST_ID"] == fr.ODOM_CONFIG_ID]


PARAMS_APPLY = [(f, 0) for f in (0, 1, 2, 3, 4, 5, 15)]  # six PARAMs and APPLY, ACKed
# the same, and the second tool's WHEELBASE (its only frame unlike the first's) NACKed REPEATED
REPEAT_ANSWERS = [*PARAMS_APPLY[:4], (3, 1), *PARAMS_APPLY[4:]]


def test_the_other_tool_s_counters_first_the_bridge_s_config_dropped_unanswered() -> None:
    bridge, board = _drive("test-two-senders-repeat", 0, other_first=True)
    assert _config_acks(board) == REPEAT_ANSWERS  # 8 answers to 14 frames: duplicates none
    _runs_wheelbase(board, 0.25)  # the other tool's: the bridge's never taken
    _said(bridge, board, "COUNTER 3 repeated with other content", bridge_says=2)
    _judges_agree(bridge, board, 0.25)  # the bridge's settled by the PROFILE page
    settled = _events(bridge, "config")[-1]
    assert settled.startswith("two senders on ODOM_CONFIG settled by the PROFILE page (0x")
    assert "the firmware runs the other tool's WHEELBASE 0.25; the pose judged since" in settled


def test_the_bridge_s_counters_first_the_other_tool_s_config_dropped_unanswered() -> None:
    bridge, board = _drive("test-two-senders-repeat-mine", 0, other_first=False)
    assert _config_acks(board) == REPEAT_ANSWERS
    _runs_wheelbase(board, 0.27)
    _said(bridge, board, "COUNTER 3 repeated with other content", bridge_says=2)
    _judges_agree(bridge, board, 0.27)
    assert _events(bridge, "config")[-1].endswith("the firmware runs this bridge's WHEELBASE 0.27")


class _Lying(_Interleaved):
    """``_Interleaved`` whose firmware, from its config's APPLY on, integrates with a wheelbase
    0.29 m while its PROFILE page says the robot it applied: a wrong firmware."""

    def firmware_frame(self, can_id: int, data: bytes) -> None:
        applied = len(self.apply_periods)
        super().firmware_frame(can_id, data)
        if not applied and self.apply_periods:
            params = dataclasses.replace(self.ecu.params, wheelbase_nm=290_000_000)
            self.ecu.odometry.reconfigure(derive_constants(params, self.ecu.errors))


@pytest.mark.parametrize("other_first", [True, False])
def test_a_firmware_running_neither_tool_s_wheelbase_fails_the_bridge(other_first: bool) -> None:
    with bridged_robot(f"test-two-senders-lying-{other_first}") as (bridge, listener):
        board = _Lying(bridge, listener, _other_frames(0), other_first)
        for _ in range(100):
            board.period()
        bridge.on_command("config", json.dumps(MINE).encode())
        for _ in range(PERIODS - 100):
            board.period()
    assert _wrongs(bridge, board)[0] >= 1  # the bridge FAILs it, settled or not
    assert _wrongs(bridge, board)[1] >= 1  # as the monitor does


@pytest.mark.parametrize(("other_first", "runs_m"), [(True, 0.27), (False, 0.25)])
def test_interleaved_staging_one_tool_s_apply_commits_the_other_s_parameters(
    other_first: bool, runs_m: float,
) -> None:
    bridge, board = _drive(f"test-two-senders-mix-{other_first}", 5, other_first)
    assert sorted(_config_acks(board)) == sorted(PARAMS_APPLY * 2)  # all 14 taken
    _runs_wheelbase(board, runs_m)  # the later writes, committed by the first APPLY
    _said(bridge, board, "interleaved COUNTER sequences")
    _judges_agree(bridge, board, runs_m)


# --- analyze: a recorded drive, two tools' configs interleaved on the bus ---
ANALYZE_CONFIG = {k: v for k, v in OTHER.items() if k != "id"}


def _recorded(path: Path, two_tools: bool) -> None:
    """``recorded_drive``: at 1 s a config (wheelbase 0.25 m) from one tool, and with
    ``two_tools`` the same from a second one (its own COUNTERs, from 0 too) whose frames each
    follow the first's: identical frames, but the wheelbase at 0.27 m: the firmware drops that
    one (REPEATED)."""
    first = CommandEncoder().build("config", ANALYZE_CONFIG).frames
    second = CommandEncoder().build("config", {**ANALYZE_CONFIG, "wheelbase_m": 0.27}).frames
    recorded_drive(path, [(f.can_id, f.data) for f in first],
                   [(f.can_id, f.data) for f in second] if two_tools else None, 3.0)


def recorded_drive(path: Path, first: list[tuple[int, bytes]],
                   second: list[tuple[int, bytes]] | None, after_s: float) -> None:
    """1 s of kobuki in the lockstep rig, the frames ``first`` (one tool's) each followed by
    ``second``'s of the same rank (another tool's, when given), ``after_s`` more; candump
    written to ``path`` from every frame on the bus."""
    messages: list[can.Message] = []

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            messages.append(msg)

    config = RigConfig(robot=KOBUKI, seed=3, channel=f"test-two-senders-{uuid.uuid4().hex}",
                       duration_s=60.0)
    rig = LockstepRig(config, [Keep()])
    try:
        rig.run(1.0)
        for k, frame in enumerate(first):
            rig.send(*frame)
            if second is not None:
                rig.send(*second[k])
        rig.run(after_s)
    finally:
        rig.close()
    path.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                            f"{bytes(m.data).hex().upper()}\n" for m in messages))


@pytest.mark.parametrize("stream", ["never", "always"])
def test_analyze_reports_two_senders_and_passes_the_correct_firmware(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], stream: str,
) -> None:
    for two_tools in (True, False):
        log, report = tmp_path / f"{two_tools}.log", tmp_path / f"{two_tools}.json"
        _recorded(log, two_tools)
        assert main(["analyze", str(log), "--robot", "kobuki", "--stream", stream,
                     "--report", str(report)]) == 0  # PASS: the firmware is right
        said = json.loads(report.read_text())
        configs = [e["detail"] for e in said["events"] if e["kind"] == "config"]
        assert len(configs) == 1
        assert "wheelbase 0.25 m" in configs[0]  # the first tool's: the 0.27 m frame dropped
        senders = [e["detail"] for e in said["events"] if e["kind"] == "two senders"]
        if two_tools:
            assert senders == ["two senders on ODOM_CONFIG: COUNTER 3 repeated with other "
                               "content: the firmware drops the second frame unanswered (E2E "
                               "REPEATED; or one sender restarted its COUNTER)"]
        else:
            assert senders == []
    capsys.readouterr()


# --- a CommandSession (the pytest kit, the experiments) as the second tool ---
def _session_drive(other_first: bool | None) -> tuple[dict[str, Any] | str, list[float]]:
    """2 s of kobuki in the lockstep rig; at 1 s a ``CommandSession`` configures wheelbase
    0.27 m while (``other_first`` not None) another tool's config (0.25 m, its COUNTERs from
    0 too) interleaves frame for frame, its frames first or second. Returns the session's
    answer (the ACK, or ``CommandNotAcked``'s reason) and the wheelbases of the frames the
    firmware took (``_acked_wheelbases``)."""
    heard = Recorder(database())
    config = RigConfig(robot=KOBUKI, seed=3, channel=f"test-two-senders-{uuid.uuid4().hex}",
                       duration_s=60.0)
    rig = LockstepRig(config, [heard])
    other = list(CommandEncoder().build("config", ANALYZE_CONFIG).frames)
    sent: list[tuple[int, bytes]] = []

    def send(can_id: int, data: bytes) -> None:
        pair = [(can_id, data)]
        if other_first is not None and can_id == fr.ODOM_CONFIG_ID and other:
            theirs = other.pop(0)
            pair = [(theirs.can_id, theirs.data), *pair] if other_first else [
                *pair, (theirs.can_id, theirs.data)]
        for frame in pair:
            sent.append(frame)
            rig.send(*frame)

    try:
        rig.run(1.0)
        session = CommandSession(heard, send, rig.run_until, ack_timeout_s=0.5)
        try:
            answer: dict[str, Any] | str = session.configure(
                **{**ANALYZE_CONFIG, "wheelbase_m": 0.27})  # type: ignore[arg-type]
        except CommandNotAcked as exc:
            answer = exc.reason
        rig.run(0.5)
    finally:
        rig.close()
    return answer, _acked_wheelbases(heard, sent)


def _acked_wheelbases(heard: Recorder, sent: list[tuple[int, bytes]]) -> list[float]:
    """cantools: the WHEELBASE of each ODOM_CONFIG frame sent that the firmware accepted (E2E:
    of two frames in a row of one COUNTER, the first; the second NACKed REPEATED when its
    bytes differ), checked against the ODOM_ACKs it gave."""
    db = database()
    taken: list[dict[str, Any]] = []
    last: bytes | None = None
    unlike = 0  # dropped frames unlike the one taken: NACK REPEATED
    for can_id, data in sent:
        if can_id != fr.ODOM_CONFIG_ID:
            continue
        if last is not None and data[1] & 0xF == last[1] & 0xF:
            unlike += data != last
            continue
        taken.append(cast(dict[str, Any], db.decode_message(can_id, data, decode_choices=False)))
        last = data
    answers = [a["RESULT"] for a in heard.decoded("ODOM_ACK") if a["REQUEST_ID"] == "ODOM_CONFIG"]
    assert answers.count("ACK") == len(taken)
    assert answers.count("NACK") == unlike
    return [float(s["WHEELBASE"]) for s in taken if "WHEELBASE" in s]


def test_a_session_alone_is_acked() -> None:
    answer, wheelbases = _session_drive(None)
    assert isinstance(answer, dict)
    assert answer["RESULT"] == "ACK"
    assert wheelbases == [0.27]


@pytest.mark.parametrize(("other_first", "taken_m"), [(True, 0.25), (False, 0.27)])
def test_a_session_with_another_sender_is_never_acked(other_first: bool, taken_m: float) -> None:
    answer, wheelbases = _session_drive(other_first)
    assert wheelbases == [taken_m]  # the firmware took the first of each COUNTER's two frames
    assert isinstance(answer, str)
    assert answer.startswith("contested: another sender's ODOM_CONFIG frame (COUNTER ")
