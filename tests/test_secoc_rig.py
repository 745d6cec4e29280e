"""SecOC attacks in the lockstep rig: the firmware provisioned with a key, everything on the bus.

The firmware runs on its board (``RigConfig(secoc_key=...)``), with the EPOCH in the board's NVM
cell; the host and the attacker only send and read frames. Each test reads the verdicts from
ODOM_ACK on the bus (the firmware's own answer), not from the firmware's memory, and checks the
pose where it matters from ODOM_POSE_X/Y.
"""

from __future__ import annotations

import random
from collections.abc import Iterator

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.firmware.secoc import FRESHNESS_TX_MASK, AuthRequest
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.secoc import SecocSigner
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests import host_frames as hf

KEY = bytes.fromhex("000102030405060708090a0b0c0d0e0f")
SECURED = (fr.NAV_GOAL_ID, fr.ODOM_SET_POSE_ID, fr.ODOM_CONFIG_ID)
REQUEST = {fr.NAV_GOAL_ID: 0, fr.ODOM_SET_POSE_ID: 1, fr.ODOM_CONFIG_ID: 2}


class Bus(can.Listener):
    """The host's view: every frame the rig's host bus hears, kept in order."""

    def __init__(self) -> None:
        self.frames: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.frames.append(msg)

    def take(self) -> list[can.Message]:
        frames, self.frames = self.frames, []
        return frames


@pytest.fixture
def rig() -> Iterator[tuple[LockstepRig, Bus]]:
    bus = Bus()
    config = RigConfig(load("pmir"), scenario=None, secoc_key=KEY)
    with LockstepRig(config, [bus]) as lockstep:
        yield lockstep, bus


def acks(frames: list[can.Message]) -> list[hf.OdomAck]:
    return [hf.unpack_odom_ack(m.data) for m in frames if m.arbitration_id == fr.ODOM_ACK_ID]


def last_freshness(frames: list[can.Message]) -> bytes | None:
    fresh = [bytes(m.data) for m in frames if m.arbitration_id == fr.ODOM_FRESHNESS_ID]
    return fresh[-1] if fresh else None


def pose_100um(frames: list[can.Message]) -> tuple[int, int]:
    """The last on-board X and Y (0.1 mm) on the bus."""
    x = [
        hf.unpack_odom_pose_x(m.data).x_100um
        for m in frames
        if m.arbitration_id == fr.ODOM_POSE_X_ID
    ]
    y = [
        hf.unpack_odom_pose_y(m.data).y_100um
        for m in frames
        if m.arbitration_id == fr.ODOM_POSE_Y_ID
    ]
    return x[-1], y[-1]


class Counters:
    """E2E counters of a sender (host or attacker: the CRC is public)."""

    def __init__(self) -> None:
        self.next: dict[int, int] = {}

    def __call__(self, can_id: int) -> int:
        value = self.next.get(can_id, 0)
        self.next[can_id] = (value + 1) & 0xF
        return value


def set_pose(counters: Counters, x_100um: int, y_100um: int) -> list[tuple[int, bytes]]:
    e = ErrorMask()
    return [
        (fr.ODOM_SET_POSE_ID, hf.pack_odom_set_pose(counters(fr.ODOM_SET_POSE_ID), f, v, e))
        for f, v in ((fr.SetPoseField.X, x_100um), (fr.SetPoseField.Y, y_100um), (15, 0))
    ]


def any_command(counters: Counters, rng: random.Random) -> tuple[int, bytes]:
    """One staged write of a random secured message (each would be ACKed if accepted)."""
    e = ErrorMask()
    can_id = rng.choice(SECURED)
    value = rng.randrange(1, 50_000)
    if can_id == fr.NAV_GOAL_ID:
        return can_id, hf.pack_nav_goal(counters(can_id), fr.NavGoalField.X, value, e)
    if can_id == fr.ODOM_SET_POSE_ID:
        return can_id, hf.pack_odom_set_pose(counters(can_id), fr.SetPoseField.Y, value, e)
    data = hf.pack_odom_config(counters(can_id), fr.ConfigParam.WHEELBASE, 400_000_000, e)
    return can_id, data


def step(
    rig: LockstepRig, bus: Bus, frames: list[tuple[int, bytes]] | None = None
) -> list[can.Message]:
    for can_id, data in frames or []:
        rig.send(can_id, data)
    rig.step()
    return bus.take()


