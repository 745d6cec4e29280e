"""A held-back twist frame just before an MCU stall does not make the stall's first sends late
(issue #11: a FAIL must never blame a correct firmware).

``odocan run --robot kobuki --scenario random --seed 698 --duration 8 --faults
busoff=1.5:0.2,delay=0.1:150,stall=3.1:0.3``: ODOM_TWIST COUNTER 10 heard in order at 3.081 s,
then 4 and 6 (held back 150 ms by ``delay``) at 3.111 and 3.151 s, then the MCU halted 0.3 s and
sent 11, 12, 13 ... on time from 3.401 s. ``latenames.LateScan`` read 11 as continuing the late
run from 10, the latest heard in order (``_top_send``: 320 ms before, a hair less than a COUNTER
lap of 16 sends), sent at 3.101 s and held back 300 ms, and every frame after it at its cadence
as late as that: the twists of 3.42-3.62 s were named at the encoder frames of 3.12-3.32 s, two
COUNTER laps back. FAIL by ODOM_TWIST 46.5 mm/s, 387 mrad/s and DISTANCE 53.8 mm (seed 699: 8.29
mm/s, 382 mrad/s, 56.5 mm) with every pose within 0.07 mm of the reference, the firmware within
1/1000 LSB of float64 (``tests.fw_watch``). A lateness of half a COUNTER lap or more cannot be
told from a silence of the sender (the lapped rule); such a reading from the latest frame heard
in order is no longer taken. The same faults' neighbours 696 and 697 (77.9 mm; DISTANCE 163.2 mm)
and figure8 671 at ``reboot=1.8:0.2,stall=5.6:0.2,delay=0.3:55`` (DISTANCE 43.5 mm) PASS with
it, as does pmir 697 (DISTANCE 163.3 mm); figure8 672 still FAILs, for another cause
(``FIGURE8_672``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from odocan.host.judge.latenames import late_sends
from odocan.host.protocol.busfacts import POSE_PERIOD_S
from tests.fw_watch import Watch
from tests.judges_cli import STREAMS, analyze, reported_analyses, watched_run, x_10_mm_off_fails
from tests.log_edit import raise_raw

RANDOM = "busoff=1.5:0.2,delay=0.1:150,stall=3.1:0.3"
FIGURE8 = "reboot=1.8:0.2,stall=5.6:0.2,delay=0.3:55"
PAST_RANDOM_S, PAST_FIGURE8_S = 3.6, 6.0  # the stall and its first sends over
DRIVES = {  # name: robot, scenario, seed, duration s, faults, a time past the faults; FAILed
    "random_696": ("kobuki", "random", 696, 8, RANDOM, PAST_RANDOM_S),  # 77.9, DISTANCE 74.2 mm
    "random_697": ("kobuki", "random", 697, 8, RANDOM, PAST_RANDOM_S),  # DISTANCE 163.2 mm
    "random_698": ("kobuki", "random", 698, 8, RANDOM, PAST_RANDOM_S),  # DISTANCE 53.8 mm
    "random_699": ("kobuki", "random", 699, 8, RANDOM, PAST_RANDOM_S),  # DISTANCE 56.5 mm
    "pmir_697": ("pmir", "random", 697, 8, RANDOM, PAST_RANDOM_S),  # DISTANCE 163.3 mm
    "figure8_671": ("kobuki", "figure8", 671, 9, FIGURE8, PAST_FIGURE8_S),  # DISTANCE 43.5 mm
    "figure8_672": ("kobuki", "figure8", 672, 9, FIGURE8, PAST_FIGURE8_S),  # 634 mm: unfixed
}
FIGURE8_672 = (
    "not fixed: figure8 672 FAILs its correct firmware (on-board vs reference 634.4 mm, "
    "DISTANCE 19.5 mm, the pose at 2.060 s 625 mm beyond a stall's resume). The reboot at "
    "2.0 s primed on the encoder frame of 2.020 s (its power-up ODOM_POSE_Y names it), but its "
    "first page of encoder E2E counts (OK 7, LOST 2), sent at 2.101 s, was held back 55 ms by "
    "the delay fault: counted back from the latest encoder frame before its stamp (2.156 s), "
    "the new life starts at 2.070 s and its first poses (X 16 mm at 2.061 s) are judged as "
    "the old life's, 625 mm off (reboots.page_counted_start reads the page at its stamp; "
    "counted from 2.101 s, the whole analysis PASSes: checked by hand, not done, as the "
    "streamed, live and replay judges count alike and a recorder may stamp the boot summary "
    "late too)")
TEN_MM_SHORT_LSB = -10  # ODOM_TWIST DISTANCE's 1 mm LSBs
DISTANCE_SPAN = (6, 2)  # ODOM_TWIST DISTANCE: bytes 6..7, little-endian
Drive = tuple[Path, Watch, int, float]


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Drive:
    robot, scenario, seed, duration, faults, past_s = DRIVES[request.param]
    log = tmp_path_factory.mktemp(request.param) / "d.log"
    watch, code = watched_run(log, robot, scenario, seed, duration, faults)
    return log, watch, code, past_s


def test_the_stall_s_first_sends_after_a_late_frame_are_on_time() -> None:
    """ODOM_TWIST as seed 698 heard it: 7, 0 (late), 8, 9, 10 in order, 4 and 6 held back
    150 ms, the MCU halted 0.3 s, then 11-14 at its cadence: 11-14 are on time."""
    heard = np.array([3.021, 3.031, 3.041, 3.061, 3.081, 3.111, 3.151,
                      3.401, 3.421, 3.441, 3.461])
    counter = np.array([7, 0, 8, 9, 10, 4, 6, 11, 12, 13, 14], dtype=np.int64)
    late, sent = late_sends(heard, counter, POSE_PERIOD_S)
    assert late[7:].tolist() == [False] * 4, sent.tolist()
    assert np.array_equal(sent[7:], heard[7:])


@pytest.mark.parametrize(("heard_s", "late"), [(8.971, True), (9.117, False)])
def test_a_late_reading_from_the_latest_in_order_stops_at_half_a_lap(
        heard_s: float, late: bool) -> None:
    """7 in order at 8.801 s, 0 held back (sent 8.661 s), then 8, off the late run's cadence:
    its step from 7 puts its send at 8.821 s. Heard 7.5 periods after that, it is read late
    there, as before. Heard 14.8 periods after (315 ms after 7, within a lap of it), its
    nearest reading from 7 is a lap more, 17 sends, on time after a silence: a lateness of half
    a lap or more cannot be told from that, and it is left where it was heard (read late
    before)."""
    heard = np.array([8.781, 8.801, 8.811, heard_s])
    read, sent = late_sends(heard, np.array([6, 7, 0, 8], dtype=np.int64), POSE_PERIOD_S)
    assert read.tolist() == [False, False, True, late]
    assert sent[3] == pytest.approx(8.821 if late else heard_s)


def test_the_firmware_integrates_the_frames_it_took(drive: Drive) -> None:
    _, watch, _, _ = drive
    assert watch.steps > 300, watch.steps
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)


def _unfixed(request: pytest.FixtureRequest) -> bool:
    return bool(request.node.callspec.params["drive"] == "figure8_672")


def test_the_correct_firmware_passes(drive: Drive, request: pytest.FixtureRequest,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    if _unfixed(request):
        request.applymarker(pytest.mark.xfail(strict=True, reason=FIGURE8_672))
    log, _, code, _ = drive
    codes = [code, *(analyze(log, s) for s in STREAMS)]
    out = capsys.readouterr().out
    assert codes == [0, 0, 0], out[-1500:]


def test_x_10_mm_off_after_the_stall_fails_by_the_position(
        drive: Drive, request: pytest.FixtureRequest, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    if _unfixed(request):
        pytest.skip("the untampered drive FAILs already (FIGURE8_672)")
    wrong = x_10_mm_off_fails(drive[0], tmp_path / "t.log", drive[3], 100)
    capsys.readouterr()
    assert wrong == []


def test_a_distance_10_mm_short_after_the_stall_fails(
        drive: Drive, request: pytest.FixtureRequest, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """ODOM_TWIST DISTANCE lowered 10 mm from after the stall on: each analysis FAILs it on
    DISTANCE."""
    if _unfixed(request):
        pytest.skip("the untampered drive FAILs already (FIGURE8_672)")
    tampered = tmp_path / "t.log"
    assert raise_raw(drive[0], tampered, "ODOM_TWIST", DISTANCE_SPAN, TEN_MM_SHORT_LSB,
                     drive[3]) > 100
    wrong = []
    for s, code, report in reported_analyses(tampered, tmp_path):
        if code != 1 or report["onboard_distance_vs_reference"]["passed"]:
            wrong.append(f"--stream {s}: exit {code}, "
                         f"{json.dumps(report['onboard_distance_vs_reference'])}")
    capsys.readouterr()
    assert wrong == []
