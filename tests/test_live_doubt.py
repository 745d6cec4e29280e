"""The live judges' doubted periods (issue #11, item 6: one judge, not three; a FAIL must never
blame a correct firmware).

The firmware judges a step its plausibility bound refused again over the periods since the frame
before the last accepted one (``firmware.sampledoubt``: that frame may have waited out a silence
in a bus-off sender's transmit buffer, its sample a silence old), and frames taken in one tick
share the first one's doubt. The whole-log and streamed judges count it
(``step_periods.doubted_bound_periods``: frames heard within half a period of each other share
the first one's doubt); the live ones (``livepose.StepGate``: the monitor's, the bridge's) did
not: they refused the frames sampled at the recovery, took them for a counter restart the
firmware never made, and FAILed correct firmwares that ``analyze`` PASSed:

* kobuki circle 652 ``busoff=3.1:0.3,stall=5.5:0.2,delay=0.3:55``: POSE WRONG 194.47 mm
  (``analyze`` FAILs its DISTANCE, 1.99 mm, the pose within: the live DISTANCE judge too now);
* kobuki random 444 ``reboot=2:0.4,delay=0.3:55,busoff=7:0.2``: POSE WRONG 94.56 mm;
* pmir figure8 80 ``delay=0.3:55,busoff=1:1``: POSE WRONG 1123.98 mm;
* kobuki figure8 647 ``busoff=2.4:0.2,reboot=6.3:0.5,delay=0.3:55``: POSE WRONG 132.65 mm;
* pmir straight 411 ``delay=0.4:70,busoff=3:0.4``: POSE WRONG 259.95 mm.

Now within 0.054 mm of the allowance each, and +10 mm on ODOM_POSE_X after the faults still
FAILs both live judges by the position. The firmware is watched at every step
(``tests.fw_watch``), so a FAIL of an untampered drive would blame a correct one.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from odocan.host.judge.livepose import RestartLog, StepGate
from odocan.host.judge.livewindow import CYCLE_S
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import sender_seq
from odocan.host.judge.step_periods import doubted_bound_periods, pair_bound_periods
from odocan.sim.robot import load
from tests.fw_watch import Watch
from tests.judges_cli import raise_x_10_mm, watched_run
from tests.test_edge_tamper import first_pose_after_silence
from tests.test_stall_bound import _live

BEYOND_M = 5e-3  # a tamper's FAIL by the position: beyond the allowance by more than this
# name: robot, scenario, seed, duration s, faults, the tamper's start (s: after the faults and
# the live placement after the last silence)
DRIVES = {
    "kobuki652": ("kobuki", "circle", 652, 9, "busoff=3.1:0.3,stall=5.5:0.2,delay=0.3:55", 5.8),
    "kobuki444": ("kobuki", "random", 444, 11, "reboot=2:0.4,delay=0.3:55,busoff=7:0.2", 7.3),
    "pmir80": ("pmir", "figure8", 80, 14, "delay=0.3:55,busoff=1:1", 3.0),
    "kobuki647": ("kobuki", "figure8", 647, 9, "busoff=2.4:0.2,reboot=6.3:0.5,delay=0.3:55",
                  6.9),
    "pmir411": ("pmir", "straight", 411, 9, "delay=0.4:70,busoff=3:0.4", 3.6),
}
Drive = tuple[str, Path, Watch, int]


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Drive:
    name = str(request.param)
    robot, scenario, seed, duration, faults, _ = DRIVES[name]
    log = tmp_path_factory.mktemp(name) / "drive.log"
    watch, code = watched_run(log, robot, scenario, seed, duration, faults)
    return name, log, watch, code


def _live_verdicts(log: Path, robot: str) -> list[tuple[bool, float]]:
    """Per live judge (the monitor, the bridge): whether it latched a wrong pose, and its
    largest position error beyond the allowance (m)."""
    monitor, bridge, _ = _live(load(robot), "exact", log)
    return [(monitor.tracker.wrongs.count > 0, monitor.tracker.max_beyond_allowance_m),
            (bridge.tracker.wrongs.count > 0, bridge.tracker.max_beyond_allowance_m)]


def test_the_firmware_integrates_the_frames_it_took(drive: Drive) -> None:
    _, _, watch, _ = drive
    assert watch.steps > 300, watch.steps
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)


def test_the_live_judges_pass_the_correct_firmware(drive: Drive) -> None:
    """Before: POSE WRONG, 94.6 to 1124 mm beyond the allowance (module docstring)."""
    name, log, _, _ = drive
    for wrong, beyond_m in _live_verdicts(log, DRIVES[name][0]):
        assert not wrong, (name, beyond_m)
        assert beyond_m <= 1e-4, (name, beyond_m)


def test_plus_10_mm_after_the_faults_fails_live(drive: Drive, tmp_path: Path) -> None:
    name, log, _, _ = drive
    tampered = tmp_path / "t.log"
    assert raise_x_10_mm(log, tampered, DRIVES[name][5]) > 50
    for wrong, beyond_m in _live_verdicts(tampered, DRIVES[name][0]):
        assert wrong, (name, beyond_m)
        assert beyond_m > BEYOND_M, (name, beyond_m)


def _burst_after_silence(speed: int, late_counts: int) -> tuple[list[int], list[float],
                                                                 list[int]]:
    """COUNTER, bus time (s) and counts of a 100 Hz stream at ``speed`` counts per period: 11
    frames, a 0.3 s silence, two frames held in it (sampled at 0.11 and 0.12 s) let out back
    to back at 0.4 s, then the frame sampled at 0.4 s (plus ``late_counts``)."""
    counter = [*range(11), 11, 12, 40 % 16]
    t_s = [*(k * CYCLE_S for k in range(11)), 0.4, 0.4002, 0.41]
    counts = [*(k * speed for k in range(13)), 40 * speed + late_counts]
    return counter, t_s, counts


def _gate_steps(counter: list[int], t_s: list[float], counts: list[int]
                ) -> list[tuple[int, int] | None]:
    """``StepGate.step`` of each frame, both wheels alike, its periods ``sender_seq``'s."""
    gate = StepGate(Geometry.of(load("kobuki")), 24, RestartLog(lambda _seq, _uptime: None))
    seq = sender_seq(np.array(counter), np.array(t_s), CYCLE_S)
    heard = [1, *np.diff(seq).tolist()]
    return [gate.step((k, c, n, n, int(h), 0, t))
            for k, (c, t, n, h) in enumerate(zip(counter, t_s, counts, heard, strict=True))]