def synced_signer(rig: LockstepRig, bus: Bus) -> SecocSigner:
    """A host with the key, synchronised by the firmware's boot ODOM_FRESHNESS."""
    signer = SecocSigner(KEY)
    seen: list[can.Message] = []
    for _ in range(3):
        seen += step(rig, bus)
    boot = last_freshness(seen)
    assert boot is not None
    assert signer.on_freshness(boot)
    return signer


def test_a_genuine_command_is_acted_on_and_an_unsigned_one_is_refused(
    rig: tuple[LockstepRig, Bus],
) -> None:
    lockstep, bus = rig
    signer = synced_signer(lockstep, bus)
    host = Counters()
    seen = step(lockstep, bus, signer.secure(set_pose(host, 12_345, -6_789)))
    seen += step(lockstep, bus) + step(lockstep, bus)
    assert [(a.result, a.reason) for a in acks(seen)] == [(0, 0)] * 3
    assert pose_100um(seen) == (12_345, -6_789)
    seen = step(lockstep, bus, set_pose(host, 1, 1))  # as a host without the key sends it
    for _ in range(4):
        seen += step(lockstep, bus)
    assert [(a.result, a.reason) for a in acks(seen)] == [(1, fr.AckReason.AUTH_MISSING)] * 3
    assert pose_100um(seen) == (12_345, -6_789)


