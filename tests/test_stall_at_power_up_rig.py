"""A firmware whose MCU halts 3 s at power-up, before its first pose, in the fault rig (issue #11:
"a PASS/OK must never hide a wrong pose"; ``tests/test_stall_beyond_window.py``'s ``drive`` at
300 ticks: pmir on the circle, the FIFO empty at tick 0, INIT, UPTIME 0, only its ODOM_STATUS
sent; then 3 s of no MCU while the sim drives on). On resuming it primes on frame 1, steps frame
2 and takes frame ``RESUMED_AT`` as one step (the float64 odometry of the tests, on
cantools-decoded frames): its first pose is that merged step, as after a reboot's stall
(``tests/test_stall_before_first_pose_after_reboot.py``). Unlike the recorded evidence of
``tests/test_stall_before_first_pose.py`` (whose first count page came before any frame), its
first count page comes 80 ms after its first pose, and counts 11 frames (ENC_E2E_OK; the FIFO's
overrun is in ENC_E2E_LOST): ``analyze`` proved the power-up by the page's tick bound
(``powerup.heard_by_tick``: its ODOM_STATUS COUNTER stood still through the halt, so the bound is
0.1 s after power-up, 11 frames on the bus by then: frame 0 counted, which the firmware never
took). Across a halt the bound is no evidence (``stallpowerup.log_power_up``): the stall's rule
proves it (frames 0 and 1 unmoved); with frame 0 moved it is unproven and said, where the bound
had FAILed the correct firmware by 29.8 mm / 15.8 mrad.

(a) Before: the live judges read that bound on their 32 recent frames only
(``liveheard.heard_before_live``), could not prove the power-up, and started the reference fitted
at the first sample kept: a firmware 1 m off from its first pose showed 0 wrong episodes (the
monitor DEGRADED only by the firmware's own POSE_UNCERTAIN) while ``analyze`` FAILed it at
944 mm. Now they read the whole window (5 s) as ``analyze`` reads the log, and when the proof
comes after the first sample was left out (``livefirst``) the reference starts at (0, 0, 0) on
frame 0 and its position is placed at the next sample within the merge allowance
(``livestart.start_reference``'s ``stalled_from``), as ``analyze`` places it.

(c) With the firmware's first two count pages lost on the bus (3.101 s and 3.701 s), the next
one's tick bound no longer reaches the power-up (its ODOM_STATUS COUNTER has wrapped past 16).
Before, no judge proved it: ``analyze`` and the live judges started fitted at the first sample
kept and PASSed a firmware 1 m off from its first pose (the monitor DEGRADED only by the
firmware's POSE_UNCERTAIN; both end verdicts PASS). Now the evidence that remains proves it
(``host.judge.stallpowerup``, ``stalls.primed_first``'s rule for a reboot's life): the
first-cycle summary says INIT at UPTIME 0, no pose before the stall, and frames 0 and 1 (the
firmware's FIFO was drained at tick 0 after frame 0: it primed on one of them) carry the same
counts. Frame 0 moved 5 counts off, that last condition fails: the frame it primed on is not
known, and ``analyze`` judges the life from each (``host.judge.primedon``: the right firmware
PASSes from frame 1, one 1 m off FAILs from both; before, fitted, it PASSed with a
``power_up_unproven`` line); the live judges leave it unproven (the end verdicts UNJUDGED):
none PASSes the wrong firmware silently, none FAILs the right one.

(b) X 3 LSB off from the 20th pose (0.3 mm): it FAILs ``analyze`` since the reboot's fix of the
double allowance (``losses.placement_accounted``, which the power-up shares: 0.235 mm beyond the
allowance, before 0.262 mm within it), and the live judges.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.host.judge.primedon import PRIMED_KIND
from odocan.host.judge.samples import ENC_E2E_PAGE
from tests.test_first_second_reboot import _decoded, _written, _wrong
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live, _poses
from tests.test_stall_beyond_window import PMIR, _end_verdicts, drive, frame_zero_moved

HALTED = 300  # ticks of no MCU after its power-up tick (3 s)
RESUMED_AT = HALTED + 2  # the encoder frame its first pose names (the merged step's end)


def _messages() -> tuple[can.Message, ...]:
    return drive("power-up", HALTED)


def _gap_m(messages: tuple[can.Message, ...], k: int) -> tuple[float, float]:
    """How far the ``k``-th pose lies from the float64 odometry of the frames the firmware
    took (frames 1, 2, ``RESUMED_AT``, then every frame to the one the pose names, 2 a send
    period): (position m, heading rad)."""
    encoders = [_decoded(m) for m in _messages() if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    pose = _poses(messages, 0.0)[k]
    named = RESUMED_AT + 2 * k
    assert int(pose["ENC_COUNTER"]) == named % 16
    odo = _odometry(encoders, [1, 2, *range(RESUMED_AT, named + 1)])
    return (math.hypot(odo.x - pose["X"] * 1e-4, odo.y - pose["Y"] * 1e-4),
            abs(odo.heading - pose["HEADING"] * 2 * math.pi / 65536))


def test_the_firmware_took_its_fifo_then_one_step() -> None:
    """Its first pose is frames 1, 2, then ``RESUMED_AT`` as one step (float64, within an
    LSB), and so are the next ones; the fine path is centimetres away."""
    for k in (0, 1, 20, 60):
        gap_m, turn_rad = _gap_m(_messages(), k)
        assert gap_m <= POSITION_LSB_M, (k, gap_m)
        assert turn_rad <= HEADING_LSB_RAD, (k, turn_rad)
    encoders = [_decoded(m) for m in _messages() if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    fine = _odometry(encoders, list(range(1, RESUMED_AT + 1)))
    first = _poses(_messages(), 0.0)[0]
    assert math.hypot(fine.x - first["X"] * 1e-4, fine.y - first["Y"] * 1e-4) > 0.01


def test_every_judge_passes_the_correct_firmware(tmp_path: Path) -> None:
    """``analyze`` (whole, streamed) and the live judges, from the power-up, the position
    placed at the stall (no false FAIL from the proof that comes after the first sample)."""
    path = _written(_messages(), tmp_path / "right.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert analysis.passed, analysis.report["onboard_vs_reference"]
    assert analysis.report["reference_start"] == "power-up"
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(_messages())
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] == 0
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.lives.power_up_proven  # as analyze: not a fitted start
        assert tracker.stall.stalls == 1
        assert tracker.wrongs.as_dict()["episodes"] == 0
        assert tracker.max_beyond_allowance_m <= POSITION_LSB_M
    for live in (monitor.distance, bridge.distance):
        assert live.as_dict()["passed"]


@pytest.mark.parametrize(("from_pose", "bias_lsb"), [(0, 10_000), (1, 10_000), (20, 3),
                                                     (60, 2)])
def test_a_wrong_firmware_fails_every_judge(tmp_path: Path, from_pose: int,
                                            bias_lsb: int) -> None:
    """X off by ``bias_lsb`` from pose ``from_pose`` on: 1 m from the first pose (before: 0
    wrong episodes live, a fitted start absorbed it; ``analyze`` 944 mm), 0.3 mm from the 20th,
    0.2 mm from the 60th. The evidence: the correct firmware is within one LSB of the float64
    odometry there, the wrong one more than one LSB off."""
    messages = _wrong(_messages(), 0, bias_lsb, from_pose)
    at = max(from_pose, 1)
    assert _gap_m(_messages(), at)[0] <= POSITION_LSB_M
    assert _gap_m(messages, at)[0] > POSITION_LSB_M
    path = _written(messages, tmp_path / "wrong.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert not analysis.passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1
    beyond_m = analysis.report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"]
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.wrongs.as_dict()["episodes"] >= 1
        assert tracker.max_beyond_allowance_m > POSITION_LSB_M
        if bias_lsb == 10_000:  # the same start and placement as analyze's: the same error
            assert tracker.max_beyond_allowance_m == pytest.approx(beyond_m, abs=POSITION_LSB_M)


def _without_first_count_pages(messages: tuple[can.Message, ...]) -> tuple[can.Message, ...]:
    """The frames without the firmware's first two ODOM_STATUS pages of WHEEL_ENCODERS E2E
    counts (lost on the bus)."""
    pages = [m for m in messages if m.arbitration_id == fr.ODOM_STATUS_ID
             and int(_decoded(m)["PAGE"]) == ENC_E2E_PAGE][:2]
    return tuple(m for m in messages if all(m is not page for page in pages))


def test_without_its_first_count_pages_the_correct_firmware_passes(tmp_path: Path) -> None:
    """The stall proves the power-up there (module docstring, (c)): every judge from (0, 0, 0)
    at frame 0, the correct firmware PASSes every judge, the end verdicts too."""
    messages = _without_first_count_pages(_messages())
    path = _written(messages, tmp_path / "right.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert analysis.passed, analysis.report["onboard_vs_reference"]
    assert analysis.report["reference_start"] == "power-up"
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] == 0
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.lives.power_up_proven
        assert tracker.wrongs.as_dict()["episodes"] == 0
        assert tracker.max_beyond_allowance_m <= POSITION_LSB_M
    assert _end_verdicts(bridge) == ("PASS", "PASS")


@pytest.mark.parametrize(("from_pose", "bias_lsb"), [(0, 10_000), (1, 10_000), (20, 3)])
def test_without_its_first_count_pages_a_wrong_firmware_fails(tmp_path: Path, from_pose: int,
                                                              bias_lsb: int) -> None:
    """X off by ``bias_lsb`` from pose ``from_pose`` on (1 m, or 0.3 mm from the 20th): every
    judge FAILs it, the end verdicts too (before: all PASSed 1 m, the start fitted)."""
    messages = _without_first_count_pages(_wrong(_messages(), 0, bias_lsb, from_pose))
    at = max(from_pose, 1)
    assert _gap_m(messages, at)[0] > POSITION_LSB_M  # the float64 evidence
    analysis, bridge = _fails_every_judge(messages, tmp_path / "wrong.log")
    if bias_lsb == 10_000:  # the same start as analyze's: the same error
        beyond_m = analysis.report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"]
        assert bridge.tracker.max_beyond_allowance_m == pytest.approx(beyond_m,
                                                                      abs=POSITION_LSB_M)


@pytest.mark.parametrize("bias_lsb", [0, 10_000])
def test_moved_frame_zero_is_judged_from_each_frame_it_may_have_primed_on(
        tmp_path: Path, bias_lsb: int) -> None:
    """Frame 0 moved (``frame_zero_moved``), the first count pages lost: the stall does not tell
    which of frames 0 and 1 the firmware primed on. ``analyze`` judges it from each
    (``host.judge.primedon``): the right firmware (``bias_lsb`` 0) PASSes from frame 1, one 1 m
    off from its 2nd pose FAILs from both (before: fitted, it PASSed with its first pose said
    not judged). The live judges cannot prove the start: never a FAIL of the right one, never
    a silent PASS (the end verdicts UNJUDGED, the start adopted)."""
    messages = frame_zero_moved(_without_first_count_pages(_wrong(_messages(), 0, bias_lsb, 1)))
    path = _written(messages, tmp_path / "log.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert analysis.passed is (bias_lsb == 0)
    assert analysis.report["reference_start"] == "power-up"
    primed = [e for e in analysis.report["events"] if e["kind"] == PRIMED_KIND]
    assert len(primed) == 1
    assert primed[0]["encoder_frame"] == 1 or bias_lsb
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == (0 if bias_lsb == 0 else 1)
    monitor, bridge, end_s = _live(messages)
    assert not bridge.tracker.lives.power_up_proven
    assert monitor.health(end_s)["state"] != "POSE WRONG"
    assert bridge.tracker.wrongs.as_dict()["episodes"] == 0
    assert _end_verdicts(bridge) == ("UNJUDGED", "UNJUDGED")


def test_without_its_first_cycle_nothing_is_proven(tmp_path: Path) -> None:
    """The log without the firmware's first-cycle ODOM_STATUS frames (INIT at UPTIME 0) nor
    its first count pages: nothing shows the power-up (a recorder started after it), so no
    judge proves it by the stall, nor says it unproven: fitted, the right firmware PASSes."""
    messages = tuple(m for m in _without_first_count_pages(_messages())
                     if not (m.arbitration_id == fr.ODOM_STATUS_ID and m.timestamp < 0.05))
    analysis = analyze(read_log(_written(messages, tmp_path / "cut.log")), PMIR, "exact")
    assert analysis.passed
    assert analysis.report["reference_start"] == "fitted"
    assert "power_up_unproven" not in [e["kind"] for e in analysis.report["events"]]
    monitor, bridge, _ = _live(messages)
    for tracker in (monitor.tracker, bridge.tracker):
        assert not tracker.lives.power_up_proven
        assert not tracker.first.unproven
        assert tracker.wrongs.as_dict()["episodes"] == 0


def test_frame_zero_moved_with_its_pages_no_judge_fails_the_correct_firmware(
        tmp_path: Path) -> None:
    """Frame 0 moved with the count pages kept (``frame_zero_moved``: the firmware, its FIFO
    drained at tick 0, primed on frame 1). Before, the first page's tick bound counted frame 0
    (``powerup.heard_by_tick``: the halt held the page's tick 3 s past its bound) and
    ``analyze`` started the reference there: FAIL by 29.8 mm / 15.8 mrad while the live judges
    PASSed. Now the halt vetoes the bound (``stallpowerup.log_power_up``) and the life is
    judged from each frame it may have primed on (``primedon``): PASS from frame 1."""
    messages = frame_zero_moved(_messages())
    path = _written(messages, tmp_path / "right.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert analysis.passed, analysis.report["onboard_vs_reference"]
    assert analysis.report["reference_start"] == "power-up"
    assert [(e["kind"], e["encoder_frame"]) for e in analysis.report["events"]
            if e["kind"] == PRIMED_KIND] == [(PRIMED_KIND, 1)]
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] != "POSE WRONG"
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.wrongs.as_dict()["episodes"] == 0
    assert _end_verdicts(bridge) == ("PASS", "PASS")


@pytest.mark.parametrize("from_pose", [0, 1])
def test_frame_zero_moved_with_its_pages_a_wrong_firmware_fails_every_judge(
        tmp_path: Path, from_pose: int) -> None:
    """X 1 m off from pose ``from_pose`` on, frame 0 moved, the pages kept: off from either
    frame it may have primed on, ``analyze`` FAILs it (whole and streamed: the stream judges
    it whole), the live judges too (POSE WRONG, both end verdicts)."""
    messages = frame_zero_moved(_wrong(_messages(), 0, 10_000, from_pose))
    analysis, _ = _fails_every_judge(messages, tmp_path / "wrong.log")
    assert analysis.report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"] > 0.5


def test_frame_zero_moved_without_a_stall_no_false_fail(tmp_path: Path) -> None:
    """No halt (``drive`` with 0 ticks): the FIFO drained at tick 0, the firmware primes on
    frame 1, frame 0 moved. Its count page then counts one frame fewer than the log holds
    before it, no bound matches: no judge proves the power-up from frame 0, none FAILs the
    correct firmware; X 1 m off from its 2nd pose FAILs every judge."""
    right = frame_zero_moved(drive("power-up", 0))
    path = _written(right, tmp_path / "right.log")
    assert analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(right)
    assert (monitor.health(end_s)["state"], _end_verdicts(bridge)) == ("OK", ("PASS", "PASS"))
    wrong = frame_zero_moved(_wrong(drive("power-up", 0), 0, 10_000, 1))
    path = _written(wrong, tmp_path / "wrong.log")
    assert not analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1
    monitor, bridge, end_s = _live(wrong)
    assert (monitor.health(end_s)["state"], _end_verdicts(bridge)) == ("POSE WRONG",
                                                                        ("FAIL", "FAIL"))


def _fails_every_judge(messages: tuple[can.Message, ...], path: Path) -> tuple[Any, Any]:
    """``messages`` written to ``path``: ``analyze`` FAILs them whole and streamed, the monitor
    ends POSE WRONG, the bridge latched a wrong episode and both end verdicts FAIL; returns the
    whole log's analysis and the bridge for the caller's figures."""
    path = _written(messages, path)
    analysis = analyze(read_log(path), PMIR, "exact")
    assert not analysis.passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert bridge.tracker.wrongs.as_dict()["episodes"] >= 1
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")
    return analysis, bridge
