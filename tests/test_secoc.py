"""SecOC: the host signer and the firmware verifier agree; forgery, replay, reboot are refused."""

from __future__ import annotations

import os
import random
from pathlib import Path

import can
import cantools
import cantools.autosar
import pytest
from cantools.subparsers.dump.formatting import layout_string

from odocan.firmware import secoc as fw
from odocan.firmware.cmac import cmac, cmac_key
from odocan.firmware.e2e import E2EReceiver, E2EStatus
from odocan.host.protocol import secoc as host
from odocan.sim.exceptions import OdocanError
from tests import host_frames as hf
from tests.dbc_typed import integers, load_can_dbc

KEY = bytes.fromhex("000102030405060708090a0b0c0d0e0f")
OTHER_KEY = bytes.fromhex("f0e0d0c0b0a090807060504030201000")
CONTRACT = Path(__file__).resolve().parent.parent / "dbc" / "odocan.dbc"
NAV_GOAL, SET_POSE, CONFIG = fw.SECURED_IDS


class MemoryNvm:
    """A simulated NVM cell (survives ``boot()``); ``fail`` makes every write fail."""

    def __init__(self, epoch: int = 0) -> None:
        self.epoch = epoch
        self.writes = 0
        self.fail = False

    def read_epoch(self) -> int:
        return self.epoch

    def write_epoch(self, epoch: int) -> bool:
        if self.fail:
            return False
        self.epoch = epoch
        self.writes += 1
        return True


def command(rng: random.Random, can_id: int) -> bytes:
    """A random E2E-protected 8-byte command frame (payload need not be meaningful for SecOC)."""
    frame = bytearray(rng.randbytes(8))
    hf.p02_protect(frame, rng.randrange(16), tuple(range(16)))
    return bytes(frame)


def synced(receiver: fw.SecocReceiver, key: bytes = KEY) -> host.SecocSigner:
    """A host signer that has seen the receiver's ODOM_FRESHNESS."""
    signer = host.SecocSigner(key)
    assert signer.on_freshness(receiver.freshness_frame(0, fw.FreshnessCause.BOOT))
    return signer


def deliver(receiver: fw.SecocReceiver, can_id: int, pdu: bytes, auth: bytes) -> fw.AuthStatus:
    """What the firmware does with a (command, ODOM_AUTH) pair that passed E2E."""
    fields = fw.unpack_odom_auth(auth)
    assert fw.SECURED_IDS[fields.request] == can_id
    return receiver.verify(can_id, pdu, fields.freshness, fields.authenticator)


def test_authenticator_is_cmac_of_one_block() -> None:
    pdu = bytes(range(8))
    block = fw.authenticator_input(0x301, pdu, 0x123456789ABC)
    assert block.hex() == "0301" + pdu.hex() + "123456789abc"
    full = cmac(cmac_key(KEY), block)
    assert fw.authenticator(cmac_key(KEY), 0x301, pdu, 0x123456789ABC) == int.from_bytes(
        full[:4], "big"
    )


def test_host_signer_and_firmware_verifier_agree() -> None:
    rng = random.Random(1)
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    signer = synced(receiver)
    for _ in range(500):
        can_id = rng.choice(fw.SECURED_IDS)
        pdu = command(rng, can_id)
        fv = signer.next_fv
        assert fv is not None
        auth = signer.sign(can_id, pdu)
        assert signer.mac(can_id, pdu, fv) == fw.authenticator(cmac_key(KEY), can_id, pdu, fv)
        assert deliver(receiver, can_id, pdu, auth) is fw.AuthStatus.OK
        assert receiver.last_fv == fv
    assert receiver.count_ok == 500


def test_each_wrong_part_is_refused() -> None:
    """Another key, another message ID, one flipped payload bit: FAILED; FV state unchanged."""
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    pdu = command(random.Random(2), SET_POSE)
    last = receiver.last_fv
    wrong_key = synced(receiver, OTHER_KEY).sign(SET_POSE, pdu)
    assert deliver(receiver, SET_POSE, pdu, wrong_key) is fw.AuthStatus.FAILED
    auth = fw.unpack_odom_auth(synced(receiver).sign(SET_POSE, pdu))
    assert receiver.verify(CONFIG, pdu, auth.freshness, auth.authenticator) is fw.AuthStatus.FAILED
    flipped = bytes([pdu[0] ^ 1]) + pdu[1:]
    assert receiver.verify(SET_POSE, flipped, auth.freshness, auth.authenticator) == (
        fw.AuthStatus.FAILED
    )
    assert receiver.last_fv == last
    assert receiver.count_failed == 3
    assert receiver.verify(SET_POSE, pdu, auth.freshness, auth.authenticator) is fw.AuthStatus.OK


