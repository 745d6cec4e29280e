"""A restart of the motor controller is never integrated as motion (issue #11, item 5).

The controller (node MOTOR_CTRL) says its age in WHEEL_ENCODERS' CTRL_UPTIME (1 + whole seconds
since its power-up, saturating at 15; 0: an old controller that does not say). When it restarts
after a silence long enough, the jump of its counters (from 0) fits the firmware's time-widened
speed bound, and no rule on the counts alone tells it from motion; CTRL_UPTIME going down does.
The firmware re-primes on that frame (DEGRADED COUNTER_RESET until a set-pose), in Python and in
C bit for bit.
"""

from __future__ import annotations

from pathlib import Path

import can

from odocan.sim.board import TICK_S
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests.dbc_typed import decode

DB = database()
STATUS = DB.get_message_by_name("ODOM_STATUS")
ENCODERS = DB.get_message_by_name("WHEEL_ENCODERS")
SILENT_FROM = 500  # tick (5 s): the controller falls silent
SILENT_TICKS = 200  # 2 s; it restarts as it speaks again
END_TICKS = SILENT_FROM + SILENT_TICKS + 300


def restart_log(path: Path, firmware: str) -> Path:
    """pmir on a circle; the motor controller silent 2 s from 5 s, then restarted (counters,
    COUNTER and CTRL_UPTIME from 0); 3 s more. The candump log of the whole run."""
    config = RigConfig(robot=load("pmir"), scenario="circle", firmware=firmware, duration_s=60.0)
    with LockstepRig(config, [can.Logger(path)]) as rig:
        send = rig.sim.tick

        def tick(k: int) -> None:
            if k == SILENT_FROM + SILENT_TICKS:
                rig.sim.motor_controller.restart()
            if not SILENT_FROM <= k < SILENT_FROM + SILENT_TICKS:
                send(k)

        rig.sim.tick = tick  # type: ignore[method-assign]
        rig.run(END_TICKS * TICK_S)
    return path


def summaries(path: Path) -> list[tuple[float, str, str]]:
    """(bus time s, STATE, REASON) of every ODOM_STATUS summary, decoded by cantools."""
    out = []
    for msg in can.LogReader(path):
        if msg.arbitration_id == STATUS.frame_id and msg.data[1] >> 4 == 0:
            s = decode(DB, STATUS.frame_id, msg.data)
            out.append((msg.timestamp, str(s["STATE"]), str(s["REASON"])))
    return out


def uptimes(path: Path) -> list[int]:
    """CTRL_UPTIME of every WHEEL_ENCODERS frame, decoded by cantools."""
    return [int(str(decode(DB, ENCODERS.frame_id, m.data)["CTRL_UPTIME"]))
            for m in can.LogReader(path) if m.arbitration_id == ENCODERS.frame_id]


def test_python_and_c_firmwares_reprime_on_a_controller_restart_bit_for_bit(
    tmp_path: Path,
) -> None:
    python = restart_log(tmp_path / "python.log", "python")
    c = restart_log(tmp_path / "c.log", "c")
    assert python.read_bytes() == c.read_bytes()
    heard = uptimes(python)
    assert heard[SILENT_FROM - 1] == 5
    assert heard[SILENT_FROM] == 1
    restart_s = (SILENT_FROM + SILENT_TICKS) * TICK_S
    after = [(state, reason) for t, state, reason in summaries(python) if t > restart_s + 0.05]
    assert after
    assert set(after) == {("DEGRADED", "COUNTER_RESET")}
