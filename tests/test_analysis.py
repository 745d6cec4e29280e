"""The analysis of lockstep runs: on-board vs reference within one LSB, vs truth, exact alignment.

Each test can fail: a pose moved by a few LSB fails the check; a DBC that does not match errors.
"""

from __future__ import annotations

import json
import math
from functools import cache
from pathlib import Path

import cantools
import numpy as np
import pytest
from cantools.database.can import Database

from odocan.host.io.logs import FrameArrays, FrameCollector, read_log
from odocan.host.judge.analysis import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    AnalysisError,
    Tolerance,
    analyze,
)
from odocan.host.judge.compare import _outside_band
from odocan.host.judge.reference import Geometry, integrate
from odocan.host.judge.samples import _first_per_encoder
from odocan.sim.contract import DBC_PATH, database
from odocan.sim.errors import ErrorModel
from odocan.sim.exceptions import OdocanError
from odocan.sim.rig import INTEGRATORS, LockstepRig, RigConfig
from odocan.sim.robot import load
from tests.dbc_typed import dbc_attribute
from tests.host_frames import p02_protect
from tests.synth_log import Synth, synthesize, wandering_drive

PMIR = load("pmir")
KOBUKI = load("kobuki")
SECONDS = 20.0
ERRORS = ErrorModel(ed=1.01, eb=1.02)
NO_ERRORS = ErrorModel()
REPORT_KEYS = {
    "robot", "integrator", "scenario", "seed", "sim_seconds", "wall_seconds", "realtime_factor",
    "frames", "onboard_vs_reference", "onboard_vs_truth", "final_onboard_pose", "e2e", "passed",
    "tolerance",
}


@cache
def run(integrator: str, errors: ErrorModel = NO_ERRORS, robot: str = "pmir") -> FrameArrays:
    """Every frame of a 20 s ``random`` run."""
    collector = FrameCollector()
    config = RigConfig(load(robot), integrator, "random", 5, errors)
    with LockstepRig(config, [collector]) as rig:
        rig.run(SECONDS)
    return collector.arrays()


def by_id(frames: FrameArrays, can_id: int) -> np.ndarray:
    return np.flatnonzero(frames.can_id == can_id)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_onboard_matches_reference_within_one_lsb(integrator: str) -> None:
    analysis = analyze(run(integrator), PMIR, scenario="random", seed=5, wall_seconds=0.5)
    report = analysis.report
    assert set(report) >= REPORT_KEYS
    json.dumps(report)
    assert analysis.passed
    assert report["passed"]
    assert report["integrator"] == integrator  # read from ODOM_STATUS
    ref = report["onboard_vs_reference"]
    assert ref["max_position_error_m"] <= POSITION_LSB_M
    assert ref["max_heading_error_rad"] <= HEADING_LSB_RAD
    assert report["samples"]["onboard"] == round(SECONDS / 0.02)  # every pose aligned
    assert report["samples"]["unmatched_poses"] == 0
    assert report["e2e"]["WHEEL_ENCODERS"]["ok"] == round(SECONDS / 0.01)
    assert report["realtime_factor"] == pytest.approx(report["sim_seconds"] / 0.5)
    n = report["samples"]["onboard"]
    for key in ("onboard_x_m", "reference_x_m", "distance_m", "position_error_m"):
        assert len(analysis.series[key]) == n
    assert report["onboard_vs_truth"]["distance_travelled_m"] > 1.0


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_truth_error_is_small_and_grows_with_systematic_errors(integrator: str) -> None:
    clean = analyze(run(integrator), PMIR).report["onboard_vs_truth"]
    skewed = analyze(run(integrator, ERRORS), PMIR).report["onboard_vs_truth"]
    assert 0 < clean["max_position_error_m"] < 0.01
    assert 0 < clean["max_heading_error_rad"] < 0.01
    assert skewed["max_position_error_m"] > 5 * clean["max_position_error_m"]
    assert skewed["max_heading_error_rad"] > 5 * clean["max_heading_error_rad"]