@pytest.mark.parametrize("mac_bits", [24, 32])
def test_ten_thousand_random_authenticators_are_all_refused(mac_bits: int) -> None:
    """A node without the key: random tags on valid commands at the right freshness."""
    rng = random.Random(mac_bits)
    receiver = fw.SecocReceiver(KEY, MemoryNvm(), mac_bits=mac_bits)
    for _ in range(10_000):
        can_id = rng.choice(fw.SECURED_IDS)
        freshness = (receiver.last_fv + 1) & fw.FRESHNESS_TX_MASK  # public: seen on the bus
        tag = rng.getrandbits(mac_bits)
        assert receiver.verify(can_id, command(rng, can_id), freshness, tag) is not (
            fw.AuthStatus.OK
        )
    assert receiver.count_ok == 0
    assert receiver.count_failed == 10_000


def test_truncation_compares_only_the_first_bits() -> None:
    """At 8 bits the right top byte verifies whatever the rest: the bench's rate is 2^-N."""
    receiver = fw.SecocReceiver(KEY, MemoryNvm(), mac_bits=8)
    pdu = bytes(8)
    fv = receiver.last_fv + 1
    top = fw.authenticator(cmac_key(KEY), NAV_GOAL, pdu, fv) >> 24
    assert receiver.verify(NAV_GOAL, pdu, fv & 0xFFFF, top) is fw.AuthStatus.OK
    assert receiver.verify(NAV_GOAL, pdu, (fv + 1) & 0xFFFF, top) is fw.AuthStatus.FAILED


def test_recorded_genuine_commands_replayed_later_are_refused() -> None:
    rng = random.Random(3)
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    signer = synced(receiver)
    recorded = []
    for _ in range(200):
        can_id = rng.choice(fw.SECURED_IDS)
        pdu = command(rng, can_id)
        auth = signer.sign(can_id, pdu)
        assert deliver(receiver, can_id, pdu, auth) is fw.AuthStatus.OK
        recorded.append((can_id, pdu, auth))
    last = receiver.last_fv
    statuses = [deliver(receiver, *pair) for pair in recorded]  # oldest first, then the last one
    assert fw.AuthStatus.OK not in statuses
    assert set(statuses) == {fw.AuthStatus.FRESHNESS}
    assert deliver(receiver, *recorded[-1]) is fw.AuthStatus.FRESHNESS  # the newest one, at once
    assert receiver.last_fv == last


def test_a_reboot_does_not_reopen_old_freshness_values() -> None:
    rng = random.Random(4)
    nvm = MemoryNvm()
    receiver = fw.SecocReceiver(KEY, nvm)
    signer = synced(receiver)
    before = []
    for _ in range(50):
        pdu = command(rng, NAV_GOAL)
        before.append((NAV_GOAL, pdu, signer.sign(NAV_GOAL, pdu)))  # signed, never delivered
    assert nvm.epoch == 1
    receiver.boot()  # power cycle: RAM state gone, the NVM cell kept
    assert (nvm.epoch, nvm.writes, receiver.epoch) == (2, 2, 2)
    assert receiver.last_fv == 2 << fw.COUNT_BITS
    assert all(deliver(receiver, *pair) is not fw.AuthStatus.OK for pair in before)
    rebooted = fw.SecocReceiver(KEY, nvm)  # a cold start reads the same cell: epoch 3
    assert rebooted.epoch == 3
    assert rebooted.sync_cause is fw.FreshnessCause.BOOT
    assert all(deliver(rebooted, *pair) is not fw.AuthStatus.OK for pair in before)
    # Resynchronisation: the host adopts ODOM_FRESHNESS and its next command goes through.
    pdu = command(rng, CONFIG)
    old_signer_auth = signer.sign(CONFIG, pdu)
    assert deliver(rebooted, CONFIG, pdu, old_signer_auth) is not fw.AuthStatus.OK
    assert signer.on_freshness(rebooted.freshness_frame(1, fw.FreshnessCause.REFUSED))
    assert deliver(rebooted, CONFIG, pdu, signer.sign(CONFIG, pdu)) is fw.AuthStatus.OK


