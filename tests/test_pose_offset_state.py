"""A lasting pose offset keeps the live state POSE WRONG (issue #11: the rig never shows OK
while the pose it reports is wrong; ``host.judge.livestanding``).

A lockstep pmir on the circle; from tick 300 the Python firmware's X is off by 1.2 LSB (or 3),
never corrected (its ``x_q40_m`` moved once, as a wrong step would). The pose signals round to
half an LSB, so the 1.2 LSB firmware's samples fall 0.7 to 1.7 LSB from the reference: the
monitor's state followed the latest sample, went POSE WRONG / OK every few samples, and ended
OK on a right-looking one (51 episodes latched). Now an episode of the pose's current life keeps
the state POSE WRONG until the pose is set anew: a set-pose of X, Y and HEADING to where the
robot is makes it OK again (the watch still FAILs: the episodes stay latched). The bridge's
retained ``status`` carries the episodes of the current life (``pose_wrongs.this_life``).

Wrong or right by this file's own float64 dead reckoning of the log (cantools decoding,
``tests.independent_checker``), not by the judges under test.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.board import TICK_S
from odocan.sim.robot import load
from tests import host_frames as hf
from tests.fault_rig import open_virtual
from tests.independent_checker import POSITION_LSB_M, Robot, check
from tests.test_cli_run import run_cli
from tests.test_health_rig import circle_rig
from tests.test_pose_wrongs import monitor_hears_log

PMIR = load("pmir")
OFF_AT, END = 300, 800  # ticks
Q40_PER_LSB = POSITION_LSB_M * (1 << 40)  # X's LSB (0.1 mm) in the firmware's Q40 metres


def _drive(tmp_path: Path, offset_lsb: float, set_pose_at: int | None = None) -> Path:
    """The rig's frames as a candump log: X ``offset_lsb`` off from ``OFF_AT`` on; at
    ``set_pose_at`` a host tool sets X, Y and HEADING to the firmware's pose less the offset
    (where the robot is: the offset is gone)."""
    with circle_rig() as rig:
        heard: list[can.Message] = []
        rig.observers.append(lambda _k, frames: heard.extend(frames))
        tool = open_virtual(rig.channel)

        def hook(k: int) -> None:
            odometry = rig.ecu.odometry
            if k == OFF_AT:
                odometry.x_q40_m += round(offset_lsb * Q40_PER_LSB)
            if set_pose_at is not None and k == set_pose_at:
                set_pose_right(tool, odometry, round(offset_lsb * Q40_PER_LSB), k)

        rig.before_board.append(hook)
        try:
            rig.run(END * TICK_S)
        finally:
            tool.shutdown()
    return candump_written(tmp_path / f"off_{offset_lsb}.log", heard)


def set_pose_right(tool: can.BusABC, odometry: Any, off_q40: int, k: int) -> None:
    """A tool sets the pose the firmware would have without its offset ``off_q40`` (X, Y,
    HEADING and APPLY at tick ``k``): the offset taken back."""
    x = round((odometry.x_q40_m - off_q40) / Q40_PER_LSB)
    y = round(odometry.y_q40_m / Q40_PER_LSB)
    heading = (odometry.heading_bam64 >> 48) & 0xFFFF
    fields = ((fr.SetPoseField.X, x), (fr.SetPoseField.Y, y),
              (fr.SetPoseField.HEADING, heading), (fr.SetPoseField.APPLY, 0))
    for counter, (field, value) in enumerate(fields):
        data = hf.pack_odom_set_pose(counter, field, value, ErrorMask())
        tool.send(can.Message(arbitration_id=fr.ODOM_SET_POSE_ID, data=data,
                              is_extended_id=False, timestamp=k * TICK_S))


def candump_written(path: Path, heard: list[can.Message]) -> Path:
    """``heard`` as a candump log at ``path``."""
    path.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                            f"{bytes(m.data).hex().upper()}\n" for m in heard))
    return path


def _checker_max_lsb(path: Path, until_s: float = float("inf")) -> float:
    """The largest on-board position error (LSB) by the independent dead reckoning from the
    power-up pose, of the samples before ``until_s``."""
    p = PMIR.firmware_params()
    robot = Robot(p["counts_per_rev"], p["wheel_radius_left_nm"], p["wheel_radius_right_nm"],
                  p["wheelbase_nm"], p["counter_bits"], p["max_wheel_speed_mm_s"])
    cut = path.with_suffix(".cut.log")
    cut.write_text("".join(line for line in path.read_text().splitlines(True)
                           if float(line[1:line.index(")")]) < until_s))
    verdict = check(cut, robot, "exact", lambda _t: (0.0, 0.0, 0.0))
    assert verdict.samples > 100
    return verdict.max_position_error_m / POSITION_LSB_M


def _watch(path: Path) -> tuple[BusMonitor, RobotTelemetry, list[tuple[float, str]]]:
    """The monitor and the bridge fed the log; the monitor's state after every frame."""
    monitor = BusMonitor(PMIR)
    bridge = RobotTelemetry("r", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits)
    states = []
    for line in path.read_text().splitlines():
        t_s, frame = line.split(" vcan0 ")
        can_id, data = frame.split("#")
        msg = can.Message(timestamp=float(t_s[1:-1]), arbitration_id=int(can_id, 16),
                          data=bytes.fromhex(data), is_extended_id=False)
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(msg)
        states.append((msg.timestamp, monitor.health(msg.timestamp)["state"]))
    return monitor, bridge, states


