"""The thirty-sixth pass's outside trial (issue #11) with fault mixes a test rig would use
(10 s drives, Python firmware, every step watched by ``tests.fw_watch``): the wrong verdicts it
found, with their figures and traced cause, each fixed.

* ``stall_delay_distance`` (fixed): ``stall=2:0.05,delay=0.1:30`` (a 50 ms halt under a 10 %
  30 ms delay) FAILed a correct firmware by ODOM_TWIST DISTANCE in ``run`` and both ``analyze``
  readings, while the live monitor said OK. Either fault alone PASSes (pmir random 5 and 6),
  and so do ``stall=2:0.1,delay=0.1:30`` and ``stall=2:0.05,delay=0.1:20`` there. Not the
  stall's merged step: after it the host took the late frame 0xE for the next lap's and
  refused the late 0xD, the firmware took 0xD and 0xE and refused 0xF and 0x0: ENC_E2E_OK net
  one short, two of the host's frames skipped (``host.judge.swappedskips``). DISTANCE raised
  or lowered 10 mm from 5 s still FAILs (``test_distance_10_mm_off_from_5_s_fails``).
* ``delay_drop_live_tamper`` (fixed): ``delay=0.2:40,drop=0.02``: ``analyze`` FAILs a pose
  10 mm off from 5 s on (9.84 mm beyond); the live monitor and the bridge's judge now do too.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from odocan.firmware import odometry as fo
from odocan.sim.robot import load
from tests.fw_watch import Watch
from tests.judges_cli import (
    both_analyses,
    live_judges,
    raise_x_10_mm,
    reported_analyses,
    watched_run,
)
from tests.log_edit import raise_raw

Spec = tuple[str, str, int, str]  # robot, scenario, seed, faults (10 s drives)
STALL_DELAY = "stall=2:0.05,delay=0.1:30"
DISTANCE_FAILS: dict[str, tuple[Spec, str]] = {  # fixed: the verdicts before, and why
    "pmir_random_5": (("pmir", "random", 5, STALL_DELAY),
                      "run, analyze whole and streamed FAILed by ODOM_TWIST DISTANCE 2.294 mm "
                      "beyond (the pose within 0.0633 mm; the live monitor OK, 0.077 mm). The "
                      "firmware sums |dS| of its steps exactly (asserted) and was 3.2..4.2 mm "
                      "below the reference after the stall: the host took the late 0xE (sent "
                      "at 2.06 s) at 2.09 s for the next lap's, a step back (-11, 7 counts) and "
                      "on (44, -29); the firmware took the late 0xD and 0xE in order and "
                      "refused 0xF and 0x0. ENC_E2E_OK one short (n = 1) allowed 0.942 mm; "
                      "the swap hides a second skip: 3.77 mm (stall_breaks empty: no 75 ms "
                      "silence, the poses 70 ms apart)"),
    "pmir_random_6": (("pmir", "random", 6, STALL_DELAY),
                      "FAILed by DISTANCE 6.015 mm beyond (the pose within 0.0636 mm; the live "
                      "monitor OK, 0.061 mm), the firmware 14.5..15.5 mm below the reference "
                      "after the 50 ms stall at 2 s, 'down' allowed 8.482 mm: the span from "
                      "frame 173 one short net, 45 frames the host refused in it"),
    "pmir_figure8_5": (("pmir", "figure8", 5, STALL_DELAY),
                       "FAILed by DISTANCE 8.411 mm beyond (figure8 seed 6 too, the same "
                       "8.411 mm); the live monitor OK, 0.065 mm"),
    "kobuki_random_6": (("kobuki", "random", 6, STALL_DELAY),
                        "FAILed by DISTANCE 7.194 mm beyond (kobuki random 5: 1.001 mm; pmir "
                        "square 5 and 6: 4.973 mm); the live monitor OK, 0.061 mm; 14.9..15.9 mm "
                        "below, 'down' 7.677 mm (skips from frame 189)"),
}
DELAY_DROP = "delay=0.2:40,drop=0.02"
# issue #11, fixed: analyze FAILs a pose raised 10 mm from 5 s (9.84 mm beyond); the monitor
# and the bridge's judge showed 0.077 (random) and 0.087 mm (figure8), OK. Their placement at
# the 3-period gap at 5 s (a frame delayed, one dropped) kept its 12.4 mm step bound after the
# pages withdrew its allowance from the budgets only, which refilled gaps had raised to 187 mm
# (liveplace.withdraw now lowers both); and the sample's own ODOM_POSE_X, 40 ms late, was read as
# its frame named again: four holds analyze does not see (liveholdevidence._named_again).
LIVE_TAMPERS: dict[str, Spec] = {
    "pmir_random_5": ("pmir", "random", 5, DELAY_DROP),
    "pmir_figure8_5": ("pmir", "figure8", 5, DELAY_DROP),
}
TAMPER_FROM_S = 5.0
DISTANCE_BYTES = (6, 2)  # ODOM_TWIST DISTANCE: bytes 6..7, u16, 1 mm
Drive = tuple[Path, Watch, int, list[tuple[float, float]]]  # log, watch, run's exit, paths


def _drive(spec: Spec, log: Path) -> Drive:
    """``watched_run`` of ``spec`` (10 s) with, per step, the firmware's path (its
    ``distance_q40_m``, m) and the float64 sum of |dS| of its steps so far."""
    robot, scenario, seed, faults = spec
    params = load(robot).firmware_params()
    m_left, m_right = (2 * math.pi * params[f"wheel_radius_{side}_nm"] * 1e-9
                       / params["counts_per_rev"] for side in ("left", "right"))
    original = fo.Odometry.step_deltas
    recorded: list[tuple[float, float]] = []

    def record_inside(odo: fo.Odometry, d_left: int, d_right: int) -> None:
        original(odo, d_left, d_right)
        path = recorded[-1][1] if recorded else 0.0
        path += abs(0.5 * (d_left * m_left + d_right * m_right))
        recorded.append((odo.distance_q40_m / 2**40, path))

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(fo.Odometry, "step_deltas", record_inside)
        watch, code = watched_run(log, robot, scenario, seed, 10, faults)
    return log, watch, code, recorded


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Drive]:
    """Each spec's drive, recorded once (keyed by table and name)."""
    made: dict[str, Drive] = {}
    for name, (spec, _) in DISTANCE_FAILS.items():
        made[f"distance/{name}"] = _drive(spec, tmp_path_factory.mktemp(name) / "d.log")
    for name, spec in LIVE_TAMPERS.items():
        made[f"tamper/{name}"] = _drive(spec, tmp_path_factory.mktemp(name) / "d.log")
    return made


