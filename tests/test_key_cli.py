"""``odocan key derive``: the key file a stand-alone robot needs to take its fleet's commands.

The file must hold what ``odocan fleet --secoc-key`` provisions into that robot, checked against
SP 800-108 written out with ``cryptography``'s CMAC (``reference_robot_key``); a firmware holding
the fleet's derivation must accept commands signed from the file, and refuse the fleet key's.
"""

from __future__ import annotations

import random
import stat
from pathlib import Path

import pytest

from odocan.firmware import secoc as fw
from odocan.host.cli.app import main
from odocan.host.protocol.secoc import load_secoc_key
from odocan.host.testkit.options import RigOptions
from odocan.host.testkit.rig import make_rig
from tests.test_fleet_secoc import reference_robot_key
from tests.test_secoc import KEY, MemoryNvm, command, deliver, synced
from tests.test_secoc_host import one_line_error


@pytest.fixture
def fleet_key(tmp_path: Path) -> Path:
    path = tmp_path / "fleet.key"
    path.write_text(KEY.hex() + "\n")
    path.chmod(0o600)
    return path


def derive(fleet_key: Path, robot: str, out: Path, *extra: str) -> int:
    argv = ["key", "derive", "--fleet-key", str(fleet_key), "--robot", robot, "--out", str(out)]
    return main([*argv, *extra])


def test_the_file_is_the_fleets_derivation_mode_0600_never_printed(
    fleet_key: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for name in ("robot001", "robot017"):
        out = tmp_path / f"{name}.key"
        assert derive(fleet_key, name, out) == 0
        assert load_secoc_key(out) == reference_robot_key(KEY, name)
        assert out.read_text() == reference_robot_key(KEY, name).hex() + "\n"
        assert stat.S_IMODE(out.stat().st_mode) == 0o600
        raw = tmp_path / f"{name}.bin"
        assert derive(fleet_key, name, raw, "--format", "raw") == 0
        assert raw.read_bytes() == reference_robot_key(KEY, name)
        raw.unlink()
        printed = capsys.readouterr()
        assert reference_robot_key(KEY, name).hex() not in printed.out + printed.err
        assert KEY.hex() not in printed.out + printed.err
    assert sorted(p.name for p in tmp_path.iterdir()) == [  # no temporary file left behind
        "fleet.key", "robot001.key", "robot017.key"
    ]


def test_a_firmware_with_the_fleets_robot_key_acks_what_the_file_signs(
    fleet_key: Path, tmp_path: Path
) -> None:
    out = tmp_path / "robot001.key"
    assert derive(fleet_key, "robot001", out) == 0
    receiver = fw.SecocReceiver(reference_robot_key(KEY, "robot001"), MemoryNvm())
    pdu = command(random.Random(7), fw.SECURED_IDS[0])
    signed = synced(receiver, load_secoc_key(out)).sign(fw.SECURED_IDS[0], pdu)
    assert deliver(receiver, fw.SECURED_IDS[0], pdu, signed) is fw.AuthStatus.OK
    by_fleet_key = synced(receiver, KEY).sign(fw.SECURED_IDS[0], pdu)
    assert deliver(receiver, fw.SECURED_IDS[0], pdu, by_fleet_key) is fw.AuthStatus.FAILED
    by_other_robot = synced(receiver, reference_robot_key(KEY, "robot002"))
    signed = by_other_robot.sign(fw.SECURED_IDS[0], pdu)
    assert deliver(receiver, fw.SECURED_IDS[0], pdu, signed) is fw.AuthStatus.FAILED


def test_a_rig_provisioned_with_the_file_acks_a_signed_set_pose(
    fleet_key: Path, tmp_path: Path
) -> None:
    out = tmp_path / "robot001.key"
    assert derive(fleet_key, "robot001", out) == 0
    rig = make_rig(RigOptions(secoc_key=str(out)))
    try:
        rig.wait_ready()
        rig.set_pose(0.75, 0.5, 0.0)  # CommandRefused unless ACKed
        rig.step(0.1)
        assert abs(rig.pose.x_m - 0.75) < 1e-3
        assert abs(rig.pose.y_m - 0.5) < 1e-3
    finally:
        rig.close()


def test_an_existing_file_is_kept_unless_force(
    fleet_key: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "robot001.key"
    out.write_text("keep me\n")
    err = one_line_error(
        capsys, "key", "derive", "--fleet-key", str(fleet_key), "--robot", "robot001",
        "--out", str(out),
    )
    assert str(out) in err
    assert "--force" in err
    assert out.read_text() == "keep me\n"
    assert derive(fleet_key, "robot001", out, "--force") == 0
    assert load_secoc_key(out) == reference_robot_key(KEY, "robot001")
    assert stat.S_IMODE(out.stat().st_mode) == 0o600


def test_bad_input_is_one_line_exit_2_naming_the_path(
    fleet_key: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "r.key"
    short = tmp_path / "short.key"
    short.write_bytes(b"0123456789abcde")
    short.chmod(0o600)
    for bad_fleet in (short, tmp_path / "absent.key"):
        err = one_line_error(
            capsys, "key", "derive", "--fleet-key", str(bad_fleet), "--robot", "robot001",
            "--out", str(out),
        )
        assert str(bad_fleet) in err
    unwritable = tmp_path / "no" / "such" / "dir.key"
    err = one_line_error(
        capsys, "key", "derive", "--fleet-key", str(fleet_key), "--robot", "robot001",
        "--out", str(unwritable),
    )
    assert str(unwritable) in err
    for name in ("", "röbot", "robot 1"):
        err = one_line_error(
            capsys, "key", "derive", "--fleet-key", str(fleet_key), "--robot", name,
            "--out", str(out),
        )
        assert "robot name" in err
    assert not out.exists()
    assert "--fleet-key" in one_line_error(capsys, "key", "derive", "--robot", "robot001")
    assert "invalid choice" in one_line_error(
        capsys, "key", "rotate", "--fleet-key", str(fleet_key), "--robot", "r", "--out", str(out)
    )
