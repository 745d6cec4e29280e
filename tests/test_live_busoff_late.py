"""A bus-off under a 300 ms delay: the live judges PASS the correct firmware that ``run`` and
``analyze`` PASS, and still FAIL +10 mm on its pose (issue #11: a FAIL must never blame a
correct firmware, a PASS never hide a wrong pose).

kobuki, 9 s, ``delay=0.3:55,busoff=5:0.2``: the motor controller's transmit buffer holds the
frames sampled in the bus-off (4.99..5.20 s) and lets them out in one burst at the recovery
(5.2028 s, two frames in the same microsecond), while 55 % of all frames arrive 300 ms late
among the frames sampled after it. The live judges' step gate (``livepose.StepGate``, the
monitor's and the bridge's) counted the step into the frames after the burst over the periods
by COUNTER alone, refused them, took them for a counter restart the firmware never made, and
latched POSE WRONG and a wrong DISTANCE where ``run`` and both analyses PASS (measured on the
judges before the doubted-period rule of ``livepose.StepGate._doubted``, main 12eda772):

* random 446: POSE WRONG 295.06 mm beyond the allowance from 5.381 s, DISTANCE 3.922 mm;
* circle 447: POSE WRONG 255.08 mm from 5.461 s, DISTANCE 164.0 mm.

(figure8 445..449, circle 445..449 and random 447, 449 FAILed alike, 112 to 387 mm; square and
straight did not.) The gate now judges a refused step again over the periods since the frame
before the burst, as the firmware's ``sampledoubt`` and the whole-log judge's
``step_periods.doubted_bound_periods`` do: within 0.08 mm of the allowance each. +10 mm on
ODOM_POSE_X from the first pose after the bus-off, from 5.5 s and from 7 s FAILs both live
judges and both analyses by the position. The firmware is watched at every step
(``tests.fw_watch``), so a FAIL of an untampered drive would blame a correct one.

Left (a strict xfail): random 448's tamper from the first pose after the bus-off PASSes live
where both analyses FAIL it (``HOLD_AT_BUS_OFF``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.judge.monitor import BusMonitor
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.robot import load
from tests.fw_watch import Watch
from tests.judges_cli import POSE_X, TEN_MM_LSB, both_analyses, fails_by_position, watched_run
from tests.log_edit import raise_raw
from tests.test_edge_tamper import first_pose_after_silence
from tests.test_stall_bound import _live

FAULTS = "delay=0.3:55,busoff=5:0.2"
DURATION_S = 9
BUS_OFF = (0.15, 5.0)  # ODOM_POSE_X silent this long (s), ending at or after this time (s)
BEYOND_M = 5e-3  # a tamper's FAIL by the position: beyond the allowance by more than this
DRIVES = {"random446": ("kobuki", "random", 446), "circle447": ("kobuki", "circle", 447)}
TAMPERS = ("first after the bus-off", 5.5, 7.0)  # +10 mm on ODOM_POSE_X from then on
Drive = tuple[str, Path, Watch, int]


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Drive:
    name = str(request.param)
    robot, scenario, seed = DRIVES[name]
    log = tmp_path_factory.mktemp(name) / "drive.log"
    watch, code = watched_run(log, robot, scenario, seed, DURATION_S, FAULTS)
    return name, log, watch, code


def _live_verdicts(log: Path, robot: str) -> list[tuple[bool, float, list[str]]]:
    """Per live judge (the monitor, the bridge): whether it latched a wrong pose, its largest
    position error beyond the allowance (m) and its DISTANCE verdict (``[]``: right)."""
    monitor, bridge, _ = _live(load(robot), "exact", log)
    judges: tuple[BusMonitor | RobotTelemetry, ...] = (monitor, bridge)
    return [(j.tracker.wrongs.count > 0, j.tracker.max_beyond_allowance_m, j.distance.verdict())
            for j in judges]


def test_the_firmware_is_correct_and_run_passes_it(drive: Drive) -> None:
    name, _, watch, code = drive
    assert code == 0, name
    assert watch.steps > 300, (name, watch.steps)
    assert watch.within_a_thousandth_lsb(), (name, watch.worst_m, watch.worst_rad)


def test_both_analyses_pass_it(drive: Drive) -> None:
    name, log, _, _ = drive
    assert both_analyses(log) == [0, 0], name


def test_the_live_judges_pass_it(drive: Drive) -> None:
    """Before: POSE WRONG 255 and 295 mm beyond, DISTANCE 164 and 3.9 mm (module docstring)."""
    name, log, _, _ = drive
    for wrong, beyond_m, distance in _live_verdicts(log, DRIVES[name][0]):
        assert not wrong, (name, beyond_m)
        assert beyond_m <= 1e-4, (name, beyond_m)
        assert distance == [], (name, distance)


@pytest.mark.parametrize("from_s", TAMPERS, ids=str)
def test_plus_10_mm_fails_live_and_in_analyze(drive: Drive, from_s: float | str,
                                              tmp_path: Path) -> None:
    name, log, _, _ = drive
    at_s = first_pose_after_silence(log, *BUS_OFF) - 1e-4 if isinstance(from_s, str) else from_s
    tampered = tmp_path / "t.log"
    assert raise_raw(log, tampered, "ODOM_POSE_X", POSE_X, TEN_MM_LSB, at_s) > 50
    for wrong, beyond_m, _ in _live_verdicts(tampered, DRIVES[name][0]):
        assert wrong, (name, from_s, beyond_m)
        assert beyond_m > BEYOND_M, (name, from_s, beyond_m)
    assert fails_by_position(tampered, tmp_path, BEYOND_M) == [], (name, from_s)


HOLD_AT_BUS_OFF = (
    "issue #11: kobuki random 448, +10 mm on ODOM_POSE_X from the first pose after the bus-off "
    "(5.221 s) PASSes both live judges (0.057 mm beyond) where both analyses FAIL it (6.12 mm "
    "beyond; seed 448's figure8, circle, square, straight alike, and 445's random, square, "
    "straight): the live hold rule (livestall: livewindow.held_on_time 321 -> 342, samples "
    "at 4.816 and 5.321 s) asks no evidence, so it owes a stall placement over the bus-off "
    "whose span holds a gap of the sender's sequence (55 periods over 22 frames): "
    "breaks.overlap_allowance_m gives it 482.5 mm of step bound (503 mm in all). analyze "
    "asks stalls.hold_evidence (the frame named again, or the poses quiet over all but "
    "SILENCE_CYCLES of the span, refused poses whose CRC holds counted as sent), finds none, "
    "places no stall and bounds the gap's placement by 4.04 mm (without hold_evidence it too "
    "PASSes, 0.097 mm). A live hold evidence alone (tried: the poses quiet, or frame 321 "
    "named again) leaves no hold there but still PASSes (0.057 mm): the gaps the live "
    "numbering makes in the burst (frame 340 15 periods after 339, 341 8 after it) bound "
    "the placement's step by 20.0 mm. From 5.5 s on the tamper FAILs live")


TAMPERED_AT_BUS_OFF = ("kobuki", "random", 448)


@pytest.fixture(scope="module")
def tampered_at_bus_off(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """random 448 recorded under the tests' watch, +10 mm from its first pose after the
    bus-off on."""
    work = tmp_path_factory.mktemp("random448")
    log, tampered = work / "drive.log", work / "t.log"
    watch, code = watched_run(log, *TAMPERED_AT_BUS_OFF, DURATION_S, FAULTS)
    assert code == 0
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)
    at_s = first_pose_after_silence(log, *BUS_OFF)
    assert raise_raw(log, tampered, "ODOM_POSE_X", POSE_X, TEN_MM_LSB, at_s - 1e-4) > 50
    return tampered


def test_plus_10_mm_from_the_first_pose_after_the_bus_off_fails_analyze(
        tampered_at_bus_off: Path, tmp_path: Path) -> None:
    assert fails_by_position(tampered_at_bus_off, tmp_path, BEYOND_M) == []


@pytest.mark.xfail(strict=True, reason=HOLD_AT_BUS_OFF)
def test_plus_10_mm_from_the_first_pose_after_the_bus_off_fails_live(
        tampered_at_bus_off: Path) -> None:
    for wrong, beyond_m, _ in _live_verdicts(tampered_at_bus_off, TAMPERED_AT_BUS_OFF[0]):
        assert wrong, beyond_m
        assert beyond_m > BEYOND_M, beyond_m