def test_truth_sample_count() -> None:
    report = analyze(run("exact"), PMIR).report
    # SIM_TRUTH every 100 ms; the on-board pose is carried to it from the next on-board sample
    assert report["samples"]["truth"] == round(SECONDS / 0.1)
    assert report["samples"]["truth_compared"] >= report["samples"]["truth"] - 1


@pytest.mark.parametrize(
    ("integrator", "robot"), [(i, r) for i in INTEGRATORS for r in ("pmir", "kobuki")]
)
def test_dropping_every_7th_encoder_frame_still_aligns(integrator: str, robot: str) -> None:
    frames = run(integrator, robot=robot)
    keep = np.ones(len(frames), dtype=bool)
    keep[by_id(frames, 0x100)[6::7]] = False
    analysis = analyze(frames.select(keep), load(robot))
    report = analysis.report
    assert analysis.passed, report["onboard_vs_reference"]
    assert report["e2e"]["WHEEL_ENCODERS"]["lost"] == len(by_id(frames, 0x100)[6::7])
    # the poses naming a dropped frame are left out, never paired with an older frame
    assert report["samples"]["unmatched_poses"] > 0
    assert report["samples"]["onboard"] + report["samples"]["unmatched_poses"] // 2 == round(
        SECONDS / 0.02
    )


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_log_starting_mid_drive_passes(integrator: str) -> None:
    frames = run(integrator)
    late = frames.select(np.flatnonzero(frames.timestamp_s >= 7.337))
    analysis = analyze(late, PMIR)
    assert analysis.passed, analysis.report["onboard_vs_reference"]
    assert abs(analysis.series["onboard_x_m"][0]) + abs(analysis.series["onboard_y_m"][0]) > 0.1


def reprotect(frames: FrameArrays, position: int, data_ids: tuple[int, ...]) -> None:
    buf = bytearray(frames.data[position].tobytes())
    p02_protect(buf, buf[1] & 0xF, data_ids)
    frames.data[position] = np.frombuffer(bytes(buf), dtype=np.uint8)


