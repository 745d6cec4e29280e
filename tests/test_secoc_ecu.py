"""SecOC in front of today's ECU: only verified commands reach it (verify before acting).

Until the lead merges the draft into ``firmware/ecu.py``, the SecOC layer sits where AUTOSAR puts
it, between the CAN driver and the application: secured frames are held by
``firmware.secoc.SecuredCommands`` and handed to the unchanged ``OdomEcu`` only when their
ODOM_AUTH verifies. The verdicts a merged ECU would send as ODOM_ACK NACK reasons are recorded.
"""

from __future__ import annotations

import random

from odocan.firmware import frames as fr
from odocan.firmware import secoc as fw
from odocan.firmware.e2e import E2EReceiver, E2EStatus
from odocan.firmware.ecu import OdomEcu
from odocan.firmware.errors import ErrorMask
from odocan.host.protocol.secoc import SecocSigner
from tests import host_frames as hf
from tests.odo_helpers import params
from tests.test_ecu import RecordingHal
from tests.test_secoc import KEY, MemoryNvm

Q40_PER_100UM = (1 << 40) // 10_000  # exact enough for whole millimetres below


class SecuredFront:
    """The SecOC layer between the receive ISR and the ECU (a test stand-in for the merge)."""

    def __init__(self, ecu: OdomEcu, receiver: fw.SecocReceiver) -> None:
        self.ecu = ecu
        self.gate = fw.SecuredCommands(receiver)
        self.rx_auth = E2EReceiver(fw.ODOM_AUTH_DATA_IDS, max_delta_counter_init=15)
        self.verdicts: list[fw.AuthStatus] = []

    def receive(self, can_id: int, data: bytes) -> None:
        tick = self.ecu.ticks
        if can_id in fw.SECURED_IDS:
            request = fw.AuthRequest(fw.SECURED_IDS.index(can_id))
            if self.gate.hold(request, data, tick) is not None:
                self.verdicts.append(fw.AuthStatus.MISSING)
        elif can_id == fw.ODOM_AUTH_ID:
            if self.rx_auth.check(data) not in (E2EStatus.OK, E2EStatus.OKSOMELOST):
                return
            result = self.gate.authenticate(fw.unpack_odom_auth(data))
            if result is not None:
                status, held = result
                self.verdicts.append(status)
                if status is fw.AuthStatus.OK:
                    self.ecu.isr_can_rx(held.can_id, held.pdu)
        else:
            self.ecu.isr_can_rx(can_id, data)

    def tick(self) -> None:
        while self.gate.expire(self.ecu.ticks) is not None:
            self.verdicts.append(fw.AuthStatus.MISSING)
        self.ecu.tick()


def set_pose_frames(x_100um: int, y_100um: int, counter0: int) -> list[tuple[int, bytes]]:
    errors = ErrorMask()
    fields = [
        (fr.SetPoseField.X, x_100um),
        (fr.SetPoseField.Y, y_100um),
        (fr.SetPoseField.APPLY, 0),
    ]
    return [
        (fr.ODOM_SET_POSE_ID, hf.pack_odom_set_pose(counter0 + i, field, value, errors))
        for i, (field, value) in enumerate(fields)
    ]


def make() -> tuple[SecuredFront, SecocSigner, MemoryNvm]:
    nvm = MemoryNvm()
    receiver = fw.SecocReceiver(KEY, nvm)
    front = SecuredFront(OdomEcu(RecordingHal(), params("exact")), receiver)
    signer = SecocSigner(KEY)
    assert signer.on_freshness(receiver.freshness_frame(0, fw.FreshnessCause.BOOT))
    return front, signer, nvm


def send(front: SecuredFront, frames: list[tuple[int, bytes]]) -> None:
    for can_id, data in frames:
        front.receive(can_id, data)
    front.tick()


def pose_mm(front: SecuredFront) -> tuple[int, int]:
    odo = front.ecu.odometry
    return odo.x_q40_m * 1000 >> 40, odo.y_q40_m * 1000 >> 40


def test_a_genuine_command_moves_the_pose_a_forged_one_does_not() -> None:
    front, signer, _ = make()
    send(front, signer.secure(set_pose_frames(12_340, -5_000, 0)))
    assert pose_mm(front) == (1234, -500)
    assert front.verdicts == [fw.AuthStatus.OK] * 3
    rng = random.Random(7)
    for attempt in range(50):  # a node without the key: right freshness, random authenticators
        forged = []
        for i, (can_id, data) in enumerate(set_pose_frames(99_990, 99_990, 3 + 3 * attempt)):
            freshness = (front.gate.receiver.last_fv + 1) & fw.FRESHNESS_TX_MASK
            auth = hf.pack_odom_auth(3 * attempt + i, 1, freshness, rng.getrandbits(32))
            forged += [(can_id, data), (fw.ODOM_AUTH_ID, auth)]
        send(front, forged)
    assert pose_mm(front) == (1234, -500)
    assert front.verdicts[3:] == [fw.AuthStatus.FAILED] * 150


def test_a_command_without_its_authenticator_never_acts() -> None:
    front, _, _ = make()
    send(front, set_pose_frames(10_000, 10_000, 0))  # unsigned, as today's host sends it
    for _ in range(3):
        front.tick()
    assert pose_mm(front) == (0, 0)
    assert front.verdicts == [fw.AuthStatus.MISSING] * 3


def test_a_recorded_command_replayed_later_or_after_a_reboot_is_refused() -> None:
    front, signer, nvm = make()
    recorded = signer.secure(set_pose_frames(20_000, 20_000, 0))
    send(front, recorded)
    send(front, signer.secure(set_pose_frames(30_000, 0, 3)))
    assert pose_mm(front) == (3000, 0)
    send(front, recorded)
    assert pose_mm(front) == (3000, 0)
    assert front.verdicts[6:] == [fw.AuthStatus.FRESHNESS] * 3
    front.gate.receiver.boot()  # a reboot of the SecOC state: EPOCH 2 from the NVM cell
    assert nvm.epoch == 2
    send(front, recorded)
    assert pose_mm(front) == (3000, 0)
    assert fw.AuthStatus.OK not in front.verdicts[9:]
