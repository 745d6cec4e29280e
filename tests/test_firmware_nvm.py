"""``odocan firmware --nvm PATH``: the SecOC EPOCH in a file, so a restarted process is a reboot.

``sim.board.FileNvm`` on its own (format, atomic write, corrupt files refused), the CLI's one-line
refusals, then the real thing: ``odocan firmware --secoc-key --nvm`` as a process on a loopback
``udp_multicast`` channel (a unique group and port per test), a signed command acked, the process
killed with SIGKILL (no chance to save anything at exit), restarted on the same file: the
recorded command replayed is refused, a freshly signed one is acked; the Python firmware and the
C one (ABI 2, the file behind its NVM callbacks).
"""

from __future__ import annotations

import signal
import struct
import zlib
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.protocol.secoc import SecocSigner
from odocan.sim import cboard
from odocan.sim.board import NVM_MAGIC, FileNvm
from odocan.sim.exceptions import ConfigurationError
from tests import host_frames as hf
from tests.requires import require_executables
from tests.test_realtime import (
    START_TIMEOUT_S,
    _listen,
    _open_udp_or_skip,
    _start,
    _stop,
    _udp_channel,
)
from tests.test_secoc_host import one_line_error
from tests.test_secoc_rig import KEY, Counters, _recount, set_pose


def image(epoch: int) -> bytes:
    """The 12-byte file of ``epoch``, written out from the documented layout."""
    head = b"ODNV" + epoch.to_bytes(4, "little")
    return head + zlib.crc32(head).to_bytes(4, "little")


def test_a_missing_file_is_an_erased_cell_and_each_write_replaces_it_whole(
    tmp_path: Path,
) -> None:
    path = tmp_path / "fw.nvm"
    nvm = FileNvm(path)
    assert nvm.read_epoch() == 0
    assert not path.exists()
    assert nvm.write_epoch(1)
    assert path.read_bytes() == image(1)
    assert nvm.write_epoch(0xFFFF_FFFF)
    assert path.read_bytes() == image(0xFFFF_FFFF)
    assert FileNvm(path).read_epoch() == 0xFFFF_FFFF
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fw.nvm"]  # no temporary file left
    assert NVM_MAGIC == b"ODNV"


@pytest.mark.parametrize(
    ("content", "why"),
    [
        (b"", "0 bytes, expected 12"),
        (image(7)[:11], "11 bytes, expected 12"),
        (image(7) + b"\n", "13 bytes, expected 12"),
        (b"XXNV" + image(7)[4:], "bad magic"),
        (image(7)[:4] + struct.pack("<I", 8) + image(7)[8:], "bad CRC"),
    ],
    ids=["empty", "short", "long", "magic", "crc"],
)
def test_a_corrupt_file_is_refused_not_read_as_zero(
    tmp_path: Path, content: bytes, why: str
) -> None:
    path = tmp_path / "fw.nvm"
    path.write_bytes(content)
    with pytest.raises(ConfigurationError, match=why):
        FileNvm(path)
    assert path.read_bytes() == content  # left as found, for a person to look at


def test_a_write_that_fails_returns_false_and_says_why(tmp_path: Path) -> None:
    nvm = FileNvm(tmp_path / "gone" / "fw.nvm")  # the directory does not exist
    assert not nvm.write_epoch(3)
    assert nvm.read_epoch() == 0
    assert nvm.error is not None
    assert str(tmp_path / "gone" / "fw.nvm") in nvm.error


def test_the_cli_refuses_a_bad_nvm_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key = tmp_path / "k.key"
    key.write_bytes(KEY)
    key.chmod(0o600)
    nvm = tmp_path / "fw.nvm"
    err = one_line_error(capsys, "firmware", "--nvm", str(nvm), "-i", "virtual", "--duration", "1")
    assert "--nvm holds the SecOC EPOCH: it needs --secoc-key" in err
    nvm.write_bytes(image(5)[:7])
    err = one_line_error(capsys, "firmware", "--secoc-key", str(key), "--nvm", str(nvm),
                         "-i", "virtual", "--duration", "1")
    assert str(nvm) in err
    assert "7 bytes, expected 12" in err
    unwritable = tmp_path / "no-such-dir" / "fw.nvm"
    err = one_line_error(capsys, "firmware", "--secoc-key", str(key), "--nvm", str(unwritable),
                         "-i", "virtual", "--duration", "1")
    assert str(unwritable) in err


def _freshness(bus: can.BusABC, signer: SecocSigner) -> None:
    """Wait for the firmware's ODOM_FRESHNESS (boot or periodic) and adopt it."""
    got = _listen(bus, lambda c: c.of(fr.ODOM_FRESHNESS_ID), START_TIMEOUT_S)
    fresh = got.of(fr.ODOM_FRESHNESS_ID)
    assert fresh, "no ODOM_FRESHNESS from odocan firmware"
    assert signer.on_freshness(bytes(fresh[-1].data))


def _send_and_ack(bus: can.BusABC, frames: list[tuple[int, bytes]]) -> list[tuple[int, int]]:
    """Send ``frames``; the (RESULT, REASON) of each ODOM_ACK that answers a command frame."""
    commands = sum(can_id != fr.ODOM_AUTH_ID for can_id, _ in frames)
    for can_id, data in frames:
        bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
    got = _listen(bus, lambda c: len(c.of(fr.ODOM_ACK_ID)) >= commands, 5.0)
    answers = [hf.unpack_odom_ack(m.data) for m in got.of(fr.ODOM_ACK_ID)]
    return [(a.result, a.reason) for a in answers]


@pytest.mark.parametrize("kind", ["python", "c"])
def test_a_restarted_firmware_process_keeps_refusing_a_replay(kind: str, tmp_path: Path) -> None:
    if kind == "c":
        require_executables("make", "cc", install="apt-get install gcc make")
        cboard.load_library()  # built here, not inside the process's start-up timeout
    argv, kwargs = _udp_channel()
    bus = _open_udp_or_skip(kwargs)
    key, nvm = tmp_path / "k.key", tmp_path / "fw.nvm"
    key.write_bytes(KEY)
    key.chmod(0o600)
    firmware = [*argv, "--firmware", kind, "--secoc-key", str(key), "--nvm", str(nvm)]
    ok = [(0, 0)] * 3
    try:
        proc = _start(["firmware", *firmware])
        try:
            signer, host = SecocSigner(KEY), Counters()
            _freshness(bus, signer)
            recorded = signer.secure(set_pose(host, 1_000, 2_000))
            assert _send_and_ack(bus, recorded) == ok
        finally:
            _stop(proc, signal.SIGKILL)
        assert FileNvm(nvm).read_epoch() == 1
        proc = _start(["firmware", *firmware])
        try:
            signer = SecocSigner(KEY)
            _freshness(bus, signer)
            assert FileNvm(nvm).read_epoch() == 2  # the boot wrote EPOCH + 1 before anything
            replayer = Counters()  # fresh E2E counters: only SecOC can stop the replay
            replay = [(i, d if i == fr.ODOM_AUTH_ID else _recount(d, replayer(i), i))
                      for i, d in recorded]
            refused = _send_and_ack(bus, replay)
            assert len(refused) == 3
            assert {result for result, _ in refused} == {1}
            assert {reason for _, reason in refused} <= {fr.AckReason.AUTH_FAILED,
                                                        fr.AckReason.AUTH_FRESHNESS}
            assert _send_and_ack(bus, signer.secure(set_pose(replayer, 3_000, 4_000))) == ok
        finally:
            code, err = _stop(proc)
        assert code == 0, err
        assert "Traceback" not in err
    finally:
        bus.shutdown()
