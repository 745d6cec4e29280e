"""Two captures of tests/test_ctrl_restart.py's process test (``odocan firmware`` and ``odocan
sim`` killed and started again) on a loaded machine (4 busy loops, every process at nice 19),
where the judges blamed the correct firmware: 4 of 7 runs said POSE WRONG. Captured by the
test's listener (the frames a monitor on the channel heard), kept as BLF.

``restart_lagged_first_pose.blf``: the sim started while the firmware was still starting; the
firmware's first pose (ENC_COUNTER 2) is on the encoder frame 53 of the capture (the float
reference there: 0.02 mm, 0.05 mrad off), 16 encoder frames before the newest frame with that
counter (73), which the judges take: 79.31 mm, 78.49 mrad off. The firmware was that far behind
(FRAME_TOTALS: 18 frames overflowed its mailbox next); its next poses name the newest frames.
A 4-bit ENC_COUNTER cannot name a frame 16 or more behind: the pose's own values tell the lap
(``host.judge.lapfirst``: X, Y, heading and the twist's DISTANCE all fit the older lap, not the
newest; live ``livelapfirst``: its HEADING picks it, each value judged there). The process test
now starts the sim once the firmware is heard (0 of 8 runs said POSE WRONG since).

``restart_live_two_lsb.blf``: after the restart (the firmware's FRAME_TOTALS: 26 frames lost,
overflowed), ``analyze`` passes (0.29 mm within its 1.681 mm allowance for the frames the
firmware lost); the live monitor said POSE WRONG for 1 s from the restarted controller's fourth
frame: 0.1985 mm against one LSB (0.1 mm): its latest sample, the one before the restart, judged
with the new reference's allowance (none) while the new life's samples were held.
"""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.sim.robot import load
from tests.judges_cli import both_analyses, fails_by_position, live_judges, x_10_mm_off_fails
from tests.log_edit import raise_raw_once

FILES = Path(__file__).resolve().parent / "files"
PMIR = load("pmir")


def live_states(path: Path) -> set[str]:
    """Every state the monitor said, frame by frame."""
    monitor = BusMonitor(PMIR)
    states = set()
    for msg in can.LogReader(path):
        monitor.feed(msg, now_s=msg.timestamp)
        states.add(monitor.health(msg.timestamp)["state"])
    return states


LAGGED = FILES / "restart_lagged_first_pose.blf"
FIRST_POSE_BEFORE_S = 0.6  # the first pose: 0.542 s after the log's first frame


def test_both_analyses_pass_a_firmware_16_frames_behind_at_its_first_pose() -> None:
    """Before: both ``analyze`` FAILed it, 78.95 mm beyond its allowance (79.60 mm, 78.49 mrad
    off at encoder frame 73, the newest of ENC_COUNTER 2) and its twist's DISTANCE 79.32 mm
    beyond; its X, Y, heading and DISTANCE fit frame 53, a lap before, within 2 LSBs each
    (``lapfirst``): it is judged there (the streamed judge reads it whole: a burst)."""
    report = analyze(read_log(LAGGED), PMIR).report
    assert report["passed"], report["onboard_vs_reference"]
    assert report["onboard_vs_reference"]["max_position_error_m"] < 2 * POSITION_LSB_M
    assert both_analyses(LAGGED) == [0, 0]


@pytest.mark.parametrize(("message", "span", "lsb"), [
    ("ODOM_POSE_X", (2, 4), 100),  # its X 10 mm off
    ("ODOM_POSE_Y", (2, 4), 10),  # its Y 1 mm off: the older lap fits X, heading, twist only
    ("ODOM_TWIST", (6, 2), 80),  # its DISTANCE the newest lap's: the pose fits the older alone
])
def test_a_first_pose_fitting_the_older_lap_but_in_part_still_fails(
        message: str, span: tuple[int, int], lsb: int, tmp_path: Path) -> None:
    """The older lap is taken only when all four of the tick's values fit it: one value off
    leaves the plain name (the newest frame), and both ``analyze`` FAIL by the position."""
    tampered = tmp_path / "tampered.blf"
    times = raise_raw_once(LAGGED, tampered, message, span, lsb, 0.0)
    assert len(times) == 1, times
    assert times[0] < FIRST_POSE_BEFORE_S, times
    assert fails_by_position(tampered, tmp_path) == []
    assert ("DISTANCE WRONG" if message == "ODOM_TWIST" else "POSE WRONG") in live_states(
        tampered)  # live, each value judged at the lap the HEADING picks (livelapfirst)
    _, bridge = live_judges("pmir", tampered)
    assert bool(bridge.tracker.wrongs.standing_text()) is (message != "ODOM_TWIST")


