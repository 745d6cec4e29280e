"""The outside trial's FAILs of the twenty-ninth pass not fixed yet (issue #11: a FAIL must never
blame a correct firmware): each firmware's every step watched (``tests.fw_watch``: within 1/1000
LSB), the verdicts pinned as strict xfails with their figures and cause. Fixed ones:
``test_busoff_queued_twist`` (kobuki 414, 446's DISTANCE and pose), ``test_held_boot_summary``
(kobuki 410), ``test_reprime_after_busoff`` (kobuki 444's COUNTER_RESET after the bus-off and
pmir figure8 82's refusals after it: the firmware's, a held frame's doubt); pmir figure8 405
``busoff=4:0.2,dup=0.1,delay=0.1:20`` PASSes on main since the revert. Fixed here, each with a
pose 10 mm off from the fault's end still FAILed:

* ``late_frame_a_lap_on`` (DISTANCE 24.5 mm, the pose 0.53 mm off; now 0 and 0.043 mm): the
  poses' proof that the firmware skipped COUNTER 9 was read as its E2E refusal, where its
  plausibility bound refused the step (``host.protocol.e2e_implausible``); the firmware's own
  doubt of the held frames fixed too (``test_reprime_after_busoff``): either PASSes it;
* ``stall_delay_dup`` (9.0 mm, 28.3 mrad; now 0.056 mm, 0.048 mrad): the reference re-primed on
  a CTRL_UPTIME gone back against a frame the halted firmware never had, which it did not report
  (``host.judge.stallrestart``);
* ``late_naming_100ms`` (kobuki random 23, ``delay=0.5:100,stall=4:1``: DISTANCE 16.8 mm off from
  8.02 s, the host's E2E taking at 7.840 s two on-time frames the firmware refused amid a run
  100 ms late): PASSes run, whole and streamed since the forty-third pass's pose evidence
  (``host.protocol.e2e_sends``, ``e2e_crosslate``), found as this strict xfail passing.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.fw_watch import Watch
from tests.judges_cli import (
    both_analyses,
    fails_by_position,
    raise_x_10_mm,
    reported_analyses,
    watched_run,
)

DRIVES: dict[str, tuple[tuple[str, str, str, str, str], str | None]] = {
    # name: (robot, scenario, seed, duration s, faults), why the judges FAIL it (None: fixed)
    "late_frame_a_lap_on": (("pmir", "figure8", "82", "10", "delay=0.3:55,busoff=1:1"), None),
    "stall_delay_dup": (("pmir", "random", "12", "12", "delay=0.3:55,dup=0.1,stall=4:2"), None),
    "late_naming_100ms": (("kobuki", "random", "23", "10", "delay=0.5:100,stall=4:1"), None),
}
Drive = tuple[Path, Watch, int]  # the log, the firmware's watch, run's exit code
TAMPERED = {"late_frame_a_lap_on": 2.0, "stall_delay_dup": 6.0}  # from the fault's end (s)


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Drive:
    robot, scenario, seed, duration, faults = DRIVES[request.param][0]
    log = tmp_path_factory.mktemp(request.param) / "d.log"
    watch, code = watched_run(log, robot, scenario, seed, duration, faults)
    return log, watch, code


def test_the_firmware_integrates_the_frames_it_took(drive: Drive) -> None:
    _, watch, _ = drive
    assert watch.steps > 400, watch.steps
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)


@pytest.mark.parametrize("drive", [
    pytest.param(name, marks=() if why is None else pytest.mark.xfail(strict=True, reason=why))
    for name, (_, why) in sorted(DRIVES.items())
], indirect=True)
def test_run_and_both_analyzes_pass_the_correct_firmware(
        drive: Drive, capsys: pytest.CaptureFixture[str]) -> None:
    log, _, code = drive
    codes = [code, *both_analyses(log)]
    out = capsys.readouterr().out
    assert codes == [0, 0, 0], out[-2000:]


@pytest.mark.parametrize("drive", sorted(TAMPERED), indirect=True)
def test_a_pose_10_mm_off_from_the_fault_s_end_fails(
        drive: Drive, request: pytest.FixtureRequest, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """+10 mm on ODOM_POSE_X's X from the first pose after the bus-off or the halt: whole and
    streamed FAIL. After the bus-off by the position beyond its allowance; after the halt by
    the pose the firmware resumed at (the stall's resume rule, ``stallfirst``: the gaps the
    delay leaves there are placed within their allowance, no page proving what it took)."""
    log, _, _ = drive
    name = request.node.callspec.params["drive"]
    out = tmp_path / "raised.log"
    assert raise_x_10_mm(log, out, TAMPERED[name]) > 100
    if name == "late_frame_a_lap_on":
        assert fails_by_position(out, tmp_path) == []
    else:
        judged = reported_analyses(out, tmp_path)
        resumes = [report["stall_first_pose"] for _, _, report in judged]
        assert [code for _, code, _ in judged] == [1, 1]
        assert all(r["max_resume_beyond_m"] > 5e-3 for r in resumes), resumes
    capsys.readouterr()
