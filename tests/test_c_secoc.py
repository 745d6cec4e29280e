"""SecOC in the C firmware through the shared-library ABI (version 2): frame for frame the Python's.

The same scripted session runs on the lockstep rig twice, ``firmware="python"`` and
``firmware="c"`` (the key provisioned with ``odocan_fw_provision_secoc``, the EPOCH in the board's
NVM cell behind two C callbacks): a genuine set_pose, a forged one (random authenticators), an
unsigned one, a replay, a reboot and a replay after it, a genuine nav goal. Every frame
on the bus, its bytes and its time, must be the same; the verdicts are read from ODOM_ACK.
Then: a library of ABI 1 still runs without a key and is refused in one line with one; the CLI
takes ``--firmware c --secoc-key``.

Skips with the reason when make or a C compiler is missing, and fails instead under CI=true.
"""

from __future__ import annotations

import random
import subprocess
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.firmware.secoc import FRESHNESS_TX_MASK
from odocan.host.cli.app import main
from odocan.sim import cboard
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.rig import LockstepRig, RigConfig, firmware_params
from odocan.sim.robot import load
from tests import host_frames as hf
from tests.requires import require_executables
from tests.test_secoc_rig import (
    KEY,
    REQUEST,
    Bus,
    Counters,
    _recount,
    acks,
    last_freshness,
    set_pose,
    step,
    synced_signer,
)


@pytest.fixture(scope="module", autouse=True)
def c_library() -> None:
    """The C firmware library, built once (skip, or fail under CI, without make and cc)."""
    require_executables("make", "cc", install="apt-get install gcc make")
    cboard.load_library()


def forged(counters: Counters, rng: random.Random, fv: int) -> list[tuple[int, bytes]]:
    """A set_pose frame and an ODOM_AUTH with the right freshness and a random authenticator."""
    can_id, data = set_pose(counters, rng.randrange(1, 9_999), 0)[0]
    auth = hf.pack_odom_auth(counters(fr.ODOM_AUTH_ID), REQUEST[can_id], fv & FRESHNESS_TX_MASK,
                             rng.getrandbits(32), ErrorMask())
    return [(can_id, data), (fr.ODOM_AUTH_ID, auth)]


def nav_goal(counters: Counters) -> list[tuple[int, bytes]]:
    """A nav goal: X, Y, HEADING, then GO."""
    e = ErrorMask()
    return [(fr.NAV_GOAL_ID, hf.pack_nav_goal(counters(fr.NAV_GOAL_ID), f, v, e))
            for f, v in ((fr.NavGoalField.X, 5_000), (fr.NavGoalField.Y, 2_000),
                         (fr.NavGoalField.HEADING, 0), (fr.NavGoalField.GO, 0))]


def session(firmware: str) -> tuple[list[tuple[float, int, bytes]], list[tuple[int, int]]]:
    """The scripted session on ``firmware``: every frame (time, id, bytes) and the ACK verdicts."""
    bus = Bus()
    config = RigConfig(load("pmir"), scenario=None, secoc_key=KEY, firmware=firmware)
    seen: list[can.Message] = []
    with LockstepRig(config, [bus]) as rig:
        signer = synced_signer(rig, bus)
        host, attacker, rng = Counters(), Counters(), random.Random(18)
        genuine = signer.secure(set_pose(host, 12_345, -6_789))
        seen += step(rig, bus, genuine) + step(rig, bus)
        assert signer.next_fv is not None
        for _ in range(20):
            seen += step(rig, bus, forged(attacker, rng, signer.next_fv))
        seen += step(rig, bus, set_pose(host, 1, 1))  # unsigned: a host without the key
        for _ in range(3):
            seen += step(rig, bus)
        attacker.next = dict(host.next)
        replay = [(i, d if i == fr.ODOM_AUTH_ID else _recount(d, attacker(i), i))
                  for i, d in genuine]
        seen += step(rig, bus, replay)
        rig.board.reboot()  # RAM lost, the NVM cell (EPOCH) kept
        seen += step(rig, bus) + step(rig, bus)
        seen += step(rig, bus, replay)
        fresh = last_freshness(seen)
        assert fresh is not None
        assert signer.on_freshness(fresh)
        seen += step(rig, bus, signer.secure(nav_goal(host)))
        for _ in range(10):
            seen += step(rig, bus)
        seen += bus.take()
    frames = [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in seen]
    return frames, [(a.result, a.reason) for a in acks(seen)]