def test_the_gate_doubts_the_burst_from_the_frame_before_it() -> None:
    """The frame sampled at the recovery lies 28 periods from the last held one by the counts,
    12 by its COUNTER: refused over 12, taken over the 28 from the frame before the burst (31
    periods of bus time), as ``doubted_bound_periods`` counts them (before: refused)."""
    bound = StepGate(Geometry.of(load("kobuki")), 24, RestartLog(lambda _s, _u: None)).bound
    speed = min(bound) // 2
    counter, t_s, counts = _burst_after_silence(speed, 0)
    seq = sender_seq(np.array(counter), np.array(t_s), CYCLE_S)
    stamps = np.array(t_s)
    assert 28 * speed > pair_bound_periods(seq, stamps, CYCLE_S, 12, 13) * min(bound)
    assert 28 * speed <= doubted_bound_periods(seq, stamps, CYCLE_S, 12, 13) * min(bound)
    assert _gate_steps(counter, t_s, counts)[-1] == (28 * speed, 28 * speed)


def test_the_gate_refuses_a_step_beyond_the_doubted_periods() -> None:
    """31 periods of bus time widen the 12 to 28 and no further: a frame 16 periods' bound
    further on (30 periods' travel) is refused as before."""
    bound = StepGate(Geometry.of(load("kobuki")), 24, RestartLog(lambda _s, _u: None)).bound
    counter, t_s, counts = _burst_after_silence(min(bound) // 2, 16 * max(bound))
    assert _gate_steps(counter, t_s, counts)[-1] is None


# name: the silence of ODOM_POSE_X (s) and the time at or after which it ends (s)
FIRST_AFTER_BUS_OFF = {"kobuki652": (0.2, 3.1), "pmir411": (0.3, 3.0)}


PMIR_411_FIRST_AFTER = (
    "issue #11: +10 mm from the first pose after the bus-off (pmir 411: 3.403 s) PASSes both "
    "live judges (0.045 mm beyond) where analyze FAILs it (9.94 mm beyond): the live placement "
    "at the bus-off's gap takes the 10 mm (9.984 asked) within its step bound (StallPlacer: "
    "1904.9 mm at frame 183, its gaps at 179, 180, 181 and 182: 3.26, 12.46, 1885.9 and 3.26 "
    "mm). Since a withdrawal lowers the step's bound too (trial36's fix) this is no longer the "
    "cause: the live pages withdraw none of those gaps (StallPlacer._lower never called for "
    "them), and the next placements' bound cannot move it back; from 3.6 s on the tamper "
    "FAILs live. kobuki 652's (795 mm at frame 148, gapbound's) FAILs live since the merge "
    "with live24 (the live pages' proofs and DISTANCE hold; not traced further)")


@pytest.mark.parametrize("name", [
    "kobuki652", pytest.param("pmir411", marks=pytest.mark.xfail(strict=True,
                                                                 reason=PMIR_411_FIRST_AFTER))])
def test_plus_10_mm_from_the_first_pose_after_the_bus_off_fails_live(
        name: str, tmp_path: Path) -> None:
    robot, scenario, seed, duration, faults, _ = DRIVES[name]
    log, tampered = tmp_path / "drive.log", tmp_path / "t.log"
    _, code = watched_run(log, robot, scenario, seed, duration, faults)
    assert code in (0, 1)  # kobuki 652's run FAILs its DISTANCE (test_mcu_bus_combos' UNFIXED)
    at_s = first_pose_after_silence(log, *FIRST_AFTER_BUS_OFF[name])
    assert raise_x_10_mm(log, tampered, at_s - 1e-4) > 50
    for wrong, beyond_m in _live_verdicts(tampered, robot):
        assert wrong, (name, beyond_m)
        assert beyond_m > BEYOND_M, (name, beyond_m)
