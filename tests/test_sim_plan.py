"""``sim.simplan``: the sim node's frames of a lookahead block, packed at once, are the plain
tick's, byte for byte: while the plan holds, across a miss (a MOTOR_CMD from elsewhere: the
vehicle falls back), across a motor controller restart (its counters and offset change
mid-block: a new plan from the next block on), and its batch CRC is ``seal_frame``'s."""

from __future__ import annotations

import random
from collections.abc import Callable

import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.host.io.logs import FrameCollector
from odocan.sim import motor_controller
from odocan.sim.e2efacts import SIM_TRUTH, message_e2e
from odocan.sim.errors import ErrorModel
from odocan.sim.lookahead import BLOCK_TICKS, PlannedVehicle
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from odocan.sim.simplan import seal_words

ERRORS = ErrorModel(ed=1.002, eb=1.01, slip=0.01)
Event = Callable[[LockstepRig], None]


def run(lookahead: bool, ticks: int, events: dict[int, Event]) -> tuple[list[object], int]:
    """The host's frames of a random drive (and the ticks the plan served), with ``events[k]``
    done before tick k."""
    served = [0]
    plain = motor_controller.SimNode._send_planned

    def counted(node: motor_controller.SimNode, plan: object, i: int) -> None:
        served[0] += 1
        plain(node, plan, i)  # type: ignore[arg-type]

    collector = FrameCollector()
    config = RigConfig(
        robot=load("kobuki"), scenario="random", seed=5, errors=ERRORS, lookahead=lookahead
    )
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(motor_controller.SimNode, "_send_planned", counted)
        with LockstepRig(config, [collector]) as rig:
            for k in range(ticks):
                if k in events:
                    events[k](rig)
                rig.step()
    frames = collector.arrays()
    return [frames.timestamp_s.tolist(), frames.can_id.tolist(), frames.data.tobytes()], served[0]


def test_the_plan_serves_every_tick_of_a_held_forecast_with_the_plain_frames() -> None:
    ticks = 3 * BLOCK_TICKS + 37
    planned, served = run(True, ticks, {})
    plain, none = run(False, ticks, {})
    assert planned == plain
    assert (served, none) == (ticks, 0)


def host_motor_cmd(rig: LockstepRig) -> None:
    """A MOTOR_CMD the forecast did not predict (the host's, stamped now; the COUNTER next to
    the driver's, so that the motor controller applies it)."""
    assert rig.driver is not None
    counter = (rig.driver.counter + 1) & 0xF
    rig.send(fr.MOTOR_CMD_ID, fr.pack_motor_cmd(counter, 120, -80, ErrorMask()))


def test_a_miss_mid_block_drops_the_plan_for_good_and_keeps_the_bytes() -> None:
    ticks, miss = 2 * BLOCK_TICKS + 50, BLOCK_TICKS + 123
    planned, served = run(True, ticks, {miss: host_motor_cmd})
    plain, _ = run(False, ticks, {miss: host_motor_cmd})
    assert planned == plain
    assert served == miss  # the vehicle fell back: the plain tick from the miss on


def restart(rig: LockstepRig) -> None:
    rig.motor_controller.restart()


def test_a_restart_mid_block_is_planned_again_from_the_next_block() -> None:
    ticks, at = 3 * BLOCK_TICKS, BLOCK_TICKS + 200
    planned, served = run(True, ticks, {at: restart})
    plain, _ = run(False, ticks, {at: restart})
    assert planned == plain
    assert served == ticks - (2 * BLOCK_TICKS - at)  # the rest of the restart's block is plain


def test_the_batch_crc_is_seal_frame_s() -> None:
    rng = random.Random(13)
    words = [rng.getrandbits(64) & ~0xFF for _ in range(500)]
    truth_ids = message_e2e(SIM_TRUTH).data_ids
    for data_ids in (fr.WHEEL_ENCODERS_DATA_IDS, fr.MOTOR_CMD_DATA_IDS, truth_ids):
        assert seal_words(words, data_ids) == [fr.seal_frame(w, data_ids) for w in words]
    assert seal_words([], truth_ids) == []


def test_the_vehicle_fell_back_at_the_miss() -> None:
    config = RigConfig(robot=load("kobuki"), scenario="random", seed=5, lookahead=True)
    with LockstepRig(config, []) as rig:
        rig.loop.run_to(BLOCK_TICKS + 10)
        vehicle = rig.vehicle
        assert isinstance(vehicle, PlannedVehicle)
        assert not vehicle.fell_back
        host_motor_cmd(rig)
        rig.step()
        assert vehicle.fell_back