def test_the_c_firmware_verifies_frame_for_frame_as_the_python_firmware() -> None:
    python_frames, python_acks = session("python")
    c_frames, c_acks = session("c")
    assert c_frames == python_frames
    assert c_acks == python_acks
    ok, missing = (0, 0), (1, fr.AckReason.AUTH_MISSING)
    failed, stale = (1, fr.AckReason.AUTH_FAILED), (1, fr.AckReason.AUTH_FRESHNESS)
    assert c_acks[:3] == [ok] * 3  # the genuine set_pose, its three frames
    assert c_acks[3:23] == [failed] * 20  # 20 forgeries, none accepted
    assert c_acks[23:26] == [missing] * 3  # the unsigned set_pose
    assert c_acks[26:29] == [stale] * 3  # the genuine command replayed: its freshness was used
    assert set(c_acks[29:32]) <= {failed, stale}  # replayed after the reboot
    assert c_acks[32:] == [ok] * 4  # the genuine nav goal after the host resynchronised


def test_the_provisioned_c_firmware_sends_its_boot_freshness_and_writes_its_epoch() -> None:
    bus = Bus()
    config = RigConfig(load("pmir"), scenario=None, secoc_key=KEY, firmware="c")
    with LockstepRig(config, [bus]) as rig:
        assert isinstance(rig.board.ecu, cboard.CEcu)
        seen = step(rig, bus) + step(rig, bus)
        assert rig.board.nvm.epoch == 1
        assert rig.board.nvm.writes == 1
        rig.board.reboot()
        assert rig.board.nvm.epoch == 2
        lib = cboard.load_library()
        ecu = rig.board.ecu
        null_read, null_write = cboard._NvmRead(), cboard._NvmWrite()
        again = lib.odocan_fw_provision_secoc(ecu._fw, KEY, 16, null_read, null_write, None)
        assert again == -1  # a key is given once, at reset
    fresh = last_freshness(seen)
    assert fresh is not None
    assert hf.unpack_odom_freshness(fresh).fv == 1 << 28  # EPOCH 1, COUNT 0


def test_a_c_firmware_without_an_nvm_cell_refuses_every_secured_command() -> None:
    class NoBoard:
        def transmit(self, can_id: int, data: bytes) -> bool:
            sent.append((can_id, data))
            return True

    sent: list[tuple[int, bytes]] = []
    ecu = cboard.CEcu(NoBoard(), firmware_params(load("pmir"), "exact"), secoc_key=KEY, nvm=None)
    ecu.tick(0)
    fresh = [hf.unpack_odom_freshness(d) for i, d in sent if i == fr.ODOM_FRESHNESS_ID]
    assert [f.fv for f in fresh] == [0]  # CAUSE UNAVAILABLE: the host refuses to sign


STUB_ABI1 = r"""
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
typedef bool (*tx_fn)(void *, uint32_t, const uint8_t *);
uint32_t odocan_fw_abi_version(void) { return 1u; }
size_t odocan_fw_state_size(void) { return 8u; }
int odocan_fw_init(void *fw, size_t size, const uint32_t p[6], tx_fn tx, void *ctx)
{ (void)fw; (void)size; (void)p; (void)tx; (void)ctx; return 0; }
void odocan_fw_rx_isr(void *fw, uint32_t id, uint32_t len, const uint8_t *d)
{ (void)fw; (void)id; (void)len; (void)d; }
void odocan_fw_bus_state(void *fw, bool off) { (void)fw; (void)off; }
void odocan_fw_rx_overrun(void *fw) { (void)fw; }
void odocan_fw_tick(void *fw, uint64_t now) { (void)fw; (void)now; }
uint32_t odocan_fw_state(const void *fw) { (void)fw; return 1u; }
uint32_t odocan_fw_errors(const void *fw) { (void)fw; return 0u; }
uint32_t odocan_fw_ticks(const void *fw) { (void)fw; return 0u; }
"""


def test_a_library_of_abi_1_runs_without_a_key_and_is_refused_in_one_line_with_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A team's firmware built against ABI 1 (no odocan_fw_provision_secoc)."""
    source, lib = tmp_path / "abi1.c", tmp_path / "libabi1.so"
    source.write_text(STUB_ABI1)
    subprocess.run(["cc", "-shared", "-fPIC", str(source), "-o", str(lib)], check=True)
    monkeypatch.setenv(cboard.LIBRARY_ENV, str(lib))
    assert cboard.board_maker("c") is cboard.CFirmwareBoard
    with pytest.raises(ConfigurationError, match="ABI version 1, which takes no SecOC key"):
        cboard.board_maker("c", secoc=True)
    key = tmp_path / "k.key"
    key.write_bytes(KEY)
    key.chmod(0o600)
    assert main(["run", "--firmware", "c", "--secoc-key", str(key), "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --secoc-key: the C firmware {lib} has ABI version 1")
    assert err.count("\n") == 1


def test_run_takes_the_c_firmware_with_a_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key = tmp_path / "k.key"
    key.write_bytes(KEY)
    key.chmod(0o600)
    code = main(["run", "--firmware", "c", "--secoc-key", str(key), "--duration", "2"])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    assert "PASS" in out
