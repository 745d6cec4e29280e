"""A gap of the log no longer places the reference freely (issue #11, rule 5;
``host.judge.gapbound``, ``host.judge.breaks``).

Frames the recorder missed (the WHEEL_ENCODERS and ODOM_* lines of an interval deleted from the
log) were on the bus: the firmware integrated them one by one. Before, ``analyze`` (whole and
streamed) placed the reference's position freely after such a gap, so a firmware jumping there
passed; the live judges did not place it at all, so a correct firmware turning across a long gap
could be called wrong. Now every judge places it within the gap's allowance.

A correct firmware on random robots with random gaps is checked by this file's own float64
odometry (``independent_checker._Odometry``, the fine counts) before the judges must pass it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.livegapseen import end_of_watch
from odocan.host.judge.samples import HEADING_LSB_RAD
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.judge.stream_refusal import NotStreamable
from odocan.host.judge.unseenrestart import DETAIL, EVIDENCELESS
from odocan.sim.contract import database
from odocan.sim.robot import RobotProfile, load
from tests.independent_checker import Robot, _Odometry
from tests.synth_log import Synth, synthesize
from tests.test_babble_firmware import _biased_x
from tests.test_judge_campaign import profile_of, robots
from tests.test_stall_bound import _live, _streamed_alike

KOBUKI = load("kobuki")
STEPS = 1_200
GAP_AT = 500


def _arc(steps: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """kobuki on a constant arc (about 0.4 m/s, 1.3 m radius)."""
    return np.full(steps, 40, dtype=np.int64), np.full(steps, 54, dtype=np.int64)


def _cut(synth: Synth, gaps: list[tuple[int, int]]) -> Synth:
    """The log less the lines of encoder frames first .. first + n - 1 of each gap (the
    WHEEL_ENCODERS frame and the ODOM_* lines after it): what a recorder that missed them
    holds."""
    dropped = {k for first, n in gaps for k in range(first, first + n)}
    synth.groups = [g for k, g in enumerate(synth.groups) if k not in dropped]
    return synth


@pytest.mark.parametrize(("missing", "integrator"), [(1, "rk2"), (3, "exact")])
def test_a_jump_at_a_recorder_gap_fails_every_judge(tmp_path: Path, missing: int,
                                                    integrator: str) -> None:
    """kobuki on an arc, ``missing`` frames lost by the recorder, then X off by 2 cm (1
    missing frame: allowance 3.7 mm) or 15 cm (3 missing: 33 mm) from the first pose after
    the gap on. Before: PASS in analyze, whole and streamed (placed freely)."""
    bias_lsb = 200 if missing == 1 else 1_500
    d_left, d_right = _arc(STEPS)
    start = GAP_AT + missing
    synth = synthesize(KOBUKI, integrator, d_left, d_right,
                       x_bias_100um=dict.fromkeys(range(start, STEPS + 1), bias_lsb))
    path = _cut(synth, [(GAP_AT, missing)]).write(tmp_path / "jump.log")
    result = analyze(read_log(path), KOBUKI, integrator)
    breaks = result.report["reference_breaks"]
    assert breaks["gap_placements"] == 1
    assert not result.passed
    allowed = breaks["gap_offset_allowance_m"]
    assert allowed < 0.5 * bias_lsb * POSITION_LSB_M
    rest = result.report["onboard_vs_reference"]["max_position_error_m"]
    assert rest >= bias_lsb * POSITION_LSB_M - allowed - POSITION_LSB_M
    _streamed_alike(path, KOBUKI, result.report, integrator, chunks=(333,))
    monitor, bridge, end_s = _live(KOBUKI, integrator, path)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.vs_reference.max_dpos_m == pytest.approx(rest, abs=1.5 * POSITION_LSB_M)


def test_a_correct_firmware_passes_a_recorder_gap_with_its_merge_error_absorbed(
    tmp_path: Path,
) -> None:
    """The same arc, 3 frames missing, the firmware right: PASS, the offset absorbed is the
    merged step's error by the independent odometry, and within the allowance."""
    d_left, d_right = _arc(STEPS)
    path = _cut(synthesize(KOBUKI, "rk2", d_left, d_right), [(GAP_AT, 3)]).write(
        tmp_path / "right.log")
    result = analyze(read_log(path), KOBUKI, "rk2")
    breaks = result.report["reference_breaks"]
    assert result.passed, result.report["onboard_vs_reference"]
    want = _merge_error_m(_robot(KOBUKI), "rk2", d_left, d_right, [(GAP_AT, 3)])
    assert breaks["max_gap_offset_absorbed_m"] == pytest.approx(want, abs=0.75 * POSITION_LSB_M)
    assert breaks["max_offset_beyond_allowance_m"] == 0.0
    assert breaks["gap_offset_allowance_m"] >= want + POSITION_LSB_M