@pytest.mark.parametrize("offset_lsb", [1.2, 3.0])
def test_a_lasting_offset_keeps_the_state_pose_wrong(tmp_path: Path, offset_lsb: float) -> None:
    path = _drive(tmp_path, offset_lsb)
    assert _checker_max_lsb(path, OFF_AT * TICK_S) <= 1.0  # right before the offset
    assert _checker_max_lsb(path) > 1.0  # the premise: wrong after it, for the checker too
    monitor, bridge, states = _watch(path)
    first = next(t for t, state in states if state == "POSE WRONG")
    assert OFF_AT * TICK_S <= first < OFF_AT * TICK_S + 0.2
    assert {state for t, state in states if t >= first} == {"POSE WRONG"}  # was OK half of it
    health = monitor.health(states[-1][0])
    assert health["state"] == "POSE WRONG"  # ended OK at 1.2 LSB
    monitor.tracker.wrongs.finish(monitor.tracker.allowance_m)
    this_life = bridge.status()[1]["pose_wrongs"]["this_life"]  # absent before
    assert this_life["since_s"] is None
    assert this_life["episodes"] >= 1
    assert this_life["worst"]["beyond_mm"] > 0.1


def test_a_correct_firmware_stays_ok(tmp_path: Path) -> None:
    """The guard against a false POSE WRONG (passes before the change too)."""
    path = _drive(tmp_path, 0.0)
    assert _checker_max_lsb(path) <= 1.0
    monitor, bridge, states = _watch(path)
    assert {state for t, state in states if t > 0.2} == {"OK"}
    assert monitor.health(states[-1][0])["why"] == []
    assert "this_life" not in bridge.status()[1]["pose_wrongs"]


def test_a_set_pose_to_where_the_robot_is_ends_it(tmp_path: Path) -> None:
    set_at = 600
    path = _drive(tmp_path, 1.2, set_pose_at=set_at)
    monitor, bridge, states = _watch(path)
    first = next(t for t, state in states if state == "POSE WRONG")
    assert {state for t, state in states if first <= t < set_at * TICK_S} == {"POSE WRONG"}
    after = {state for t, state in states if t > (set_at + 20) * TICK_S}
    assert after == {"OK"}  # its pose set anew: right again, and judged so
    wrongs = monitor.health(states[-1][0])["pose_wrongs"]
    assert wrongs["episodes"] >= 1  # latched
    assert "this_life" not in wrongs  # no longer standing
    assert "this_life" not in bridge.status()[1]["pose_wrongs"]


def test_the_watch_json_says_pose_wrong_and_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    monitor_hears_log(monkeypatch, _drive(tmp_path, 1.2))
    code, out, err = run_cli(capsys, "monitor", "-i", "virtual", "--robot", "pmir",
                             "--integrator", "exact", "--duration", "600", "--json")
    model: dict[str, Any] = json.loads(out)
    assert model["health"]["state"] == "POSE WRONG", model["health"]["why"]  # was OK
    assert "the offset stays until a set-pose or a reboot" in model["health"]["why"][-1]
    assert code == 1
    assert err.startswith("monitor: FAIL: the on-board pose was wrong in ")
