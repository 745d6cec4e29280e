"""An outside trial's own firmware (written from the DBC) under odocan's judges: the verdicts that
hid what was not judged, or blamed the wrong thing.

* A firmware that never sends ODOM_TWIST (a cyclic 20 ms message of the DBC), or a DBC without
  its DISTANCE: ``analyze`` PASSed with the twist and DISTANCE checks ``passed: true`` on 0
  samples. Now UNJUDGED, exit 1, one reason naming what was never heard (whole and streamed;
  the live end verdict too: ``host.judge.watchline``).
* A firmware whose E2E COUNTER never advances: ``analyze`` FAILed on 9 reboots that never
  happened (``bootticks``: a repeated COUNTER 0 read as a new firmware's power-up tick), the
  live monitor on a 52 mm pose episode; the kit said "no ODOM_ACK". Now every judge names the
  REPEATED frames (``host.judge.verdictfacts``) and invents no reboot.
* The monitor's FAIL line paired the worst heading's episode with its own position (0.41 mm
  where another episode was 7.56 mm off), said epoch seconds and ``(enc 10)``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from cantools.autosar import compute_profile2_crc
from cantools.database.can import Database

from odocan.host.judge.posewrongs import PoseWrongs
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.protocol.heard import Recorder
from odocan.host.protocol.session import CommandNotAcked, CommandSession
from odocan.sim import contract
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.dbc_typed import dbc_attribute
from tests.synth_log import synthesize, wandering_drive
from tests.test_cli_run import run_cli

PMIR = load("pmir")
STEPS = 300  # 3 s of encoder frames: past the firmware's first second (its boot-tick rule)
FIRMWARE_MESSAGES = ("ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST", "ODOM_STATUS")


def _drive_log(path: Path, *, twist: bool) -> Path:
    """A correct firmware's drive (``synth_log``), with ODOM_TWIST or without."""
    d_left, d_right = wandering_drive(PMIR, STEPS, 0.002, seed=3)
    return synthesize(PMIR, "exact", d_left, d_right, twist=twist).write(path)


def _stuck(src: Path, dst: Path, names: tuple[str, ...] = FIRMWARE_MESSAGES) -> Path:
    """``src`` with the E2E COUNTER of ``names``' frames stuck at 0, each frame re-signed with
    its Profile 2 CRC by cantools (the trial's firmware: its counter never incremented)."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    ids = {db.get_message_by_name(n).frame_id:
           int(dbc_attribute(db.get_message_by_name(n), "E2EDataIDs").split(",")[0])
           for n in names}
    with can.Logger(str(dst)) as out:
        for msg in can.LogReader(str(src)):
            if msg.arbitration_id in ids:
                data = bytearray(msg.data)
                data[1] &= 0xF0
                crc = compute_profile2_crc(bytes(data), ids[msg.arbitration_id])
                assert crc is not None
                data[0] = crc
                msg.data = data
            out.on_message_received(msg)
    return dst


def _analyze(capsys: pytest.CaptureFixture[str], log: Path, *argv: str
             ) -> tuple[int, str, dict[str, object]]:
    report = log.with_suffix(".json")
    code, out, err = run_cli(capsys, "analyze", str(log), "--report", str(report), *argv)
    assert "Traceback" not in err, err
    return code, out.strip().splitlines()[-1], json.loads(report.read_text())


@pytest.mark.parametrize("stream", ["never", "always"])
def test_a_firmware_that_never_sends_odom_twist_is_unjudged_not_passed(
        stream: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: PASS, exit 0, twist and DISTANCE ``passed: true`` on 0 samples, no word."""
    code, line, report = _analyze(capsys, _drive_log(tmp_path / "notwist.log", twist=False),
                                  "--stream", stream)
    assert code == 1, line
    assert line.startswith("UNJUDGED: no ODOM_TWIST frame in 3.0 s: twist and DISTANCE not "
                           "judged; on-board vs reference within"), line
    assert report["passed"] is False
    assert report["unjudged"] == {"reasons": [
        "no ODOM_TWIST frame in 3.0 s: twist and DISTANCE not judged"], "judged_passed": True}