def test_a_first_pose_whose_heading_fits_no_older_lap_still_fails(tmp_path: Path) -> None:
    """Its HEADING 3 LSBs off (the older lap's X, Y and DISTANCE kept): no lap picked, the
    plain name stands, every judge FAILs it by the position (79.6 mm off the newest frame)."""
    tampered = tmp_path / "tampered.blf"
    assert len(raise_raw_once(LAGGED, tampered, "ODOM_POSE_X", (6, 2), 3, 0.0)) == 1
    assert fails_by_position(tampered, tmp_path) == []
    assert "POSE WRONG" in live_states(tampered)
    _, bridge = live_judges("pmir", tampered)
    assert bridge.tracker.wrongs.standing_text()


@pytest.mark.parametrize("from_s", [0.0, 1.0])  # from the lagged first pose on, after it
def test_x_10_mm_off_fails_every_judge_on_the_lagged_first_pose(
        from_s: float, tmp_path: Path) -> None:
    tampered = tmp_path / "tampered.blf"
    assert x_10_mm_off_fails(LAGGED, tampered, from_s, 50) == []
    assert "POSE WRONG" in live_states(tampered)
    _, bridge = live_judges("pmir", tampered)
    assert bridge.tracker.wrongs.standing_text()


def test_the_live_judges_pass_a_firmware_16_frames_behind_at_its_first_pose() -> None:
    """Before: the monitor and the bridge latched POSE WRONG at 0.64 s, 79.60 mm, 78.49 mrad
    off (78.95 mm beyond); the first pose's HEADING picks frame 53 (``livelapfirst``), its Y
    half and twist follow, each judged there."""
    assert "POSE WRONG" not in live_states(LAGGED)
    _, bridge = live_judges("pmir", LAGGED)
    assert not bridge.tracker.wrongs.standing_text()
    assert bridge.tracker.max_beyond_allowance_m <= POSITION_LSB_M


def test_the_whole_log_passes_the_restart_with_lost_frames() -> None:
    report = analyze(read_log(FILES / "restart_live_two_lsb.blf"), PMIR).report
    assert report["passed"], report["onboard_vs_reference"]


def test_the_monitor_passes_the_restart_with_lost_frames() -> None:
    """Before: POSE WRONG 1 s from the restarted controller's fourth frame: the latest sample,
    the one before the restart (0.1985 mm within its 1.456 mm for the 26 frames lost), was
    judged with the new reference's allowance (none) while the new life's samples were held
    (``livelosses.LiveAllowance.latest_m``). The bridge passed it, as both ``analyze``."""
    path = FILES / "restart_live_two_lsb.blf"
    assert "POSE WRONG" not in live_states(path)
    _, bridge = live_judges("pmir", path)
    assert not bridge.tracker.wrongs.standing_text()
    assert bridge.tracker.max_beyond_allowance_m <= POSITION_LSB_M
    assert both_analyses(path) == [0, 0]


@pytest.mark.parametrize("from_s", [1.0, 7.0])  # before the restart (6.4 s), after its new start
def test_x_10_mm_off_fails_every_judge_on_the_restart_with_lost_frames(
        from_s: float, tmp_path: Path) -> None:
    """The lost frames' allowance (1.681 mm) hides no 10 mm: both ``analyze`` FAIL by the
    position, the monitor says POSE WRONG, the bridge latches it."""
    tampered = tmp_path / "tampered.blf"
    assert x_10_mm_off_fails(FILES / "restart_live_two_lsb.blf", tampered, from_s, 50) == []
    assert "POSE WRONG" in live_states(tampered)
    _, bridge = live_judges("pmir", tampered)
    assert bridge.tracker.wrongs.standing_text()


@pytest.mark.xfail(strict=True, reason=(
    "X 10 mm off from the first pose after the restart on (6.0 s, 97 frames): both analyze FAIL "
    "(8.58 mm beyond), the monitor stays DEGRADED (0.062 mm beyond): live, the controller's "
    "restart behind the log's 4.4 s silence is an unseen one and the reference starts again at "
    "the next pose, the tampered one (livedark's known limit: the pages proving the firmware "
    "took the frames heard across it come after the restart). Before the latest-sample fix the "
    "monitor said POSE WRONG here only for the sample before the restart (0.1985 mm)"))
def test_x_10_mm_off_from_the_restart_on_fails_the_monitor(tmp_path: Path) -> None:
    tampered = tmp_path / "tampered.blf"
    assert x_10_mm_off_fails(FILES / "restart_live_two_lsb.blf", tampered, 6.0, 50) == []
    assert "POSE WRONG" in live_states(tampered)