def test_forged_commands_with_random_authenticators_are_never_accepted(
    rig: tuple[LockstepRig, Bus],
) -> None:
    """10^4 forgeries, each with the right freshness (ODOM_FRESHNESS is public) and E2E: 0 pass.

    At 32 bits one success is expected every 2^32 tries; a firmware that compared fewer bits
    (or none) would accept some of them: 10^4 x 2^-8 = 39 expected at 8 bits."""
    lockstep, bus = rig
    synced_signer(lockstep, bus)
    attacker = Counters()
    rng = random.Random(18)
    tries, per_tick = 10_000, 8
    answers: list[hf.OdomAck] = []
    seen = step(lockstep, bus)
    next_fv = lockstep.board.ecu.secoc.receiver.last_fv + 1 if lockstep.board.ecu.secoc else 0
    for _ in range(tries // per_tick):
        frames = []
        for _ in range(per_tick):
            can_id, data = any_command(attacker, rng)
            auth = hf.pack_odom_auth(
                attacker(fr.ODOM_AUTH_ID),
                REQUEST[can_id],
                next_fv & FRESHNESS_TX_MASK,
                rng.getrandbits(32),
                ErrorMask(),
            )
            frames += [(can_id, data), (fr.ODOM_AUTH_ID, auth)]
        seen = step(lockstep, bus, frames)
        answers += acks(seen)
    for _ in range(3):
        answers += acks(step(lockstep, bus))
    assert len(answers) == tries
    assert sum(a.result == fr.AckResult.ACK for a in answers) == 0
    assert {a.reason for a in answers} == {fr.AckReason.AUTH_FAILED}


def test_a_recorded_command_replayed_later_and_after_a_reboot_is_refused(
    rig: tuple[LockstepRig, Bus],
) -> None:
    lockstep, bus = rig
    signer = synced_signer(lockstep, bus)
    host = Counters()
    recorded = [signer.secure(set_pose(host, 100 * i, 0)) for i in range(1, 41)]
    for frames in recorded:
        assert [a.result for a in acks(step(lockstep, bus, frames))] == [0] * 3
    seen = step(lockstep, bus) + step(lockstep, bus)
    assert pose_100um(seen) == (4_000, 0)
    attacker = Counters()  # the replay comes with fresh E2E counters: only SecOC can stop it
    attacker.next = dict(host.next)

    def replay(frames: list[tuple[int, bytes]]) -> list[tuple[int, bytes]]:
        out = []
        for can_id, data in frames:
            if can_id == fr.ODOM_AUTH_ID:
                fields = fr.unpack_odom_auth(data)
                data = hf.pack_odom_auth(attacker(can_id), *fields[1:], ErrorMask())
            else:
                data = _recount(data, attacker(can_id), can_id)
            out.append((can_id, data))
        return out

    refused: list[int] = []
    for frames in recorded[:10]:  # replayed at once: stale freshness
        refused += [a.reason for a in acks(step(lockstep, bus, replay(frames)))]
    assert refused == [fr.AckReason.AUTH_FRESHNESS] * 30
    assert lockstep.board.nvm.epoch == 1
    lockstep.board.reboot()  # RAM lost; the NVM cell (EPOCH) survives
    seen = step(lockstep, bus) + step(lockstep, bus)
    assert lockstep.board.nvm.epoch == 2
    fresh = last_freshness(seen)
    assert fresh is not None
    assert hf.unpack_odom_freshness(fresh).cause == 0
    refused = []
    for frames in recorded:  # their 16-bit freshness now falls inside the new window
        refused += [a.reason for a in acks(step(lockstep, bus, replay(frames)))]
    assert len(refused) == 120
    assert fr.AckResult.ACK not in refused
    assert set(refused) <= {fr.AckReason.AUTH_FAILED, fr.AckReason.AUTH_FRESHNESS}
    assert fr.AckReason.AUTH_FAILED in refused  # the window let them through: the MAC did not
    assert signer.on_freshness(fresh)  # the genuine host resynchronises and is obeyed again
    seen = step(lockstep, bus, signer.secure(set_pose(attacker, 7_000, 7_000)))
    assert [a.result for a in acks(seen)] == [0] * 3


def _recount(data: bytes, counter: int, can_id: int) -> bytes:
    """The same command with another E2E COUNTER (what a replaying node can always do)."""
    frame = bytearray(data)
    hf.p02_protect(frame, counter, hf.DATA_IDS_BY_FRAME_ID[can_id])
    return bytes(frame)


def test_without_a_key_the_firmware_refuses_nothing_and_sends_no_freshness() -> None:
    bus = Bus()
    with LockstepRig(RigConfig(load("pmir"), scenario=None), [bus]) as lockstep:
        seen = step(lockstep, bus, set_pose(Counters(), 500, 500))
        seen += step(lockstep, bus) + step(lockstep, bus)
    assert [a.result for a in acks(seen)] == [0] * 3
    assert not any(m.arbitration_id == fr.ODOM_FRESHNESS_ID for m in seen)


def test_a_firmware_whose_nvm_fails_refuses_every_secured_command() -> None:
    bus = Bus()
    with LockstepRig(RigConfig(load("pmir"), scenario=None, secoc_key=KEY), [bus]) as lockstep:
        lockstep.board.nvm.fail_writes = True
        lockstep.board.reboot()
        seen = step(lockstep, bus) + step(lockstep, bus)
        fresh = last_freshness(seen)
        assert fresh is not None
        assert hf.unpack_odom_freshness(fresh).fv == 0
        signer = SecocSigner(KEY)
        assert not signer.on_freshness(fresh)  # the host refuses to sign
        signer.next_fv = 1 << 28  # a host that signs anyway
        seen = step(lockstep, bus, signer.secure(set_pose(Counters(), 500, 500)))
    answers = [a.reason for a in acks(seen)]
    assert answers == [fr.AckReason.AUTH_UNAVAILABLE] * 3
    assert REQUEST[fr.ODOM_SET_POSE_ID] == AuthRequest.ODOM_SET_POSE


def test_the_monitor_counts_and_shows_authentication_failures(
    rig: tuple[LockstepRig, Bus],
) -> None:
    lockstep, bus = rig
    monitor = BusMonitor(load("pmir"))
    heard: list[can.Message] = []
    signer = synced_signer(lockstep, bus)
    host = Counters()
    heard += step(lockstep, bus, signer.secure(set_pose(host, 1_000, 0)))  # genuine: no count
    rng = random.Random(3)
    fv = (lockstep.board.ecu.secoc.receiver.last_fv + 1) if lockstep.board.ecu.secoc else 0
    for _ in range(5):  # forged: AUTH_FAILED x5
        can_id, data = any_command(host, rng)
        auth = hf.pack_odom_auth(host(fr.ODOM_AUTH_ID), REQUEST[can_id], fv, 7, ErrorMask())
        heard += step(lockstep, bus, [(can_id, data), (fr.ODOM_AUTH_ID, auth)])
    heard += step(lockstep, bus, set_pose(host, 5, 5))  # unsigned: AUTH_MISSING x3
    for _ in range(2):  # ODOM_AUTH with no command before it
        auth = hf.pack_odom_auth(host(fr.ODOM_AUTH_ID), 2, fv, 7, ErrorMask())
        heard += step(lockstep, bus, [(fr.ODOM_AUTH_ID, auth)])
    for _ in range(5):
        heard += step(lockstep, bus)
    for msg in heard:
        monitor.feed(msg)
    assert monitor.snapshot()["auth"] == {
        "auth_failed": 5,
        "auth_freshness": 0,
        "auth_missing": 3,
        "auth_unavailable": 0,
        "auth_without_command": 2,
    }
    assert sum(e["kind"] == "auth" for e in monitor.events) == 8
