"""Combined bus faults (``delay`` with ``busoff`` and ``dup``, issue #11): who is wrong.

The trial's three drives (kobuki, 4 s, seed 703) FAIL a firmware whose every on-board pose is
the float64 odometry of the encoder frames it actually took: the Python firmware (the C port's
log is byte-identical) is run with its ``Odometry.step_deltas`` and ``set_pose`` watched, and
each step it integrated is integrated again here in plain float64 (the exact arc) from the pose
it had; the RAM pose after each step is within 1e-6 mm and 1e-12 rad of it on every drive
below. So the firmware is right and the judge wrong: its model of the frames the firmware took
differs under these faults. Fixed: ``delay=0.5:150``, where the firmware took the late stream's
COUNTER 8, 9, 10 at 0.55 to 0.57 s and refused the on-time COUNTER 7 at 0.55 s, a wrong sequence
in its one-period window, and the host took both: two ODOM_POSE_X frames heard 150 ms late were
read as sent when heard, and the pose evidence took the 7 for the one the second named
(``e2e_evidence.heard_in_order``, ``tests/test_late_pose_evidence.py``). Fixed too: seed 2's
``delay=0.5:150`` (65.6 mm) and seed 2's ``delay=0.5:100`` PASSing a pose 10 mm off: an
ODOM_STATUS summary held back behind a newer second read as a reboot at 1.00 s (1.05 s:
``livelatestatus``, ``tests/test_late_status.py``), and the last frame of an E2E lock-out named
again before the next frame came read as a hold at 1.57 s, its 11.7 mm allowance absorbing the
tamper (``stalls.named_again``, ``tests/test_combo_hold_evidence.py``).
Fixed too: the drives with a bus-off, where the log itself was wrong: frames held back by ``delay``
whose release fell in the bus-off went on the bus at the recovery (2.0028 s) but kept their due
time as stamp, so the log showed the encoder frames heard at 1.04 to 1.09 s that the firmware took
only at its tick of 2.01 s (``tests/test_busoff_release.py``); with the stamps the bus gave them
the host's E2E takes the bus-off's frames as the firmware did and all four PASS (32 to 52 mm off
before). Its verdicts still differ from the firmware's on 6 encoder frames, the delay's alone: 0.55
to 0.60 s on ``delay=0.5:100`` (as without the bus-off) and COUNTER 7 at 3.91 s on
``delay=0.3:55,busoff=1:1``, refused for an ODOM_POSE_Y held back 55 ms behind another held one,
read as in order (``e2e_evidence.sent_times``) naming COUNTER 4. Until the judges are fixed the
other verdicts are pinned as strict xfails: a fixed judge turns them into XPASS, which fails the
suite until the marks are removed. A pose 10 mm off from 2.0 s FAILs on every drive (three PASSed
before: ``test_a_pose_10_mm_off_fails``) but the pinned ones: on the three with ``busoff=1:1`` 2.0
s is the end of the bus-off's silence, a gap of the log's encoder frames whose placement may absorb
what the firmware could have taken in it (~830 mm); the firmware's E2E counts, refusals included,
prove it took none on the two with ``delay=0.3:55`` (``host.judge.gapchecked``), not on
``delay=0.5:100``, where no ODOM_STATUS page is known made in its tick.
Fixed too: the stalls under a delay, seed 703 ``delay=0.5:100,stall=2:1`` (40.2 mm, 67.1 mrad;
now 0.022 mm, 0.045 mrad) and seed 2 ``stall=1.5:0.5,delay=0.3:55`` (3.75 mrad; now 0.047
mrad): the reference re-primed where a late frame's CTRL_UPTIME went back against an on-time
frame the halted firmware's full mailbox had dropped; its last frame was older, and it reported
no COUNTER_RESET (``host.judge.stallrestart``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.sim.robot import load
from tests.fw_watch import HEADING_LSB_RAD, POSITION_LSB_M, watched
from tests.judges_cli import raise_x_10_mm

KOBUKI = load("kobuki")
JUDGE_WRONG = ("issue #11: the judge's model of the frames the firmware took under delay + busoff "
               "/ long delay differs (its E2E window and bus-off receive order); analyze's "
               "reference is off the correct firmware by ")
# measured after the stall/hold/gap-fill fixes (offline analyze, seed 703; main alike in heading)
OFF: dict[str, str] = {  # none left: the stall drives fixed by stallrestart, the delay
    # drives by latenames (their figures beside each drive below)
}

# (seed, faults, the judge wrongly FAILs it today): the trial's three, then a sweep of
# delay P:MS x busoff x dup (measured: every delay with busoff=1:1 FAILs, delay alone PASSes;
# 0.5:150 FAILed 209 mm, 183 mrad till late pose frames no longer counted as evidence)
DRIVES = [
    (703, "delay=0.5:150", False),
    (703, "delay=0.5:100,busoff=1:1", False),
    (703, "delay=0.3:55,dup=0.1,busoff=1.2:0.8,reboot=2.5", False),
    (703, "delay=0.3:55", False),
    (703, "delay=0.3:55,dup=0.1", False),
    (703, "delay=0.3:55,busoff=1:1", False),
    (703, "delay=0.3:55,dup=0.1,busoff=1:1", False),
    (703, "delay=0.5:100", False),
    (703, "delay=0.5:100,dup=0.1", False),
    # the sweep beyond 703 (kobuki seeds 1-2): main PASSed seed 1's tamper on both
    (1, "delay=0.5:100", False),
    (1, "delay=0.5:150", False),
    (2, "delay=0.5:100", False),
    # 40.2 mm, 67.1 mrad till a CTRL_UPTIME restart inside a stall followed the firmware's
    # COUNTER_RESET (stallrestart) and asked its E2E window (ctrlrestart.window_periods,
    # tests/test_mcu_bus_combos.py): either rule alone PASSes it
    (703, "delay=0.5:100,stall=2:1", False),
    # stallfirst FAILed it 762 mm once merged; 29.96 mm beyond till a silence anywhere between
    # two samples was a stall (stalls.inner_silences, tests/test_stall_delay_dup.py)
    (2, "delay=0.5:100,stall=2:1", False),
    # 3.75 mrad till then (the same two rules): the host took the on-time 7 and 8 (CTRL_UPTIME
    # 3) the full mailbox dropped, so the late 5 (CTRL_UPTIME 2) after them read as a restart
    (2, "stall=1.5:0.5,delay=0.3:55", False),
    (2, "delay=0.5:150", False),  # a held-back summary read as a reboot: 65.6 mm till lateup
    # FAILed (3.58 mm of DISTANCE; 17.7, 1.8, 33.8, 59.3 mm) till a pose or twist frame held
    # back was named from where it was sent (host.judge.latenames, tests/test_delay_long.py)
    *((seed, "delay=0.5:150", False) for seed in (3, 4, 5, 6)),
    (6, "delay=0.5:100", False),
]


def _params(drives: list[tuple[int, str, bool]]) -> list[object]:
    return [pytest.param(seed, faults, id=f"{seed}-{faults}", marks=[pytest.mark.xfail(
        strict=True, reason=JUDGE_WRONG + OFF.get(faults, "?"))]
        if wrong else [])
            for seed, faults, wrong in drives]


def _run(path: Path, seed: int, faults: str) -> int:
    return main(["run", "--robot", "kobuki", "--duration", "4", "--seed", str(seed),
                 "--faults", faults, "--firmware", "python", "--log", str(path)])


@pytest.mark.parametrize(("seed", "faults"), [(s, f) for s, f, _ in DRIVES])
def test_the_firmware_integrates_the_frames_it_took(seed: int, faults: str,
                                                    tmp_path: Path) -> None:
    with watched(KOBUKI) as watch:
        _run(tmp_path / "drive.log", seed, faults)
    assert watch.steps > 100, watch.steps
    assert watch.worst_m <= POSITION_LSB_M / 1000, watch.worst_m
    assert watch.worst_rad <= HEADING_LSB_RAD / 1000, watch.worst_rad


@pytest.mark.parametrize(("seed", "faults"), _params(DRIVES))
def test_every_judge_passes_the_right_firmware(seed: int, faults: str, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "drive.log"
    codes = [_run(log, seed, faults)]
    codes += [main(["analyze", str(log), "--stream", s]) for s in ("always", "never")]
    capsys.readouterr()
    assert codes == [0, 0, 0]


# Before (measured, seed 703) delay=0.3:55, delay=0.5:100 and delay=0.5:100,dup=0.1 PASSed X
# raised 10 mm from 2.0 s: pose frames the host refused (reordered) counted as silence and made
# stalls, sparse samples made holds without evidence (stalls.hold_evidence), and frames held
# back 10 periods left gaps unfilled (gapfill.MAX_LATE_PERIODS): each placement absorbed it.
# Seed 2's delay=0.5:100 PASSed it too: a held-back summary read as a reboot, and a frame named
# again before the next came read as a hold (stalls.named_again).


TAMPER_ABSORBED = {
    (703, "delay=0.5:100,busoff=1:1"): (
        "issue #11: a pose 10 mm off from 2.0 s PASSes: 10.03 mm absorbed within 851.2 mm (10 of "
        "47.5 poses judged): 2.0 s is the end of the bus-off's 1 s silence, a gap of the log's "
        "encoder frames (~100 periods) whose placement may absorb what the firmware could have "
        "integrated of frames the log lacks. gapchecked's proof (the E2E counts, refusals "
        "included, grew by the log's frames) would withdraw it, as on the 0.3:55 drives, but no "
        "ENC_E2E page is evidence here: the 100 ms delay (one status cycle) holds back the "
        "summary or the page of every tick, or lets a held summary out with the next, so no page "
        "is known made in its tick (pagekeeper)")}


@pytest.mark.parametrize(("seed", "faults"), [
    pytest.param(s, f, id=f"{s}-{f}", marks=[pytest.mark.xfail(
        strict=True, reason=TAMPER_ABSORBED[(s, f)])] if (s, f) in TAMPER_ABSORBED else [])
    for s, f, _ in DRIVES])
def test_a_pose_10_mm_off_fails(seed: int, faults: str, tmp_path: Path,
                                capsys: pytest.CaptureFixture[str]) -> None:
    log, tampered = tmp_path / "drive.log", tmp_path / "tampered.log"
    _run(log, seed, faults)
    assert raise_x_10_mm(log, tampered, 2.0) > 20
    capsys.readouterr()
    assert not analyze(read_log(tampered), KOBUKI, "exact").passed
    for stream in ("always", "never"):
        assert main(["analyze", str(tampered), "--stream", stream]) == 1
