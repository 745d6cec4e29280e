"""A PROFILE page with MAX_WHEEL_SPEED 0 is no bound (issue #11's last note).

A firmware in FAULT (or one that lost its configuration) may report a plausibility bound of 0:
the live judges took it, and a 0 mm/s gate lets one count per period through, so a correct pose
became POSE WRONG (the monitor and the bridge) and ``analyze`` judged the log with the same gate.
Here a right pmir drive's PROFILE pages are rewritten to MAX_WHEEL_SPEED 0 with the CRC-32 of the
profile at bound 0 (the test's own, ``tests.test_profile_page``) and a fresh Profile 2 CRC
(cantools.autosar): the judges keep their bound (the profile's 4 m/s), judge the drive right,
and say that the page gave none."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import can
import cantools.autosar
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.sim import robot
from tests.test_live_reboot import bridge_of, monitor_of
from tests.test_profile_page import DB, crc32_iso_hdlc, parameter_bytes

PMIR = robot.load("pmir")
SAID = ("the firmware's PROFILE page gives max wheel speed 0 (no bound: a firmware in FAULT?); "
        "the judges keep 4 m/s (the last page's bound, else --robot pmir's)")


def _unbounded(page: can.Message) -> can.Message:
    """``page`` (ODOM_STATUS PROFILE) with MAX_WHEEL_SPEED 0 and the CRCs made anew."""
    status = DB.get_message_by_name("ODOM_STATUS")
    layout = {name: (status.get_signal_by_name(name).start, status.get_signal_by_name(name).length)
              for name in ("MAX_WHEEL_SPEED", "PROFILE_CRC")}
    assert layout == {"MAX_WHEEL_SPEED": (16, 16), "PROFILE_CRC": (32, 32)}  # little-endian
    zero = dataclasses.replace(PMIR, max_wheel_speed_m_s=0.0)
    data = bytearray(page.data)
    data[2:4] = (0).to_bytes(2, "little")
    data[4:8] = crc32_iso_hdlc(parameter_bytes(zero, "exact")).to_bytes(4, "little")
    assert status.dbc is not None
    data_ids = [int(v) for v in str(status.dbc.attributes["E2EDataIDs"].value).split(",")]
    fixed = cantools.autosar.apply_profile2_crc(bytes(data), data_ids[data[1] & 0x0F])
    assert fixed is not None
    return can.Message(timestamp=page.timestamp, arbitration_id=page.arbitration_id,
                       data=bytes(fixed), is_extended_id=False, channel=page.channel)


@pytest.fixture(scope="module")
def unbounded_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("unbounded")
    drive, rewritten = folder / "drive.log", folder / "unbounded.log"
    assert main(["run", "--robot", "pmir", "--duration", "3", "--seed", "2",
                 "--log", str(drive)]) == 0
    status_id = DB.get_message_by_name("ODOM_STATUS").frame_id
    pages = 0
    with can.LogReader(str(drive)) as reader, can.Logger(str(rewritten)) as writer:
        for msg in reader:
            if msg.arbitration_id == status_id and msg.data[1] >> 4 == 6:  # PAGE PROFILE
                msg, pages = _unbounded(msg), pages + 1
            writer.on_message_received(msg)
    assert pages >= 4
    return rewritten


def test_the_live_judges_keep_their_bound(unbounded_log: Path) -> None:
    monitor = monitor_of(unbounded_log, "pmir", "exact")
    assert monitor.tracker.counter_restarts == 0
    assert monitor.tracker.vs_reference.max_dpos_m < POSITION_LSB_M
    assert monitor.status["max_wheel_speed_m_s"] == 4.0
    assert monitor.status["profile_mismatch"] == SAID
    bridge = bridge_of(unbounded_log, "pmir", "exact")
    status = bridge.status()[1]
    assert status["pose_wrongs"]["episodes"] == 0
    assert bridge.tracker.vs_reference.max_dpos_m < POSITION_LSB_M
    profile = status["profile"]
    assert (profile["verdict"], profile["max_wheel_speed_m_s"]) == ("OK", 4.0)
    assert profile["detail"].startswith("the firmware's PROFILE page gives max wheel speed 0")


def test_analyze_keeps_the_profiles_bound_and_says_so(
    unbounded_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["analyze", str(unbounded_log), "--robot", "pmir"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert f"  - {SAID}" in out
