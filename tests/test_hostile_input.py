"""Hostile input into the firmware's receive path: fuzzed frames, corruption, a babbling node.

The firmware never raises and never grows: its mailbox is a fixed ring whose overflows are counted
(exactly: the tests know how many frames each tick got). Random frames are any 11- or 29-bit ID,
DLC 0-8, random bytes; a quarter of those the ECU's path sees are sealed with a valid Profile 2
CRC and counter for a message it listens to, so they reach the decoders, the staged writes and
APPLY with arbitrary values. The host decoder's fuzzing is for later (issue #6).
"""

from __future__ import annotations

import random

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorFlag, State
from odocan.firmware.hal import MAILBOX_SLOTS
from odocan.sim.board import FirmwareBoard
from odocan.sim.clock import LockstepClock
from odocan.sim.faults import FaultInjectingBus, FaultSpec
from odocan.sim.scenarios import RandomScenario
from tests.fault_rig import (
    FaultRig,
    PoseAudit,
    burst_sizes,
    fuzz_ecu,
    open_virtual,
    random_message,
    unique_channel,
)
from tests.odo_helpers import params

N_FRAMES = 100_000


def test_fuzzed_frames_into_the_isr_and_tick_never_raise_and_never_grow() -> None:
    fuzz = fuzz_ecu(N_FRAMES, seed=6)
    ecu, grown = fuzz.ecu, fuzz.grown_bytes
    rejected = ecu.frames_rejected
    print(
        f"\n{N_FRAMES} fuzzed frames into OdomEcu: {ecu.mailbox.overflows} mailbox overflows, "
        f"{ecu.frames_filtered} filtered, {rejected} rejected, {fuzz.hal.sent} frames sent, state "
        f"{State(ecu.state).name}, memory {grown:+d} B over the last 90%"
    )
    assert ecu.mailbox.overflows == fuzz.expected_overflows > 0
    assert ecu.errors.has(ErrorFlag.MAILBOX_OVERFLOW)
    assert ecu.frames_filtered > 0
    assert rejected > 0
    assert grown < 64 * 1024


def test_fuzzed_messages_through_a_bus_into_the_board_never_raise() -> None:
    rng = random.Random(7)
    channel = unique_channel()
    sender = open_virtual(channel)
    board = FirmwareBoard(open_virtual(channel), params("rk2"), LockstepClock())
    filtered = expected_overflows = 0
    t = 0.0
    try:
        for n in burst_sizes(rng, N_FRAMES):
            passing = 0
            for _ in range(n):
                msg = random_message(rng, t)
                filtered += msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id
                passing += not (msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id)
                sender.send(msg)
            expected_overflows += max(0, passing - MAILBOX_SLOTS)
            board.run_tick()
            t += 0.01
    finally:
        sender.shutdown()
        board.bus.shutdown()
    ecu = board.ecu
    print(
        f"\n{N_FRAMES} fuzzed messages through a virtual bus: {board.frames_dropped_by_filter} "
        f"dropped by the acceptance filter, {ecu.mailbox.overflows} mailbox overflows, "
        f"{ecu.frames_rejected} rejected by E2E or length"
    )
    assert board.frames_dropped_by_filter == filtered > 0
    assert ecu.mailbox.overflows == expected_overflows > 0


def test_flipped_frames_and_a_babbling_node_leave_the_pose_on_the_reference() -> None:
    spec = FaultSpec.parse("flip=0.05,babble=200,seed=13")
    with FaultRig(sim_faults=spec, scenario=RandomScenario(13, duration_s=60.0), seed=13) as rig:
        audit = PoseAudit(rig.params, rig.integrator)
        rig.observers.append(audit)
        rig.run(60.0)
        bus = rig.sim_bus
        assert isinstance(bus, FaultInjectingBus)
        ecu = rig.ecu
        flips = bus.injected_by_id["flip", fr.WHEEL_ENCODERS_ID]
        ex, ey, eh, n = audit.max_errors_lsb()
        print(
            f"\n1 min, 5% flips ({bus.injected['flip']}, {flips} on WHEEL_ENCODERS) and "
            f"{bus.injected['babble']} babbled frames: firmware crc errors "
            f"{ecu.rx_encoders.count_error}, filtered {ecu.frames_filtered}, rejected "
            f"{ecu.frames_rejected}; pose vs float64 over {n} pose frames: X {ex:.3f}, "
            f"Y {ey:.3f}, HEADING {eh:.3f} LSB"
        )
        assert flips > 200
        assert bus.injected["babble"] > 10_000
        assert ecu.rx_encoders.count_error >= flips
        assert audit.rx.count_error == ecu.rx_encoders.count_error  # the audit saw the same
        assert max(ex, ey, eh) < 1.0
        assert ecu.state is State.OK
        assert ecu.mailbox.overflows == 0
