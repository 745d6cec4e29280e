"""A set-pose never makes the firmware say DEGRADED with REASON NONE (issue #11).

Found in review: ``pose_set`` cleared the latched REASON (POSE_UNCERTAIN, COUNTER_RESET) and left
STATE DEGRADED for the watchdog to clear after the tick's transmissions, so the summary of a
set-pose's tick went out DEGRADED with REASON NONE, against the DBC ("NONE while OK"; a DEGRADED
always carries its REASON); set before the recovery frames were in, it stayed so for longer.
Now the set-pose releases the latch and the reason stays until STATE and REASON recover together.
Python and C alike; every summary decoded with cantools; set-poses in a summary's tick (900), in
another (905), and right after the stall (502: the recovery frames not in yet)."""

from __future__ import annotations

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.sim.contract import database
from tests import host_frames as hf
from tests.dbc_typed import decode, numbers
from tests.fault_rig import FaultRig

STALL = (300, 500)  # ticks the firmware is halted: its merged step latches POSE_UNCERTAIN
SET_POSE_AT = [502, 900, 905]  # after the stall; in a summary's tick (900) and not (905)


def _summaries(frames: list[can.Message]) -> list[tuple[str, str]]:
    db = database()
    out = []
    for msg in frames:
        if msg.arbitration_id == fr.ODOM_STATUS_ID and numbers(db, msg.arbitration_id,
                                                               msg.data)["PAGE"] == 0:
            sig = decode(db, msg.arbitration_id, msg.data)
            out.append((str(sig["STATE"]), str(sig["REASON"])))
    return out


def _run(firmware: str, set_pose_at: int) -> list[tuple[str, str]]:
    heard: list[can.Message] = []
    with FaultRig(robot="pmir", firmware=firmware, seed=1) as rig:
        rig.halted = lambda k: STALL[0] <= k < STALL[1]

        def set_pose(k: int) -> None:
            if k == set_pose_at:
                data = hf.pack_odom_set_pose(1, fr.SetPoseField.APPLY, 0, ErrorMask())
                rig.ecu.isr_can_rx(fr.ODOM_SET_POSE_ID, data)

        rig.before_board.append(set_pose)
        rig.observers.append(lambda k, frames: heard.extend(frames))
        for _ in range(set_pose_at + 60):
            rig.step()
    return _summaries(heard)


@pytest.mark.parametrize("firmware", ["python", "c"])
def test_no_degraded_summary_without_its_reason(firmware: str) -> None:
    for set_pose_at in SET_POSE_AT:
        said = _run(firmware, set_pose_at)
        assert [s for s in said if s[0] != "OK" and s[1] == "NONE"
                and s[0] != "INIT"] == [], set_pose_at
        assert ("DEGRADED", "POSE_UNCERTAIN") in said, set_pose_at  # the latch was on the bus
        assert said[-1] == ("OK", "NONE"), set_pose_at  # the set-pose ended it