def test_freshness_window_is_one_to_4096_ahead() -> None:
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    signer = synced(receiver)
    pdu = bytes(8)
    assert signer.next_fv is not None
    signer.next_fv += fw.FRESHNESS_WINDOW  # 4097 ahead of last: refused
    assert deliver(receiver, SET_POSE, pdu, signer.sign(SET_POSE, pdu)) is fw.AuthStatus.FRESHNESS
    signer.next_fv = receiver.last_fv + fw.FRESHNESS_WINDOW  # exactly 4096 ahead: accepted
    assert deliver(receiver, SET_POSE, pdu, signer.sign(SET_POSE, pdu)) is fw.AuthStatus.OK
    assert receiver.sync_cause is fw.FreshnessCause.REFUSED  # the refusal asked for a resync
    assert receiver.take_sync_cause() is fw.FreshnessCause.REFUSED
    assert receiver.take_sync_cause() is None  # sent once
    frame = receiver.freshness_frame(5, fw.FreshnessCause.REFUSED)
    assert hf.unpack_odom_freshness(frame) == hf.OdomFreshness(
        5, fw.FreshnessCause.REFUSED, receiver.last_fv
    )
    assert host.FRESHNESS_WINDOW == fw.FRESHNESS_WINDOW


def test_epoch_rolls_over_before_count_runs_out_and_the_host_follows() -> None:
    nvm = MemoryNvm(epoch=6)
    receiver = fw.SecocReceiver(KEY, nvm)
    receiver.last_fv = (7 << fw.COUNT_BITS) | (fw.ROLLOVER_COUNT - 1)  # as after ~2^28 commands
    signer = synced(receiver)
    for _ in range(3):  # ROLLOVER_COUNT, ROLLOVER_COUNT + 1 (rolls over), then EPOCH 8's first
        pdu = bytes(8)
        assert deliver(receiver, NAV_GOAL, pdu, signer.sign(NAV_GOAL, pdu)) is fw.AuthStatus.OK
    assert (receiver.epoch, nvm.epoch) == (8, 8)
    assert receiver.last_fv == (8 << fw.COUNT_BITS) + 1


def test_fail_closed_without_key_nvm_or_epochs() -> None:
    pdu = bytes(8)
    broken = MemoryNvm()
    broken.fail = True
    for receiver in (
        fw.SecocReceiver(KEY[:15], MemoryNvm()),
        fw.SecocReceiver(KEY, broken),
        fw.SecocReceiver(KEY, MemoryNvm(epoch=fw.EPOCH_MAX)),
    ):
        assert receiver.epoch == 0  # unavailable: no EPOCH to accept a freshness value in
        assert receiver.sync_cause is fw.FreshnessCause.UNAVAILABLE
        mac = fw.authenticator(cmac_key(KEY), NAV_GOAL, pdu, 1)
        assert receiver.verify(NAV_GOAL, pdu, 1, mac) is fw.AuthStatus.UNAVAILABLE
        frame = receiver.freshness_frame(0, fw.FreshnessCause.UNAVAILABLE)
        signer = host.SecocSigner(KEY)
        assert not signer.on_freshness(frame)
        with pytest.raises(host.SecocNotSynchronised):
            signer.sign(NAV_GOAL, pdu)


def test_held_commands_wait_for_their_authenticator() -> None:
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    gate = fw.SecuredCommands(receiver)
    signer = synced(receiver)
    pose, goal = bytes(8), bytes(range(8))
    assert gate.hold(fw.AuthRequest.ODOM_SET_POSE, pose, tick=10) is None
    assert gate.hold(fw.AuthRequest.NAV_GOAL, goal, tick=10) is None
    verdict = gate.authenticate(fw.unpack_odom_auth(signer.sign(NAV_GOAL, goal)))
    assert verdict == (fw.AuthStatus.OK, fw.Held(NAV_GOAL, goal, 10))
    assert gate.authenticate(fw.unpack_odom_auth(signer.sign(NAV_GOAL, goal))) is None  # orphan
    assert gate.orphans == 1
    assert gate.expire(12) is None  # two ticks: still waiting
    assert gate.expire(13) == fw.Held(SET_POSE, pose, 10)  # AUTH_MISSING
    assert gate.expire(13) is None
    gate.hold(fw.AuthRequest.ODOM_CONFIG, pose, tick=20)
    assert gate.hold(fw.AuthRequest.ODOM_CONFIG, goal, tick=20) == fw.Held(CONFIG, pose, 20)


