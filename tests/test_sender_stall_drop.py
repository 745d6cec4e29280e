"""A motor controller that stalls with no catch-up burst (issue #11, rule 5: a PASS must never
hide a wrong pose): it sends nothing for 0.5 to 1.9 s while the robot drives on, then resumes
with its COUNTER one on and counts that jumped. The E2E counters show no frame missing: the
firmware saw exactly the frames the log saw, and took the jump as the one step the reference
takes.

The judge's sender sequence widens that step by the bus time (``samples.sender_seq``): a gap of
50 to 190 periods, placed within ``gapbound``'s allowance (metres: a robot may spin inside a
gap), so a firmware that DROPPED the big step (accepted the frame, integrated nothing) was
placed where it stood and PASSed. Its own ODOM_STATUS pages say it accepted every frame the log
holds and none it lacks (``host.judge.gapseen``): no re-placement is due, and it FAILs by the
step it dropped, measured here by float64 dead reckoning of the robot's own counts (the rig's
``Watch``), not by the judges' reference. The correct firmware still PASSes.

The live judge (the monitor's model and the MQTT bridge, ``host.judge.livegapseen``) learns the
same from the pages, which come after the gap: it placed its reference at the next sample with
the gap's allowance, then withdraws it once they prove the firmware took the frames; before, it
said OK (no POSE WRONG latched) on the 190-tick log while ``analyze`` FAILed by 0.31 m.
"""

from __future__ import annotations

from pathlib import Path

import can
import pytest

import odocan.firmware.odometry as odometry
from odocan.host.io.logs import parse_candump_line, read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.livegapseen import end_of_watch
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.board import TICK_S
from odocan.sim.robot import load
from odocan.sim.scenarios import straight
from tests.fault_rig import FaultRig
from tests.test_health_rig import Watch
from tests.test_sender_stall_step import _streamed
from tests.test_wrap_after_gaps import ONE_CM_TOML

SILENT_FROM = 500  # tick (5 s)
BIG_COUNTS = 50  # a step of more counts than this is dropped by the wrong firmware (~0.1 s)


def _silent_no_burst(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, silent_ticks: int, *,
                     drops: bool) -> tuple[float, Path]:
    """A 1 cm robot (pmir's wheels) driving straight at 0.5 m/s; the sim sends nothing for
    ``silent_ticks`` from 5 s, then goes on (its next frame carries the whole distance, no
    catch-up frame); 3 s more. ``drops``: the
    firmware accepts the resumed frame but integrates nothing of its step. Returns the
    firmware's final position error against float64 dead reckoning (m) and the bus's log."""
    if drops:
        whole = odometry.Odometry.step_deltas

        def step_deltas(self: odometry.Odometry, d_left: int, d_right: int) -> None:
            if max(abs(d_left), abs(d_right)) <= BIG_COUNTS:
                whole(self, d_left, d_right)

        monkeypatch.setattr(odometry.Odometry, "step_deltas", step_deltas)
    heard: list[can.Message] = []
    robot = tmp_path / "pmir1cm.toml"
    robot.write_text(ONE_CM_TOML)
    with FaultRig(robot=str(robot), scenario=straight(load(robot), 6.0)) as rig:
        watch = Watch(rig)
        rig.observers.append(lambda _k, frames: heard.extend(frames))
        send, resume = rig.sim.tick, SILENT_FROM + silent_ticks

        def tick(k: int) -> None:
            if not SILENT_FROM <= k < resume:
                send(k)

        rig.sim.tick = tick  # type: ignore[method-assign]
        rig.run((resume + 300) * TICK_S)
        path = tmp_path / f"rig-{silent_ticks}-{drops}.log"
        path.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                                f"{m.data.hex().upper()}\n" for m in heard))
        return watch.pose_error_m(), path


def _analyzed(path: Path) -> tuple[bool, dict[str, float]]:
    """analyze's verdict and on-board vs reference, the whole log and streamed alike."""
    result = analyze(read_log(path), load(path.parent / "pmir1cm.toml"), "exact")
    onboard = result.report["onboard_vs_reference"]
    assert _streamed(path, path.parent, str(path.parent / "pmir1cm.toml")) == onboard
    return result.passed, onboard


def live_judges(path: Path, robot: Path, integrator: str = "exact"
                ) -> list[tuple[str, PoseTracker]]:
    """The monitor's model and the bridge fed ``path`` frame by frame, to the end (the last
    pages' proof, the samples still waiting judged with the allowance they have, as ``odocan
    monitor`` ends): their
    trackers, the monitor's health state first ("monitor <state>", "bridge")."""
    profile = load(robot)
    monitor = BusMonitor(profile)  # the integrator from ODOM_STATUS, as `odocan monitor`
    bridge = RobotTelemetry("r", Geometry.of(profile), integrator,
                            counter_bits=profile.counter_bits, publish_hz=10)
    last = 0.0
    for line in path.read_bytes().splitlines(keepends=True):
        msg = parse_candump_line(line)
        if msg is not None:
            monitor.feed(msg, now_s=msg.timestamp)
            bridge.feed(msg)
            last = msg.timestamp
    state = monitor.health(now_s=last)["state"]
    for tracker in (monitor.tracker, bridge.tracker):
        end_of_watch(tracker)
        tracker.wrongs.finish(tracker.allowance_m)
    return [(f"monitor {state}", monitor.tracker), ("bridge", bridge.tracker)]


@pytest.mark.parametrize("silent_ticks", [50, 190])
def test_a_correct_firmware_across_a_stall_without_burst_passes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, silent_ticks: int
) -> None:
    firmware_error_m, path = _silent_no_burst(tmp_path, monkeypatch, silent_ticks, drops=False)
    assert firmware_error_m < 1e-6
    passed, onboard = _analyzed(path)
    assert passed, onboard
    for name, tracker in live_judges(path, path.parent / "pmir1cm.toml"):
        assert "POSE WRONG" not in name
        assert tracker.wrongs.count == 0, (name, tracker.wrongs.summary())
        assert tracker.max_beyond_allowance_m < POSITION_LSB_M, name


@pytest.mark.parametrize("silent_ticks", [50, 190])
def test_a_firmware_that_dropped_the_step_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, silent_ticks: int
) -> None:
    """Before: PASS (the gap's allowance, metres, absorbed the step dropped)."""
    firmware_error_m, path = _silent_no_burst(tmp_path, monkeypatch, silent_ticks, drops=True)
    assert firmware_error_m > 0.1
    passed, onboard = _analyzed(path)
    assert not passed
    assert onboard["max_position_error_beyond_allowance_m"] == pytest.approx(
        firmware_error_m, rel=0.05)
    judges = live_judges(path, path.parent / "pmir1cm.toml")
    assert judges[0][0] == "monitor POSE WRONG"
    for name, tracker in judges:
        assert tracker.wrongs.count >= 1, name  # before: 0, and the monitor said OK
        assert tracker.max_beyond_allowance_m == pytest.approx(firmware_error_m, rel=0.05), name
