"""The host side of SecOC: the bridge signs what it sends, the CLI loads and refuses keys.

The bridge's signed frames are checked by the firmware's own verifier (``firmware.secoc``), an
implementation independent of the host's (``cryptography``'s CMAC, cantools' frames).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware import secoc as fw
from odocan.host.cli.app import main
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import BridgeConfig, RobotEndpoint, _Robot
from odocan.host.mqtt.broker import BrokerURL
from odocan.host.protocol.commands import CommandEncoder
from odocan.host.protocol.secoc import SecocSigner
from odocan.host.testkit.options import RigOptions
from odocan.host.testkit.rig import make_rig
from odocan.sim import robot
from tests.test_secoc import KEY, MemoryNvm


def bridge_robot(bus: can.BusABC, signer: SecocSigner | None) -> _Robot:
    pmir = robot.load("pmir")
    endpoint = RobotEndpoint("r1", bus, Geometry.of(pmir), counter_bits=pmir.counter_bits,
                             signer=signer)
    return _Robot(endpoint, BridgeConfig(broker=BrokerURL("127.0.0.1", 1883)))


def sent(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (msg := bus.recv(0.05)) is not None:
        out.append(msg)
    return out


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    channel = "secoc_host_bridge"
    a = can.Bus(interface="virtual", channel=channel)
    b = can.Bus(interface="virtual", channel=channel)
    yield a, b
    a.shutdown()
    b.shutdown()


def test_the_bridge_signs_each_command_frame_and_the_firmware_verifies_it(
    buses: tuple[can.BusABC, can.BusABC],
) -> None:
    host_bus, firmware_bus = buses
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    gate = fw.SecuredCommands(receiver)
    signer = SecocSigner(KEY)
    r = bridge_robot(host_bus, signer)
    payload = json.dumps({"x_m": 1.5, "y_m": -0.25, "heading_rad": 0.5}).encode()
    [early] = r.on_command("set_pose", payload)  # no ODOM_FRESHNESS seen yet: refused, unsent
    _, answer = early
    assert answer["result"] == "rejected"
    assert "ODOM_FRESHNESS" in answer["reason"]
    assert sent(firmware_bus) == []
    assert signer.on_freshness(receiver.freshness_frame(0, fw.FreshnessCause.BOOT))
    r.on_command("set_pose", payload)
    frames = sent(firmware_bus)
    assert [m.arbitration_id for m in frames] == [fr.ODOM_SET_POSE_ID, fr.ODOM_AUTH_ID] * 4
    verdicts = []
    for command, auth in zip(frames[::2], frames[1::2], strict=True):
        gate.hold(fw.AuthRequest.ODOM_SET_POSE, bytes(command.data), 0)
        result = gate.authenticate(fw.unpack_odom_auth(bytes(auth.data)))
        assert result is not None
        verdicts.append(result[0])
    assert verdicts == [fw.AuthStatus.OK] * 4
    assert r.commands_sent == 1
    assert r.commands_rejected == 1


def test_without_a_key_the_bridge_sends_what_it_sent_before(
    buses: tuple[can.BusABC, can.BusABC],
) -> None:
    host_bus, firmware_bus = buses
    r = bridge_robot(host_bus, None)
    r.on_command("set_pose", json.dumps({"x_m": 1, "y_m": 2, "heading_rad": 0}).encode())
    assert [m.arbitration_id for m in sent(firmware_bus)] == [fr.ODOM_SET_POSE_ID] * 4


def one_line_error(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(list(argv)) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ")
    assert "\n" not in err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize("command", ["run", "bridge"])
def test_a_bad_key_file_is_one_line_exit_2(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    short = tmp_path / "short.key"
    short.write_bytes(b"0123456789abcde")  # 15 bytes
    short.chmod(0o600)
    err = one_line_error(capsys, command, "--secoc-key", str(short), "--duration", "1")
    assert str(short) in err
    assert "15 bytes" in err
    missing = tmp_path / "absent.key"
    err = one_line_error(capsys, command, "--secoc-key", str(missing), "--duration", "1")
    assert str(missing) in err
    secret = tmp_path / "secret.key"
    secret.write_text("00112233445566778899aabbccddeeff0\n")  # 33 hex digits
    secret.chmod(0o600)
    err = one_line_error(capsys, command, "--secoc-key", str(secret), "--duration", "1")
    assert "00112233" not in err  # the key never appears in a message


def test_run_provisions_the_lockstep_firmware_with_the_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key = tmp_path / "robot.key"
    key.write_text(KEY.hex() + "\n")
    key.chmod(0o600)
    log = tmp_path / "run.log"
    code = main(
        [
            "run",
            "--scenario",
            "straight",
            "--duration",
            "3",
            "--secoc-key",
            str(key),
            "--log",
            str(log),
        ]
    )
    out = capsys.readouterr()
    assert code == 0, out.err
    assert KEY.hex() not in out.out + out.err + log.read_text()
    freshness = [line for line in log.read_text().splitlines() if " 304#" in line]
    assert len(freshness) >= 3  # at boot, then every second
    plain = tmp_path / "plain.log"
    assert main(["run", "--scenario", "straight", "--duration", "3", "--log", str(plain)]) == 0
    assert " 304#" not in plain.read_text()


def test_the_testkit_provisions_and_signs_with_the_secoc_key_option(tmp_path: Path) -> None:
    key = tmp_path / "robot.key"
    key.write_bytes(KEY)
    key.chmod(0o600)
    rig = make_rig(RigOptions(secoc_key=str(key)))
    try:
        rig.wait_ready()
        rig.set_pose(1.25, -0.5, 0.0)  # signed: ACKed (CommandRefused otherwise)
        rig.step(0.1)
        assert abs(rig.pose.x_m - 1.25) < 1e-3
        assert abs(rig.pose.y_m + 0.5) < 1e-3
        unsigned = CommandEncoder().encode("set_pose", b'{"x_m": 9, "y_m": 9, "heading_rad": 0}')
        for frame in unsigned.frames:
            rig.send(frame.can_id, frame.data)
        rig.step(0.1)
        reasons = [a["REASON"] for a in rig.frames("ODOM_ACK")]
        assert reasons[-4:] == ["AUTH_MISSING"] * 4
        assert abs(rig.pose.x_m - 1.25) < 1e-3
    finally:
        rig.close()
