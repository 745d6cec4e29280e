"""A recorder that stamps every ODOM_STATUS frame late (10..50 ms) must not hide a stall the
firmware declared it re-primed after (issue #11, rule 5: a FAIL must never blame a correct
firmware).

pmir on the circle in the lockstep rig, its MCU halted 6 s mid-drive (``drive_mid``): it
re-primes on resuming and says so (COUNTER_RESET newly set, ``host.judge.stallreprime``). The
log's ODOM_STATUS frames all stamped ``late_s`` later, the log re-sorted by time. The summary
sent in the tick of the last pose before the halt then comes after the frame the reference
restarts at: read by arrival order, the stall was the 0.1 s between that summary and the one
before (too short to re-prime), the re-prime went unseen and the correct firmware FAILed by
metres (an outside trial's live log: 3.1 m / 2.66 rad). The summaries' own gap (the widest
around the stall within the lateness) is the stall's. The same firmware 10 mm or 1 m off after
the stall still FAILs every judge.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from tests.test_first_second_reboot import _written, _wrong
from tests.test_stall_before_first_pose_after_reboot import _live
from tests.test_stall_beyond_window import MID, PMIR, drive_mid
from tests.test_status_stamped_late import _status_late

HALTED = 600  # 6 s: long enough for the firmware's bound to reach the ambiguous step


@pytest.mark.parametrize("late_s", [0.01, 0.03, 0.05])
def test_a_correct_firmware_passes_every_judge(late_s: float, tmp_path: Path) -> None:
    messages = _status_late(drive_mid(HALTED), late_s)
    path = _written(messages, tmp_path / "late.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert analysis.passed, analysis.report["onboard_vs_reference"]  # before: FAIL, metres
    assert [e["kind"] for e in analysis.report["events"]].count("stall_reprime") == 1
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(messages)
    assert (monitor.health(end_s)["pose_wrongs"]["episodes"],
            bridge.tracker.wrongs.as_dict()["episodes"]) == (0, 0)
    assert monitor.health(end_s)["state"] == "DEGRADED"  # its own COUNTER_RESET
    for judge in (monitor, bridge):
        assert [e["kind"] for e in judge.events].count("stall_reprime") == 1


@pytest.mark.parametrize("late_s", [0.01, 0.05])
@pytest.mark.parametrize(("from_pose", "bias_lsb"), [(1, 10_000), (1, 100), (20, 100)])
def test_a_wrong_firmware_still_fails(late_s: float, from_pose: int, bias_lsb: int,
                                      tmp_path: Path) -> None:
    """X off by ``bias_lsb`` (1 m, 10 mm) from the ``from_pose``-th pose after the stall's
    start (pose 0 is the one before the halt's backlog)."""
    messages = _status_late(_wrong(drive_mid(HALTED), MID + 1, bias_lsb, from_pose), late_s)
    path = _written(messages, tmp_path / "wrong.log")
    assert not analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert bridge.tracker.wrongs.as_dict()["episodes"] >= 1