@pytest.mark.parametrize("key", [f"distance/{n}" for n in DISTANCE_FAILS]
                         + [f"tamper/{n}" for n in LIVE_TAMPERS])
def test_the_firmware_integrates_and_sums_its_path_right(drives: dict[str, Drive],
                                                         key: str) -> None:
    """Every step within 1/1000 LSB of float64, and its DISTANCE the sum of |dS| of its steps
    (within 1 µm)."""
    _, watch, _, paths = drives[key]
    assert watch.steps > 400, watch.steps
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)
    assert max(abs(q40 - f64) for q40, f64 in paths) < 1e-6


@pytest.mark.parametrize("name", list(DISTANCE_FAILS))
def test_run_and_both_analyzes_pass_the_stall_under_delay(
        drives: dict[str, Drive], name: str) -> None:
    """Each was a FAIL (``DISTANCE_FAILS``' figures): the host's E2E and the firmware's
    refused different late frames, and the net ENC_E2E_OK count hid the swap."""
    log, _, code, _ = drives[f"distance/{name}"]
    assert [code, *both_analyses(log)] == [0, 0, 0]


@pytest.mark.parametrize("name", LIVE_TAMPERS)
def test_the_live_judges_pass_the_drive(drives: dict[str, Drive], name: str,
                                        tmp_path: Path) -> None:
    """The untampered drive: run and both analyzes PASS it, and the live judges too (within
    their allowance, no wrong episode), placing the reference after no more stalls than
    ``analyze`` does (none was injected: the delays are no hold)."""
    log, _, code, _ = drives[f"tamper/{name}"]
    judged = reported_analyses(log, tmp_path)
    assert [code, *(c for _, c, _ in judged)] == [0, 0, 0]
    stalls = max(r["reference_breaks"]["stall_placements"] for _, _, r in judged)
    for judge in live_judges(LIVE_TAMPERS[name][0], log):
        assert judge.tracker.wrongs.count == 0, judge.tracker.wrongs.summary()
        assert judge.tracker.max_beyond_allowance_m < 1e-4
        assert judge.tracker.placer.placements.stalls <= stalls


@pytest.mark.parametrize("mm", [10, -10])
@pytest.mark.parametrize("name", ["pmir_random_5", "kobuki_random_6"])
def test_distance_10_mm_off_from_5_s_fails(drives: dict[str, Drive], name: str, mm: int,
                                           tmp_path: Path) -> None:
    """The swapped frames' allowance hides no wrong DISTANCE: 10 mm off from 5 s on FAILs
    whole and streamed, by more than 9 mm."""
    log, _, _, _ = drives[f"distance/{name}"]
    tampered = tmp_path / "tampered.log"
    assert raise_raw(log, tampered, "ODOM_TWIST", DISTANCE_BYTES, mm, TAMPER_FROM_S) > 100
    for stream, code, report in reported_analyses(tampered, tmp_path):
        excess_m = report["onboard_distance_vs_reference"]["max_excess_m"]
        assert (code, excess_m > 9e-3) == (1, True), (stream, excess_m)


@pytest.mark.parametrize("name", LIVE_TAMPERS)
def test_the_live_judges_fail_a_pose_10_mm_off(drives: dict[str, Drive], name: str,
                                               tmp_path: Path) -> None:
    log, _, code, _ = drives[f"tamper/{name}"]
    assert code == 0
    tampered = tmp_path / "tampered.log"
    assert raise_x_10_mm(log, tampered, TAMPER_FROM_S) > 100
    assert both_analyses(tampered) == [1, 1]  # analyze FAILs it, as the live judges must
    monitor, bridge = live_judges(LIVE_TAMPERS[name][0], tampered)
    beyond_m = (monitor.tracker.max_beyond_allowance_m, bridge.tracker.max_beyond_allowance_m)
    assert min(beyond_m) > 5e-3, beyond_m
