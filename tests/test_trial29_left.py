"""The outside trial's FAILs of the twenty-ninth pass not fixed yet (issue #11: a FAIL must never
blame a correct firmware): each firmware's every step watched (``tests.fw_watch``: within 1/1000
LSB; kobuki 444's frame choice likely wrong all the same), the verdicts pinned as strict xfails
with their figures and cause. Fixed ones:
``test_busoff_queued_twist`` (kobuki 414, 446's DISTANCE), ``test_held_boot_summary`` (kobuki
410); pmir figure8 405 ``busoff=4:0.2,dup=0.1,delay=0.1:20`` PASSes on main since the revert.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.fw_watch import Watch
from tests.judges_cli import both_analyses, watched_run

DRIVES = {  # name: (robot, scenario, seed, duration s, faults), why the judges FAIL it
    "reprime_after_busoff": (
        ("kobuki", "random", "444", "11", "reboot=2:0.4,delay=0.3:55,busoff=7:0.2"),
        "issue #11: likely the firmware's fault: after the 0.2 s bus-off it refused the frames "
        "after the motor controller's held ones (7.2028 s) and took three consistent ones for "
        "a counter restart (COUNTER_RESET at 7.40 s, re-primed on the 7.31 s frame) where the "
        "controller never restarted: 148 mm and 964 mrad off the truth (as pmir figure8 80 of "
        "test_trial_false_fails was before firmware.sampledoubt); the reference re-primed at "
        "7.26 s instead: DISTANCE 15.9 mm, the pose 21.0 mm and 266.7 mrad off the firmware"),
    "late_frame_a_lap_on": (
        ("pmir", "figure8", "82", "10", "delay=0.3:55,busoff=1:1"),
        "issue #11: after the 1 s bus-off the host's E2E took a frame the delay held back "
        "(COUNTER 2, heard at 2.155 s) as one a lap on, after three newer frames the firmware "
        "refused; the reference's path steps back and forth through it: DISTANCE 24.5 mm off "
        "a right firmware (the pose 0.53 mm)"),
    "stall_delay_dup": (
        ("pmir", "random", "12", "12", "delay=0.3:55,dup=0.1,stall=4:2"),
        "issue #11: pmir random 12 halted 2 s under delay=0.3:55,dup=0.1: the pose 9.0 mm, "
        "28.3 mrad off a right firmware (test_stall_delay_dup's family); not traced"),
    "late_naming_100ms": (
        ("kobuki", "random", "23", "10", "delay=0.5:100,stall=4:1"),
        "issue #11: ODOM_TWIST DISTANCE 16.8 mm off a right firmware from 8.02 s (the twist "
        "COUNTER 9 sent 7.921 s, heard 100 ms late, named where sent: the WHEEL_ENCODERS "
        "ENC_COUNTER 13 of 7.91 s; the reference's path runs 16.5 mm past its DISTANCE there, "
        "likely the firmware had the late frame of that ENC_COUNTER from 7.75 s: not traced). "
        "The pose is met since the late naming (host.judge.latenames; 23.3 mm, 603 mrad "
        "before)"),
}
Drive = tuple[Path, Watch, int]  # the log, the firmware's watch, run's exit code


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
    pytest.param(name, marks=pytest.mark.xfail(strict=True, reason=why))
    for name, (_, why) in sorted(DRIVES.items())
], indirect=True)
def test_run_and_both_analyzes_pass_the_correct_firmware(
        drive: Drive, capsys: pytest.CaptureFixture[str]) -> None:
    log, _, code = drive
    codes = [code, *both_analyses(log)]
    out = capsys.readouterr().out
    assert codes == [0, 0, 0], out[-2000:]