def _robot(p: RobotProfile) -> Robot:
    return Robot(p.counts_per_rev, round(p.wheel_radius_left_m * 1e9),
                 round(p.wheel_radius_right_m * 1e9), round(p.wheelbase_m * 1e9), p.counter_bits)


def _merge_error_m(robot: Robot, integrator: str, d_left: npt.NDArray[np.int64],
                   d_right: npt.NDArray[np.int64], gaps: list[tuple[int, int]]) -> float:
    """How far the fine path (every frame) ends from the path that takes each gap's frames
    as one step, by the independent float64 odometry (encoder frame k: d_*[k - 1] behind it)."""
    fine, merged = _Odometry(robot, integrator), _Odometry(robot, integrator)
    inside = {k for first, n in gaps for k in range(first, first + n)}
    pending = [0, 0]
    for k in range(1, len(d_left) + 1):
        step = (int(d_left[k - 1]), int(d_right[k - 1]))
        fine.step(*step)
        pending = [pending[0] + step[0], pending[1] + step[1]]
        if k not in inside:
            merged.step(*pending)
            pending = [0, 0]
    return math.hypot(fine.x - merged.x, fine.y - merged.y)


def _drive(robot: Robot, steps: int, seed: int, speed_m: float, turn: float
           ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Count deltas: ``speed_m`` per period (within the firmware's 4 m/s, and below a 16th of
    the wire counter's range, so that a gap of a few frames stays readable), turning by up to
    ``turn`` rad a period, the turn changing now and then (straight runs among them)."""
    rng = np.random.default_rng(seed)
    m_left = 2 * math.pi * robot.wheel_radius_left_nm * 1e-9 / robot.counts_per_rev
    m_right = 2 * math.pi * robot.wheel_radius_right_nm * 1e-9 / robot.counts_per_rev
    b_m = robot.wheelbase_nm * 1e-9
    speed_m = min(speed_m, (1 << (min(robot.counter_bits, 24) - 5)) * min(m_left, m_right))
    pieces = rng.integers(30, 300, size=steps // 30 + 2)
    turns = rng.choice([0.0, turn, -turn, 0.3 * turn], size=len(pieces))
    half_diff = 0.5 * b_m * np.repeat(turns, pieces)[:steps]
    half_diff = np.clip(half_diff, -0.9 * speed_m, 0.9 * speed_m)
    return (np.rint((speed_m - half_diff) / m_left).astype(np.int64),
            np.rint((speed_m + half_diff) / m_right).astype(np.int64))


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                    HealthCheck.data_too_large])
@given(robot=robots(), integrator=st.sampled_from(["euler", "rk2", "exact"]),
       speed_m=st.floats(0.0005, 0.02), turn=st.sampled_from([0.0, 0.005, 0.03]),
       seed=st.integers(0, 2**32 - 1),
       gaps=st.lists(st.tuples(st.floats(0.05, 0.9), st.integers(1, 200)), min_size=1,
                     max_size=4))
@example(  # a 200-frame gap on a 16.5 mm wheelbase turning 0.03 rad a period: the firmware's
    # fine counts cannot span it (a re-prime, host.judge.unseenrestart) and the drive turned
    # 6.03 rad inside it: the new start took the wrapped -0.25 rad, TURNS one more (before: FAIL
    # with a heading error of 2 pi, whole analyze; found by hypothesis with a random seed)
    robot=Robot(150_000, 11_000_000, 11_000_000, 16_500_000, 32), integrator="euler",
    speed_m=0.0125, turn=0.03, seed=0, gaps=[(0.5, 200)],
)
@example(  # a 2-frame recorder hole on a fast 16-bit robot: 3 periods reach half the 16-bit
    # range (host.judge.ambiguity), the log holds no pages that tell whether the firmware took
    # the frames (it did): before, analyze re-primed there and FAILed it by 22.4 mm; now the
    # next pose chooses (host.judge.evidenceless; found by hypothesis with random seeds 11, 12)
    robot=Robot(17155, 10_000_000, 10_000_000, 1_000_000_000, 16), integrator="euler",
    speed_m=0.015625, turn=0.0, seed=0, gaps=[(0.25, 2)],
)
@example(  # an 80-frame recorder hole the fine counts cannot span (an unseen restart) on a
    # nearly straight drive: the new start's heading, the middle of its samples' heading
    # overlap, is known to half a heading LSB only, and over the 4.7 m after it the reference
    # drifted: FAIL by 0.148 mm; now the heading is fitted to the life's positions
    # (host.judge.newstartfit; found by hypothesis with a random seed)
    robot=Robot(9_431_988, 285_819_757, 300_110_745, 151_990_577, 32), integrator="euler",
    speed_m=0.01925670943473033, turn=0.0, seed=804,
    gaps=[(0.5, 186), (0.2757746747984123, 5), (0.8986581081388366, 1)],
)
@example(  # the same on a 16-bit robot of 3878 counts/rev turning slowly, a 31-frame hole: the
    # judge's own error grew to 1.2 LSB after it, FAIL by 0.177 mm; now 0.009 LSB (found by
    # hypothesis with random seed 108)
    robot=Robot(3878, 15_719_271, 15_719_271, 1_000_000_000, 16), integrator="euler",
    speed_m=0.01948434034339805, turn=0.005, seed=1, gaps=[(0.21485434758903704, 31)],
)
def test_a_correct_firmware_with_random_recorder_gaps_passes(
    tmp_path_factory: pytest.TempPathFactory, robot: Robot, integrator: str, speed_m: float,
    turn: float, seed: int, gaps: list[tuple[float, int]],
) -> None:
    """Random robots (16/32-bit counters, 1 cm .. 2 m wheelbases, unequal radii), straight
    and turning, gaps of 1 .. 200 frames the recorder missed: the firmware, right by the
    independent odometry, passes analyze (whole and streamed alike) and the monitor."""
    profile = profile_of(robot)
    steps = 800
    d_left, d_right = _drive(robot, steps, seed, speed_m, turn)
    m_left = 2 * math.pi * robot.wheel_radius_left_nm * 1e-9 / robot.counts_per_rev
    wire_half = 1 << (min(robot.counter_bits, 24) - 1)  # the count jump a gap can carry
    cut: list[tuple[int, int]] = []
    for where, n in sorted(gaps):
        first = 50 + int(where * (steps - 260))
        step_max = int(max(np.max(np.abs(d_left)), np.max(np.abs(d_right)))) + 1
        n = min(n, wire_half // step_max - 2)  # the gap's count jump below half the range
        if not cut or first > cut[-1][0] + cut[-1][1] + 4:  # apart, a pose between
            cut.append((first, n))
    synth = synthesize(profile, integrator, d_left, d_right)
    fine = _Odometry(robot, integrator)
    for k in range(1, steps + 1):  # the firmware is right: the fine path, to its rounding
        fine.step(int(d_left[k - 1]), int(d_right[k - 1]))
        x_m, y_m, _ = synth.state[k].pose
        assert math.hypot(x_m - fine.x, y_m - fine.y) < 0.05 * POSITION_LSB_M + 1e-9 * k * (
            speed_m + m_left)
    path = _cut(synth, cut).write(tmp_path_factory.mktemp("gaps") / "drive.log")
    result = analyze(read_log(path), profile, integrator)
    assert result.passed, (result.report["onboard_vs_reference"],
                           result.report["reference_breaks"], cut)
    if result.report["samples"]["unseen_restarts"]:  # a hole the firmware's bound cannot read
        # (tests/test_wrap_in_silence.py): it may have re-primed there, a new start the streamed
        # judge does not fit (host.judge.unseenrestart): it refuses, odocan analyze judges whole
        with pytest.raises(NotStreamable):
            analyze_file(path, profile, integrator, chunk_frames=333)
    else:
        refused = ""
        try:
            _streamed_alike(path, profile, result.report, integrator, chunks=(333,))
        except NotStreamable as refusal:  # the next pose chose at an ambiguous gap the log
            refused = str(refusal)  # gives no evidence for (in a hole the stream re-primed
        assert refused in ("", EVIDENCELESS, DETAIL)  # a new start): the whole log's judges
    monitor, bridge, end_s = _live(profile, integrator, path)
    assert monitor.health(end_s)["state"] != "POSE WRONG", (monitor.health(end_s), cut)
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.placer.placements.max_beyond_m == 0.0


def _lockstep_with_gaps(tmp_path: Path, gaps_s: list[tuple[float, float]]) -> Path:
    """A lockstep rig's log (kobuki, figure 8, seed 3) less the WHEEL_ENCODERS and ODOM_*
    lines within each interval of bus time (s): what a recorder that missed them holds."""
    log = tmp_path / "rig.log"
    assert main(["run", "--robot", "kobuki", "--scenario", "figure8", "--duration", "6",
                 "--seed", "3", "--log", str(log)]) == 0
    db = database()
    ids = {m.frame_id for m in db.messages
           if m.name == "WHEEL_ENCODERS" or m.name.startswith("ODOM_")}
    kept = []
    for line in log.read_text().splitlines(keepends=True):
        stamp, _, frame = line.split()[:3]
        t_s = float(stamp.strip("()"))
        if int(frame.split("#")[0], 16) in ids and any(a <= t_s < b for a, b in gaps_s):
            continue
        kept.append(line)
    out = tmp_path / "gaps.log"
    out.write_text("".join(kept))
    return out


def test_a_lockstep_log_with_recorder_gaps_and_a_jump(tmp_path: Path) -> None:
    """The rig's correct firmware with recorder gaps of 1, 2 and 25 frames passes every judge;
    the same firmware's X off by 3 cm from the first pose after the short gap at 2.0 s fails
    them (before: PASS in analyze, whole and streamed)."""
    gaps_s = [(1.0, 1.0095), (2.0, 2.0195), (4.0, 4.2495)]
    path = _lockstep_with_gaps(tmp_path, gaps_s)
    kobuki = load("kobuki")
    result = analyze(read_log(path), kobuki)
    breaks = result.report["reference_breaks"]
    assert breaks["gap_placements"] == 3
    assert result.passed, (result.report["onboard_vs_reference"], breaks)
    _streamed_alike(path, kobuki, result.report, chunks=(333,))
    monitor, _, end_s = _live(kobuki, "exact", path)
    assert monitor.health(end_s)["state"] == "OK", monitor.health(end_s)
    wrong = tmp_path / "wrong.log"
    assert _biased_x(path, wrong, lambda _k, t_s: 2.0 < t_s < 4.0, 300) > 50
    bad = analyze(read_log(wrong), kobuki)
    assert not bad.passed
    _streamed_alike(wrong, kobuki, bad.report, chunks=(333,))
    upto = tmp_path / "upto.log"  # the monitor's state while the jump lasts (to 4 s)
    upto.write_text("".join(line for line in wrong.read_text().splitlines(keepends=True)
                            if float(line.split()[0].strip("()")) < 3.9))
    monitor, _, end_s = _live(kobuki, "exact", upto)
    assert monitor.health(end_s)["state"] == "POSE WRONG"


@pytest.mark.parametrize("bias_lsb", [0, 2, 1 << 16])
def test_a_turn_past_half_inside_an_unseen_restart_gap(tmp_path: Path, bias_lsb: int) -> None:
    """The pinned example above (a 200-frame gap the fine counts cannot span, 6.03 rad turned
    inside it): the new start takes the on-board turns across it, so the firmware, right by the
    independent odometry, passes (before: FAIL, 2 pi); its HEADING 2 LSB off, or TURNS one off,
    from frame 650 on (the new start's samples from 520) still FAILs."""
    robot = Robot(150_000, 11_000_000, 11_000_000, 16_500_000, 32)
    d_left, d_right = _drive(robot, 800, 0, 0.0125, 0.03)
    synth = synthesize(profile_of(robot), "euler", d_left, d_right,
                       heading_bias_lsb=dict.fromkeys(range(650, 801), bias_lsb))
    fine = _Odometry(robot, "euler")
    for k in range(1, 801):
        fine.step(int(d_left[k - 1]), int(d_right[k - 1]))
    x_m, y_m, heading_rad = synth.state[800].pose
    assert math.hypot(x_m - fine.x, y_m - fine.y) < POSITION_LSB_M
    assert abs(heading_rad - fine.heading) < 1e-6
    path = _cut(synth, [(320, 200)]).write(tmp_path / "turned.log")
    result = analyze(read_log(path), profile_of(robot), "euler")
    assert result.report["samples"]["unseen_restarts"] == 1
    assert result.passed is (bias_lsb == 0), result.report["onboard_vs_reference"]


FAST = Robot(17155, 10_000_000, 10_000_000, 1_000_000_000, 16)  # 3 periods are ambiguous


def hole_log(tmp_path: Path, firmware: str, totals_at: frozenset[int] = frozenset()) -> Path:
    """The drive of the evidenceless hole (the pinned example above), frames 185-186 cut: the
    firmware ``took`` them, ``reprimed`` at 187 (X off by the float64 odometry's difference),
    or took them with its HEADING 2 LSB off from 187 on (``heading_off``); FRAME_TOTALS pages
    after the summaries of the frames ``totals_at`` (``synth_log.synthesize``)."""
    d_left, d_right = _drive(FAST, 800, 0, 0.015625, 0.0)
    fine, reprimed = _Odometry(FAST, "euler"), _Odometry(FAST, "euler")
    x_bias: dict[int, int] = {}
    for k in range(1, 801):
        fine.step(int(d_left[k - 1]), int(d_right[k - 1]))
        if k not in (185, 186, 187):  # the re-prime integrates nothing from 184 to 187
            reprimed.step(int(d_left[k - 1]), int(d_right[k - 1]))
        assert abs(reprimed.y - fine.y) < 1e-9
        assert abs(reprimed.heading - fine.heading) < 1e-12
        x_bias[k] = round((reprimed.x - fine.x) / POSITION_LSB_M)
    assert x_bias[187] < -200  # the re-prime is 2 cm behind: far beyond the gap's allowance
    synth = synthesize(profile_of(FAST), "euler", d_left, d_right, totals_at=totals_at,
                       x_bias_100um=x_bias if firmware == "reprimed" else None,
                       heading_bias_lsb=dict.fromkeys(range(187, 801), 2)
                       if firmware == "heading_off" else None)
    return _cut(synth, [(185, 2)]).write(tmp_path / "hole.log")


@pytest.mark.parametrize("firmware", ["took", "reprimed", "heading_off"])
def test_an_ambiguous_recorder_hole_without_evidence_takes_either(tmp_path: Path,
                                                                   firmware: str) -> None:
    """The pinned example above: frames 185-186 cut from the log, the step from 184 to 187
    (3 periods) ambiguous (host.judge.ambiguity) and no page telling what the firmware did. The
    firmware that took them one by one passes (before: FAIL by 22.4 mm, re-primed); one that
    re-primed there (its pose the float64 odometry without the steps into 185-187) passes too;
    one whose HEADING is 2 LSB off from 187 on fits neither and FAILs, on the live judges too
    (the monitor's model, the bridge). The streamed judge leaves such a life to the whole
    log's."""
    path = hole_log(tmp_path, firmware)
    result = analyze(read_log(path), profile_of(FAST), "euler")
    assert result.passed is (firmware != "heading_off"), result.report["onboard_vs_reference"]
    with pytest.raises(NotStreamable, match="no evidence"):
        analyze_file(path, profile_of(FAST), "euler", chunk_frames=333)
    monitor, bridge, end_s = _live(profile_of(FAST), "euler", path)  # the live judge agrees:
    wrong = firmware == "heading_off"  # both candidates held until the pose after the hole
    assert (monitor.health(end_s)["state"] == "POSE WRONG") is wrong, monitor.health(end_s)
    for tracker in (monitor.tracker, bridge.tracker):  # (before: heading_off PASSed live)
        assert (tracker.vs_reference.max_dheading_rad > HEADING_LSB_RAD) is wrong
        assert (tracker.wrongs.count > 0) is wrong
        assert tracker.max_beyond_allowance_m <= POSITION_LSB_M
        assert tracker.reference_starts == 1  # one start: the choice, not a new start


@pytest.mark.parametrize("firmware", ["took", "heading_off"])
def test_an_ambiguous_hole_near_the_end_of_a_watch_is_chosen_at_its_end(tmp_path: Path,
                                                                        firmware: str) -> None:
    """The hole above, the watch ending 0.4 s after it (before the 1 s the live judge gives
    the pages): ``end_of_watch`` (``odocan monitor``'s end) makes the choice, so the samples
    held since the hole are judged; the firmware whose HEADING is 2 LSB off FAILs on the
    monitor's model and the bridge (before: PASS, a new start from the pose after the
    hole), the one that took the frames passes."""
    d_left, d_right = _drive(FAST, 800, 0, 0.015625, 0.0)
    synth = synthesize(profile_of(FAST), "euler", d_left, d_right,
                       heading_bias_lsb=dict.fromkeys(range(187, 801), 2)
                       if firmware == "heading_off" else None)
    synth = _cut(synth, [(185, 2)])
    synth.groups = synth.groups[:228]  # encoder frames 0 .. 227 but the hole's
    path = synth.write(tmp_path / "end.log")
    monitor, bridge, _ = _live(profile_of(FAST), "euler", path)
    for tracker in (monitor.tracker, bridge.tracker):
        end_of_watch(tracker)
        wrong = tracker.vs_reference.max_dheading_rad > HEADING_LSB_RAD
        assert wrong is (firmware == "heading_off"), tracker.vs_reference
        assert tracker.max_beyond_allowance_m <= POSITION_LSB_M
