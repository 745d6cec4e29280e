"""The live judge across a silence of the encoder node (found trying ``odocan sim --faults
busoff=40:2`` against ``odocan firmware`` and ``odocan monitor``: POSE WRONG by 1.28 m on a
correct firmware).

While the motor controller is silent (its bus off, the sim SIGSTOPped) the robot drives on and its
counters count on; the first frame after the silence carries the distance driven meanwhile. The
firmware bounds that step by the periods its clock saw pass and integrates it (DEGRADED
ENCODER_TIMEOUT, then POSE_UNCERTAIN until a set-pose: its path is unknowable), as ``analyze`` does.
The live reference bounded it by the COUNTER advance alone (at most 16 periods): it refused the
step, took the next frames for a counter restart and dropped the distance, so the monitor said POSE
WRONG on a firmware whose pose is right to a nanometre of float64 dead reckoning written here
(``test_health_rig.reference_xy``).
"""

from __future__ import annotations

import math

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.host.io.logs import FrameCollector
from odocan.host.judge.analysis import analyze
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.sim.board import TICK_S
from tests import host_frames as hf
from tests.fault_rig import open_virtual
from tests.test_health_rig import Watch, circle_rig, reference_xy, verdicts_between

SILENT_FROM = 500  # tick (5 s)
SILENT_TICKS = 200  # 2 s: the firmware's ENCODER_TIMEOUT, and 12 whole COUNTER cycles
SET_POSE_TICK = SILENT_FROM + SILENT_TICKS + 200  # 9 s: the host accepts the on-board pose


def run_silent_encoders() -> tuple[Watch, float]:
    """pmir on a circle; the sim sends nothing from 5 s for 2 s, then 5 s more; 2 s after the
    silence a host tool accepts the on-board pose (ODOM_SET_POSE APPLY, no field staged: the
    pose stays). Returns the watch and the firmware's final position error against float64 dead
    reckoning (m)."""
    with circle_rig() as rig:
        watch = Watch(rig)
        tool = open_virtual(rig.channel)
        send = rig.sim.tick

        def tick(k: int) -> None:
            if not SILENT_FROM <= k < SILENT_FROM + SILENT_TICKS:
                send(k)

        def host(k: int) -> None:
            if k == SET_POSE_TICK:
                data = hf.pack_odom_set_pose(0, fr.SetPoseField.APPLY, 0, ErrorMask())
                tool.send(can.Message(arbitration_id=fr.ODOM_SET_POSE_ID, data=data,
                                      is_extended_id=False, timestamp=k * TICK_S))

        rig.sim.tick = tick  # type: ignore[method-assign]
        rig.before_board.append(host)
        try:
            rig.run((SILENT_FROM + SILENT_TICKS + 500) * TICK_S)
        finally:
            tool.shutdown()
        return watch, watch.pose_error_m()


def test_a_silent_encoder_node_is_never_pose_wrong_on_a_correct_firmware() -> None:
    watch, firmware_error_m = run_silent_encoders()
    assert firmware_error_m < 1e-6  # the firmware is right
    assert ("DEGRADED", "ENCODER_TIMEOUT") in watch.states()  # the silence was seen
    # the 2 s step's path is unknowable: POSE_UNCERTAIN, latched until the host sets the pose
    assert ("DEGRADED", "POSE_UNCERTAIN") in watch.states()
    assert watch.states()[-1] == ("OK", "NONE")
    after = SILENT_FROM * TICK_S
    set_pose_s = SET_POSE_TICK * TICK_S
    assert "POSE WRONG" not in {v for _, v in watch.verdicts}
    assert verdicts_between(watch, after + 0.3, set_pose_s) == {"DEGRADED"}  # never OK
    assert verdicts_between(watch, set_pose_s + 0.5, after + 7.0) == {"OK"}
    # the live reference took the step across the silence (compared before and after the
    # set-pose alike): within one LSB of the on-board pose, no counter restart
    vs_ref = watch.monitor.tracker.vs_reference
    assert vs_ref.samples > 500
    assert vs_ref.max_dpos_m <= POSITION_LSB_M
    assert vs_ref.max_dheading_rad <= HEADING_LSB_RAD
    assert watch.monitor.tracker.counter_restarts == 0  # the step was taken, not a restart


def test_a_counter_restart_inside_the_silence_is_never_called_ok() -> None:
    """As above, but the motor controller restarts (counters, COUNTER and CTRL_UPTIME from 0) as
    it speaks again. Its jump fits the time-widened bound, so the counts alone took it for motion
    (the pose ~2 m off the robot's, OK / PASS everywhere); its CTRL_UPTIME going back (6 -> 1)
    tells the firmware, which re-primes on that frame (DEGRADED COUNTER_RESET until a set-pose),
    and every judge models the same rule."""
    restart = SILENT_FROM + SILENT_TICKS
    with circle_rig() as rig:
        watch = Watch(rig)
        collector = FrameCollector()

        def record(_tick: int, frames: list[can.Message]) -> None:
            for msg in frames:
                collector.on_message_received(msg)

        rig.observers.append(record)
        send = rig.sim.tick

        def tick(k: int) -> None:
            if k == restart:
                rig.sim.motor_controller.restart()
            if not SILENT_FROM <= k < restart:
                send(k)

        rig.sim.tick = tick  # type: ignore[method-assign]
        rig.run((restart + 500) * TICK_S)
        # float64 dead reckoning re-primed at the restart: the motion of the silence dropped
        counts = watch.counts
        jump = [counts[restart][i] - counts[SILENT_FROM - 1][i] for i in (0, 1)]
        reprimed = counts[:SILENT_FROM] + [(a - jump[0], b - jump[1]) for a, b in counts[restart:]]
        x, y = reference_xy(reprimed, rig)
        odo = rig.ecu.odometry
        assert math.hypot(odo.x_q40_m / 2**40 - x, odo.y_q40_m / 2**40 - y) < 1e-6
        assert watch.pose_error_m() > 0.1  # the silence's motion: unknowable, not integrated
    assert watch.states()[-2:] == [("DEGRADED", "ENCODER_TIMEOUT"), ("DEGRADED", "COUNTER_RESET")]
    assert "OK" not in verdicts_between(watch, restart * TICK_S, (restart + 500) * TICK_S)
    assert "POSE WRONG" not in {v for _, v in watch.verdicts}
    tracker = watch.monitor.tracker
    assert tracker.counter_restarts == 1
    assert tracker.vs_reference.max_dpos_m <= POSITION_LSB_M
    assert tracker.vs_reference.max_dheading_rad <= HEADING_LSB_RAD
    result = analyze(collector.arrays(), rig.profile, "exact")
    assert result.passed, result.report["onboard_vs_reference"]
    events = [e for e in result.report["events"] if e["kind"] == "counter_restart"]
    assert [e["t_s"] for e in events] == [pytest.approx(restart * TICK_S, abs=0.002)]
    assert "CTRL_UPTIME went back" in events[0]["detail"]