def test_the_same_drive_with_its_twists_passes(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, line, report = _analyze(capsys, _drive_log(tmp_path / "twist.log", twist=True))
    assert (code, line.split(":")[0]) == (0, "PASS"), line
    assert "unjudged" not in report
    assert report["passed"] is True


# A --dbc without ODOM_TWIST's DISTANCE (the trial's DISTANCE judged on 0 samples, PASS) is now
# refused before any judging, one line, exit 2: tests/test_dbc_lacking_signal.py.


@pytest.mark.parametrize("stream", ["never", "always"])
def test_a_stuck_e2e_counter_fails_for_that_and_invents_no_reboot(
        stream: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: 'reboots 2: the firmware restarted at 0.33 s, 0.65 s ...' (a COUNTER 0 after a
    COUNTER 0 read as a power-up tick), the pose off against those power-up references, or a
    PASS on the one pose accepted; never the REPEATED frames."""
    log = _stuck(_drive_log(tmp_path / "ok.log", twist=True), tmp_path / "stuck.log")
    code, line, report = _analyze(capsys, log, "--stream", stream)
    assert code == 1, line
    assert line.startswith("FAIL: "), line
    assert " ODOM_POSE_X" in line, line
    assert "frames E2E REPEATED: the sender's E2E COUNTER does not advance" in line, line
    assert report["reboots"] == [], report["reboots"]
    stuck = {s["message"] for s in report["e2e_not_advancing"]}  # type: ignore[attr-defined]
    assert stuck == set(FIRMWARE_MESSAGES)


def _telemetry_of(log: Path) -> RobotTelemetry:
    telemetry = RobotTelemetry("robot001", Geometry.of(PMIR), "exact",
                               counter_bits=PMIR.counter_bits)
    for msg in can.LogReader(str(log)):
        telemetry.feed(msg)
    telemetry.end_watch()
    return telemetry


def test_the_live_end_verdict_says_what_was_never_heard_and_the_stuck_counter(
        tmp_path: Path) -> None:
    """The bridge's (and the monitor's) end verdict: before, PASS ('no ODOM_TWIST judged')
    and a 52 mm pose episode for the stuck counter."""
    none = end_verdict(_telemetry_of(_drive_log(tmp_path / "notwist.log", twist=False)))
    assert (none.verdict, none.reason) == (
        "UNJUDGED", "no ODOM_TWIST frame in the watch: twist and DISTANCE not judged "
        "(--require-firmware fails it)")
    required = end_verdict(_telemetry_of(tmp_path / "notwist.log"), require_firmware=True)
    assert required.verdict == "FAIL", required
    good = end_verdict(_telemetry_of(_drive_log(tmp_path / "twist.log", twist=True)))
    assert good.verdict == "PASS", good
    stuck = end_verdict(_telemetry_of(_stuck(tmp_path / "twist.log", tmp_path / "stuck.log")))
    assert stuck.verdict == "FAIL", stuck
    assert "E2E REPEATED: the sender's E2E COUNTER does not advance" in stuck.reason, stuck
    assert "pose was wrong" not in stuck.reason, stuck


def test_the_kit_says_the_acks_were_refused_as_repeated() -> None:
    """The pytest kit's configure: ACKs sent with a stuck COUNTER 0 were refused as REPEATED
    and the kit said 'no ODOM_ACK from the firmware'."""
    db = database()
    heard = Recorder(db)
    ack = db.get_message_by_name("ODOM_ACK")
    ids = [int(v) for v in dbc_attribute(ack, "E2EDataIDs").split(",")]

    def answer(request_counter: int, t_s: float) -> None:
        data = bytearray(8)
        data[1] = (request_counter & 0xF) << 4  # COUNTER 0, always
        data[2:4] = (0x300).to_bytes(2, "little")  # REQUEST_ID ODOM_SET_POSE
        crc = compute_profile2_crc(bytes(data), ids[0])
        assert crc is not None
        data[0] = crc
        heard.on_message_received(can.Message(arbitration_id=ack.frame_id, data=bytes(data),
                                              is_extended_id=False, timestamp=t_s))

    answer(15, 0.0)  # an earlier answer: COUNTER 0 accepted once
    sent: list[tuple[int, bytes]] = []

    def send(can_id: int, data: bytes) -> None:
        sent.append((can_id, data))
        answer(data[1] & 0xF, 0.01 * len(sent))

    session = CommandSession(heard, send, lambda done, t: bool(done()), ack_timeout_s=0.5)
    with pytest.raises(CommandNotAcked) as err:
        session.set_pose(0.0, 0.0, 0.0)
    assert err.value.reason == ("no ODOM_ACK that passed its E2E check (4 repeated refused: the "
                                "firmware's E2E COUNTER does not advance)"), err.value.reason


def test_the_fail_line_gives_the_worst_position_and_the_worst_heading_each() -> None:
    """Two episodes: one 7.556 mm off (heading right), one 40.88 mrad off (0.41 mm): the line
    named the second's 0.4144 mm as the worst, at epoch seconds, with '(enc 10)'."""
    wrongs = PoseWrongs()
    t0 = 1796342230.0
    wrongs.origin_s = t0
    lsb = 2 * math.pi / 65536
    wrongs.sample(5, t0 + 4.88, 7.556e-3, 0.0)
    wrongs.judged([(5, 7.556e-3)])
    wrongs.sample(6, t0 + 4.90, 0.0, 0.0)
    wrongs.judged([(6, 0.0)])
    wrongs.sample(7, t0 + 10.18, 0.4144e-3, 40.8814e-3)
    wrongs.judged([(7, 0.4144e-3)])
    assert wrongs.summary() == (
        "the on-board pose was wrong in 2 episodes (2 samples), worst position 7.5560 mm off at "
        "4.88 s, heading 40.8814 mrad off at 10.18 s")
    heading_only = PoseWrongs()
    heading_only.origin_s = t0
    heading_only.sample(1, t0 + 1.5, 0.0673e-3, 3 * lsb)
    heading_only.judged([(1, 0.0673e-3)])
    assert heading_only.summary().endswith("worst heading 0.2876 mrad off at 1.50 s")
    allowed = PoseWrongs()
    allowed.sample(1, 2.0, 2.0e-3, 0.0)
    allowed.judged([(1, 1.5e-3)])
    assert allowed.summary().endswith(
        "worst position 2.0000 mm off (1.5000 mm beyond its allowance) at 0.00 s")
    assert np.isclose(allowed.origin_s or 0.0, 2.0)  # a bridge: from its first sample


def test_an_unknown_bus_arg_is_warned_of_by_name(capsys: pytest.CaptureFixture[str]) -> None:
    """python-can passes any keyword on in ``**kwargs``: ``--bus-arg bogus=1`` was silent.
    Interfaces that read options from ``**kwargs`` (kvaser, pcan) make a refusal unsafe: one
    warning line; a parameter the interface names (``receive_own_messages``) says nothing."""
    code, _, err = run_cli(capsys, "monitor", "-i", "virtual", "-c", "trial23-bus-arg",
                           "--bus-arg", "bogus=1", "--bus-arg", "receive_own_messages=1",
                           "--duration", "0.2", "--json")
    assert code == 0, err
    assert err == ("warning: --bus-arg bogus: not a parameter of python-can's virtual "
                   "interface; it may be ignored\n"), err