def test_frame_codecs_match_the_dbc() -> None:
    db = load_can_dbc(CONTRACT)
    auth_msg = db.get_message_by_name("ODOM_AUTH")
    fresh_msg = db.get_message_by_name("ODOM_FRESHNESS")
    assert (auth_msg.frame_id, fresh_msg.frame_id) == (fw.ODOM_AUTH_ID, fw.ODOM_FRESHNESS_ID)
    rng = random.Random(5)
    rx = E2EReceiver(fw.ODOM_AUTH_DATA_IDS)
    for counter in range(40):
        fields = (rng.randrange(3), rng.getrandbits(16), rng.getrandbits(32))
        data = hf.pack_odom_auth(counter, *fields)
        assert rx.check(data) is E2EStatus.OK
        assert cantools.autosar.check_profile2_crc(data, fw.ODOM_AUTH_DATA_IDS[counter & 0xF])
        decoded = integers(auth_msg, data)
        assert (decoded["REQUEST"], decoded["FRESHNESS"], decoded["AUTHENTICATOR"]) == fields
        assert fw.unpack_odom_auth(data) == fw.OdomAuth(counter & 0xF, *fields)
        fv = rng.getrandbits(fw.COUNT_BITS + fw.EPOCH_BITS)
        data = fw.pack_odom_freshness(counter, fw.FreshnessCause.PERIODIC, fv)
        decoded = integers(fresh_msg, data)
        assert (decoded["FV_EPOCH"] << fw.COUNT_BITS) | decoded["FV_COUNT"] == fv
        assert hf.unpack_odom_freshness(data).fv == fv
    signer = host.SecocSigner(KEY)
    assert (signer.mac_bits, signer.freshness_bits) == (fw.MAC_BITS, fw.FRESHNESS_TX_BITS)
    assert (signer.count_bits, signer.epoch_bits) == (fw.COUNT_BITS, fw.EPOCH_BITS)


def test_a_bad_freshness_frame_is_ignored_by_the_host() -> None:
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    signer = synced(receiver)
    good = receiver.freshness_frame(3, fw.FreshnessCause.PERIODIC)
    corrupted = good[:4] + bytes([good[4] ^ 0x10]) + good[5:]
    before = signer.next_fv
    assert not signer.on_freshness(corrupted)
    assert not signer.on_freshness(good[:7])
    assert signer.next_fv == before


def test_over_a_python_can_bus() -> None:
    """HOST secures a set_pose sequence, ODOM_MCU receives it from a real python-can bus."""
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    gate = fw.SecuredCommands(receiver)
    signer = synced(receiver)
    rng = random.Random(6)
    commands = [(SET_POSE, command(rng, SET_POSE)) for _ in range(4)]
    with (
        can.Bus(interface="virtual", channel="secoc-test", receive_own_messages=False) as tx,
        can.Bus(interface="virtual", channel="secoc-test") as rx,
    ):
        for can_id, data in signer.secure(commands):
            tx.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        acted = []
        for _ in range(8):
            msg = rx.recv(timeout=1.0)
            assert msg is not None
            if msg.arbitration_id == fw.ODOM_AUTH_ID:
                verdict = gate.authenticate(fw.unpack_odom_auth(bytes(msg.data)))
                assert verdict is not None
                assert verdict[0] is fw.AuthStatus.OK
                acted.append((verdict[1].can_id, verdict[1].pdu))
            else:
                gate.hold(fw.AuthRequest.ODOM_SET_POSE, bytes(msg.data), tick=0)
    assert acted == commands


def test_key_file_raw_or_hex(tmp_path: Path) -> None:
    raw = tmp_path / "raw.key"
    raw.write_bytes(KEY)
    hexed = tmp_path / "hex.key"
    hexed.write_text(KEY.hex() + "\n")
    raw.chmod(0o600)
    hexed.chmod(0o600)
    assert host.load_secoc_key(raw) == host.load_secoc_key(hexed) == KEY


def test_a_key_file_open_to_others_loads_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "shared.key"
    path.write_bytes(KEY)
    path.chmod(0o600)
    with caplog.at_level("WARNING", logger="odocan.host.protocol.secoc"):
        host.load_secoc_key(path)
        assert caplog.records == []
        path.chmod(0o644)
        assert host.load_secoc_key(path) == KEY
    assert [r.getMessage() for r in caplog.records] == [
        f"SecOC key {path} is open to other users (mode 644): chmod 600 it"
    ]
    assert KEY.hex() not in caplog.text


