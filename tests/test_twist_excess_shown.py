"""A FAIL on ODOM_TWIST's speeds says by how much, never "by up to 0.000 m/s, 0.000 rad/s".

Found by the user trial (eleventh pass): a kobuki drive whose LINEAR_VEL was raised by one LSB
(1 mm/s) from 10 s on, re-signed with cantools' Profile 2 CRC, made `odocan analyze` print

    FAIL: on-board vs reference within 0.1 mm and 0.09587 mrad; ODOM_TWIST outside the
    reference's speeds by up to 0.000 m/s, 0.000 rad/s

(the report's excess was 0.18 mm/s: three decimals of m/s round it away), while the monitor says
the same excess in mm/s. The verdict now gives the excesses in mm/s and mrad/s to three
significant digits, as the report has them.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import can
import cantools
import pytest
from cantools.autosar import compute_profile2_crc
from cantools.database.can import Database

from odocan.host.cli.app import main
from odocan.sim import contract
from tests.dbc_typed import dbc_attribute

FROM_S = 10.0


def _raise_linear_vel(src: Path, dst: Path) -> int:
    """Copy ``src`` with ODOM_TWIST.LINEAR_VEL one LSB higher from ``FROM_S`` on (CRC re-signed,
    cantools); the number of frames changed."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    twist = db.get_message_by_name("ODOM_TWIST")
    ids = [int(v) for v in dbc_attribute(twist, "E2EDataIDs").split(",")]
    changed, first = 0, None
    with can.Logger(str(dst)) as out:
        for msg in can.LogReader(str(src)):
            first = msg.timestamp if first is None else first
            if msg.arbitration_id == twist.frame_id and msg.timestamp - first >= FROM_S:
                data = bytearray(msg.data)
                raw = int.from_bytes(data[2:4], "little", signed=True) + 1  # LINEAR_VEL: 16|16
                data[2:4] = raw.to_bytes(2, "little", signed=True)
                crc = compute_profile2_crc(bytes(data), ids[data[1] & 0xF])
                assert crc is not None
                data[0] = crc
                msg.data = data
                changed += 1
            out.on_message_received(msg)
    return changed


def test_a_twist_fail_names_a_nonzero_excess(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    log, edited, report = tmp_path / "r.log", tmp_path / "e.log", tmp_path / "e.json"
    assert main(["run", "--robot", "kobuki", "--duration", "20", "--log", str(log)]) == 0
    assert _raise_linear_vel(log, edited) > 400  # every twist of the last 10 s, 1 mm/s high
    capsys.readouterr()
    assert main(["analyze", str(edited), "--robot", "kobuki", "--report", str(report)]) == 1
    verdict = capsys.readouterr().out.strip().splitlines()[-1]
    excess_mps = json.loads(report.read_text())["onboard_twist_vs_reference"][
        "max_linear_excess_mps"]
    assert excess_mps > 0.0
    said = re.search(r"speeds by up to ([0-9.e+-]+) mm/s, ([0-9.e+-]+) mrad/s", verdict)
    assert said is not None, verdict  # was "by up to 0.000 m/s, 0.000 rad/s"
    assert float(said.group(1)) > 0.0, verdict
    assert abs(float(said.group(1)) - excess_mps * 1e3) <= 0.005 * excess_mps * 1e3, verdict