def test_a_wrong_onboard_pose_fails() -> None:
    frames = run("exact")
    frames = frames.select(np.arange(len(frames)))  # a copy
    poses = by_id(frames, 0x200)
    target = int(poses[len(poses) // 2])
    x = int.from_bytes(frames.data[target, 2:6].tobytes(), "little", signed=True) + 3
    frames.data[target, 2:6] = np.frombuffer(x.to_bytes(4, "little", signed=True), np.uint8)
    ids = dbc_attribute(database().get_message_by_name("ODOM_POSE_X"), "E2EDataIDs")
    reprotect(frames, target, tuple(int(v) for v in ids.split(",")))
    analysis = analyze(frames, PMIR)
    assert not analysis.passed
    assert analysis.report["onboard_vs_reference"]["max_position_error_m"] > 2 * POSITION_LSB_M
    assert analyze(frames, PMIR, tolerance=Tolerance(position_m=1e-3)).passed


def test_wrong_integrator_fails() -> None:
    analysis = analyze(run("euler"), PMIR, "exact")
    assert analysis.report["integrator_source"] == "argument"
    assert not analysis.passed


def dbc_variant(tmp_path: Path, old: str, new: str) -> Database:
    text = DBC_PATH.read_text().replace(old, new)
    db = cantools.database.load_string(text, database_format="dbc")
    assert isinstance(db, Database)
    return db


def test_dbc_mismatch_errors(tmp_path: Path) -> None:
    frames = run("exact")
    moved = dbc_variant(tmp_path, "BO_ 256 WHEEL_ENCODERS", "BO_ 1000 WHEEL_ENCODERS")
    with pytest.raises(AnalysisError, match=r"no WHEEL_ENCODERS frame .* does not match"):
        analyze(frames, PMIR, db=moved)
    other_ids = dbc_variant(
        tmp_path, '"16,17,18,19,20,21,22,23,24,25,26,27,28,29,30,31"',
        '"32,33,34,35,36,37,38,39,40,41,42,43,44,45,46,47"',
    )
    with pytest.raises(AnalysisError, match="E2E check: the DBC does not match"):
        analyze(frames, PMIR, db=other_ids)
    renamed = dbc_variant(tmp_path, "ODOM_POSE_Y", "ODOM_POSE_Z")
    with pytest.raises(OdocanError, match="ODOM_POSE_Y"):
        analyze(frames, PMIR, db=renamed)


def test_integrator_must_be_known_or_logged() -> None:
    frames = run("rk2")
    no_status = frames.select(np.flatnonzero(frames.can_id != 0x380))
    with pytest.raises(AnalysisError, match="integrator"):
        analyze(no_status, PMIR)
    assert analyze(no_status, PMIR, "rk2").passed
    assert math.isfinite(analyze(no_status, PMIR, "rk2").report["final_onboard_pose"]["x_m"])


# --- the judge's own error on long drives (logs written directly, tests/synth_log.py) ----------

LONG_STEPS = 56_100  # 2 m per 10 ms step: 112 km, over 100 km after the mid-drive cut
MID_DRIVE_CUT = 6_000  # an even encoder frame: the log's first on-board sample names it


@cache
def long_drive(robot: str, integrator: str) -> tuple[Synth, np.ndarray, np.ndarray]:
    profile = load(robot)
    d_left, d_right = wandering_drive(profile, LONG_STEPS, 2.0, seed=11)
    return synthesize(profile, integrator, d_left, d_right), d_left, d_right


@pytest.mark.parametrize(("robot", "integrator"), [("kobuki", "exact"), ("pmir", "rk2")])
@pytest.mark.parametrize("cut", [0, MID_DRIVE_CUT])
def test_judge_own_error_after_100_km_is_below_a_twentieth_lsb(
    tmp_path: Path, robot: str, integrator: str, cut: int
) -> None:
    """The reference the judge builds vs the same float64 odometry started at the firmware's true
    internal pose (Q40, BAM64) of the log's first sample: only the start can differ."""
    synth, d_left, d_right = long_drive(robot, integrator)
    # 2 m per 10 ms: faster than any ECU build allows, so without the plausibility rule
    analysis = analyze(read_log(synth.write(tmp_path / "long.log", cut)), load(robot),
                       max_wheel_speed_mm_s=None)
    x0, y0, h0 = synth.state[cut].pose
    exact = integrate(d_left[cut:], d_right[cut:], Geometry.of(load(robot)), integrator,
                      x0_m=x0, y0_m=y0, heading0_rad=h0)
    exact_x = np.concatenate(([x0], exact.x_m))[::2]  # the pose is sent every other frame
    exact_y = np.concatenate(([y0], exact.y_m))[::2]
    judge_x, judge_y = analysis.series["reference_x_m"], analysis.series["reference_y_m"]
    assert len(judge_x) == len(exact_x)
    own_error_m = float(np.max(np.hypot(judge_x - exact_x, judge_y - exact_y)))
    assert analysis.series["distance_m"][-1] >= 100e3
    assert own_error_m < 0.05 * POSITION_LSB_M
    assert analysis.report["reference_start"] == ("power-up" if cut == 0 else "fitted")
    assert analysis.passed, analysis.report["onboard_vs_reference"]


def test_power_up_needs_uptime_zero(tmp_path: Path) -> None:
    """A log whose first sample reads 0 but whose firmware has been up for a while is fitted."""
    profile = load("pmir")
    d = np.full(400, 40)
    synth = synthesize(profile, "exact", d, d + (np.arange(400) % 3 == 0), t0_s=5.0)
    analysis = analyze(read_log(synth.write(tmp_path / "late.log")), profile)
    assert analysis.report["reference_start"] == "fitted"
    assert analysis.passed


def test_a_pose_after_16_lost_frames_is_not_paired_with_the_frame_16_older(tmp_path: Path) -> None:
    """15 encoder frames lost after frame 100: frame 116 repeats frame 100's COUNTER, and the
    pose naming it would resolve to frame 100 (whose own pose is lost too): 16 periods of
    driving off. Frame 116 came 16 periods after frame 100 with no refused frame between, so it
    is the sender's frame 16 on, no repeat (``host.protocol.e2e_cycles``): taken, and the pose
    naming it is paired with it (before that rule it was refused and the pose left unmatched);
    frame 100 is never its match."""
    profile = load("pmir")
    d = np.full(300, 30)
    synth = synthesize(profile, "exact", d, d + 1)
    lines = [line for k, group in enumerate(synth.groups) if not 100 < k < 116
             for line in group if not (k == 100 and " 100#" not in line)]
    analysis = analyze(read_log(write_lines(tmp_path / "gap16.log", lines)), profile)
    assert analysis.passed, analysis.report["onboard_vs_reference"]
    assert analysis.report["samples"]["unmatched_poses"] == 0  # X and Y of frame 116: paired
    assert analysis.report["e2e"]["WHEEL_ENCODERS"]["repeated"] == 0


def write_lines(path: Path, lines: list[str]) -> Path:
    path.write_text("".join(lines))
    return path


def test_a_recorder_started_late_is_not_a_power_up(tmp_path: Path) -> None:
    """The robot at rest for 0.3 s, the recorder started 40 ms after the firmware: the first
    sample names the log's first encoder frame and reads 0, UPTIME 0, but ENC_E2E_OK (11 at
    frame 10) counts frames the log lacks, so the start is fitted; the whole log is a power-up.
    80-81 counts a period: 0.69 m/s, within kobuki's 0.7 (90 was 0.77 m/s, a step its profile's
    firmware refuses)."""
    profile = load("kobuki")
    d = np.concatenate((np.zeros(30, dtype=np.int64), np.full(400, 80)))
    synth = synthesize(profile, "exact", d, d + ((np.arange(430) % 4 == 0) & (d > 0)))
    whole = analyze(read_log(synth.write(tmp_path / "whole.log")), profile)
    late = analyze(read_log(synth.write(tmp_path / "late.log", 4)), profile)
    assert (whole.report["reference_start"], late.report["reference_start"]) == (
        "power-up", "fitted")
    assert whole.passed
    assert late.passed


def test_the_twist_band_keeps_the_step_into_the_last_named_frame() -> None:
    """When the log's last twist frames name the same encoder frame again, the band of the
    segment before them still holds the step into that frame (``reduceat``'s clipped start cut
    it off: a narrower band could fail a correct firmware, and where the log ended decided)."""
    step = np.array([0.0, 0.1, 0.1, 0.1, 0.5])  # the speed steps at encoder frames 0..4
    gap = np.zeros(5)
    e = np.array([0, 2, 4, 4])  # the encoder frames four twist frames name
    value = np.array([0.1, 0.1, 0.5, 0.5])  # each the speed of its last step
    out = _outside_band(value, e, step, gap)
    assert out[2] == 0.0
    assert out[3] == 0.0


@pytest.mark.parametrize("seed", range(6))
def test_first_per_encoder_is_np_unique_s_first_occurrences(seed: int) -> None:
    """The fast path (named frames in order) and the general one agree with ``np.unique``."""
    rng = np.random.default_rng(seed)
    named = np.sort(rng.integers(0, 400, size=1000))  # in bus order, repeats
    if seed % 2:
        named[rng.integers(0, 1000, size=40)] = rng.integers(0, 400, size=40)  # some go back
    named[rng.random(1000) < 0.1] = -1  # not matched
    keep = np.flatnonzero(named >= 0)
    expected, first = np.unique(named[keep], return_index=True)
    uniq, positions = _first_per_encoder(named)
    np.testing.assert_array_equal(uniq, expected)
    np.testing.assert_array_equal(positions, keep[first])
    assert _first_per_encoder(np.full(3, -1))[0].size == 0