def test_a_wrong_key_open_to_others_is_only_the_error(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """One line: the file is no key, so its mode is not worth a warning."""
    path = tmp_path / "bad.key"
    path.write_bytes(b"\x01" * 15)
    path.chmod(0o644)
    with caplog.at_level("WARNING", logger="odocan.host.protocol.secoc"), \
            pytest.raises(OdocanError, match="15 bytes"):
        host.load_secoc_key(path)
    assert caplog.records == []


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"\x01" * 15, "15 bytes, expected 16 raw bytes or 32 hex digits"),
        (b"\x01" * 17, "17 bytes"),
        (b"zz" * 16, "32 bytes"),
        (b"", "0 bytes"),
    ],
)
def test_key_file_of_the_wrong_length_is_one_line_naming_the_path(
    tmp_path: Path, content: bytes, message: str
) -> None:
    path = tmp_path / "bad.key"
    path.write_bytes(content)
    with pytest.raises(OdocanError) as caught:
        host.load_secoc_key(path)
    text = str(caught.value)
    assert str(path) in text
    assert message in text
    assert "\n" not in text
    assert KEY.hex() not in text


@pytest.mark.parametrize("kind", ["missing", "directory", "fifo"])
def test_unreadable_key_file_is_one_line_naming_the_path(tmp_path: Path, kind: str) -> None:
    """A FIFO is refused before any read (reading it would block until a writer came)."""
    path = tmp_path / "secoc.key"
    if kind == "directory":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    with pytest.raises(OdocanError, match=r"^cannot read SecOC key .*secoc\.key: \w") as caught:
        host.load_secoc_key(path)
    assert "\n" not in str(caught.value)


def test_only_secured_ids_are_signed() -> None:
    signer = synced(fw.SecocReceiver(KEY, MemoryNvm()))
    with pytest.raises(OdocanError, match="0x100 is not a secured command"):
        signer.sign(0x100, bytes(8))
    assert signer.secure([(0x100, bytes(8))]) == [(0x100, bytes(8))]


DOC = Path(__file__).resolve().parent.parent / "docs" / "secoc.md"


def test_the_doc_draws_both_secoc_frames() -> None:
    doc = DOC.read_text(encoding="utf-8")
    db = load_can_dbc(CONTRACT)
    for message in (db.get_message_by_name(n) for n in ("ODOM_AUTH", "ODOM_FRESHNESS")):
        assert layout_string(message) in doc, f"docs/secoc.md: layout of {message.name} is stale"


def test_the_doc_vectors_for_the_c_port() -> None:
    """Each row of the doc's table: the firmware and the host give the same tag and frame."""
    key = bytes.fromhex("2b7e151628aed2a6abf7158809cf4f3c")
    rows = [
        line.split("|")[1:6]
        for line in DOC.read_text(encoding="utf-8").splitlines()
        if line.startswith("| 0x")
    ]
    assert len(rows) == 3
    for data_id, pdu, fv, tag, auth in (tuple(c.strip(" `") for c in row) for row in rows):
        can_id, pdu_b, fv_i = int(data_id, 16), bytes.fromhex(pdu), int(fv, 16)
        block = fw.authenticator_input(can_id, pdu_b, fv_i)
        assert cmac(cmac_key(key), block).hex() == tag
        mac = fw.authenticator(cmac_key(key), can_id, pdu_b, fv_i)
        assert host.SecocSigner(key).mac(can_id, pdu_b, fv_i) == mac
        request = fw.SECURED_IDS.index(can_id)
        assert hf.pack_odom_auth(3, request, fv_i & 0xFFFF, mac).hex() == auth


def test_hostile_frames_never_raise_nor_verify() -> None:
    """10^4 random ODOM_AUTH payloads (any length) and held frames: no exception, nothing OK."""
    rng = random.Random(8)
    receiver = fw.SecocReceiver(KEY, MemoryNvm())
    gate = fw.SecuredCommands(receiver)
    signer = host.SecocSigner(KEY)
    for tick in range(10_000):
        gate.hold(fw.AuthRequest(rng.randrange(3)), rng.randbytes(8), tick)
        verdict = gate.authenticate(fw.unpack_odom_auth(rng.randbytes(rng.randrange(9))))
        assert verdict is None or verdict[0] is not fw.AuthStatus.OK
        gate.expire(tick)
        signer.on_freshness(rng.randbytes(rng.randrange(10)))
    assert receiver.count_ok == 0
    assert receiver.last_fv == 1 << fw.COUNT_BITS
