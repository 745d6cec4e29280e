"""The live judges leave out a pose half the bus held back (issue #11: a FAIL must never blame a
correct firmware; ``host.judge.livelatehalves``).

``odocan run --scenario random --duration 10 --firmware python --faults delay=0.5:150``: half
the frames reach the bus 150 ms late (15 encoder periods). pmir seed 6: the ODOM_POSE_Y of
COUNTER 9 heard at 2.251 s was sent at 2.101 s naming the encoder frame of 2.04 s (ENC_COUNTER
12); resolved where it was heard, its 12 named the frame of 2.20 s, whose on-time ODOM_POSE_X
(2.201 s) the live judges paired with it: a pose 37 mm off the firmware's, the reference placed
onto it within a stall's budget, and 16.7 mm beyond the allowance once the pages withdrew that
budget (4.001 s). ``analyze`` names such halves where they were sent (``latenames``) and PASSes
whole and streamed; the monitor and the bridge FAILed (mm beyond the allowance): pmir 6 16.67,
kobuki 1 1.54, kobuki 4 8.47, kobuki 7 5.99, pmir 4 2.51, every one first at such a mixed pair.
They now name a late half where it was sent too: pmir 6, kobuki 1, pmir 4 within 0.1 mm; X 10
mm off from 5 s, which no live judge saw before (the same figures as the correct drive's),
FAILs pmir 6 and kobuki 1 by 9.70 and 9.20 mm. kobuki 4 and 7 were then 31.39 and 22.84 mm
beyond where a step after a counter restart's run counted its periods from the frame before the
run (``tests/test_restart_run_periods.py``); 0.04 and 0.0 mm now. Every drive here: the Python
firmware's every step within 1/1000 LSB of float64 (``tests.fw_watch``)."""

from __future__ import annotations

from collections import deque
from pathlib import Path

import pytest

from odocan.host.judge.latenames import LateScan
from odocan.host.judge.livelatehalves import LateHalves, named_sent
from odocan.host.protocol.busfacts import POSE_PERIOD_S
from tests.judges_cli import both_analyses, live_judges, raise_x_10_mm, watched_run

FAULTS = "delay=0.5:150"
DRIVES = {"pmir_6": ("pmir", 6), "kobuki_1": ("kobuki", 1), "kobuki_4": ("kobuki", 4),
          "kobuki_7": ("kobuki", 7), "pmir_4": ("pmir", 4)}
LIVE = ["kobuki_4", "kobuki_1", "kobuki_7", "pmir_4", "pmir_6"]
BUDGET_ABSORBS = pytest.mark.xfail(strict=True, reason=(
    "not fixed: pmir 4 with X 10 mm off from 5 s stays 0.046 mm beyond live (2.51 before, the "
    "correct drive's figure: no live judge saw it before either): 46 samples are judged after "
    "5 s, each placed again after the gaps of the held-back frames within a budget their "
    "pages never withdraw"))
TAMPERED = ["kobuki_1", "kobuki_4", "kobuki_7", pytest.param("pmir_4", marks=BUDGET_ABSORBS),
            "pmir_6"]
TAMPER_FROM_S = 5.0  # X 10 mm off from here on
# pmir seed 6's ODOM_POSE_Y as heard from 1.961 s (bus time s, COUNTER; True: held back)
PMIR_6_YS = ((1.961, 2, False), (1.971, 11, True), (1.981, 3, False), (2.021, 5, False),
             (2.031, 14, True), (2.051, 15, True), (2.061, 7, False), (2.081, 8, False),
             (2.121, 10, False), (2.151, 4, True), (2.161, 12, False), (2.181, 13, False),
             (2.191, 6, True), (2.221, 15, False), (2.251, 9, True))


def test_the_held_back_halves_are_read_late() -> None:
    """C6 (2.191 s) and C9 (2.251 s), sent at 2.041 and 2.101 s, are read late; the on-time
    C13 and C15 around them are not."""
    late = LateHalves()
    sent_s = [late.heard("y", t, c) for t, c, _ in PMIR_6_YS]
    assert [s is not None for s in sent_s] == [w for _, _, w in PMIR_6_YS]
    assert sent_s[-3] == pytest.approx(2.041)
    assert sent_s[-1] == pytest.approx(2.101)


def test_a_refused_half_is_read_in_its_sequence() -> None:
    """A CRC-right frame the host's E2E refused is read too (``sent_places`` reads them all):
    the late C9 after a refused on-time C15 is still read late."""
    late = LateHalves()
    for t, c, _ in PMIR_6_YS[:-2]:
        late.heard("y", t, c)
    late.refused("ODOM_POSE_Y", 2.221, 15)
    late.refused("ODOM_TWIST", 2.231, 3)  # not a pose: not read
    assert late.heard("y", 2.251, 9) == pytest.approx(2.101)


ROWS: deque[tuple[float, ...]] = deque([(100, 0, 11, 2.030, 0, 0, 1), (101, 0, 12, 2.040, 0, 0, 1),
              (102, 0, 6, 2.140, 0, 0, 10), (103, 0, 8, 2.160, 0, 0, 2),
              (104, 0, 12, 2.200, 0, 0, 4)])  # seq, pos, COUNTER, bus time s, L, R, periods


@pytest.mark.parametrize(("enc_counter", "sent_s", "seq"), [
    (12, 2.101, 101),  # sent after the frame of 2.04 s: that one, not the one of 2.20 s
    (11, 2.101, 100),  # one sender step back
    (12, 2.201, 104),  # sent after 2.20 s: that one
    (6, 2.201, 102),  # six sender steps back (periods 4 and 2)
    (7, 2.201, -1),  # five steps back: a frame the host did not take
    (13, 2.101, -1),  # a name after the latest frame before its send
    (12, 2.030, -1),  # sent before every frame kept
])
def test_a_late_half_is_named_where_it_was_sent(enc_counter: int, sent_s: float,
                                                seq: int) -> None:
    assert named_sent(ROWS, enc_counter, sent_s) == seq


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[str, Path]:
    """(robot, log) of the drive, its firmware's every step asserted right (``fw_watch``)."""
    robot, seed = DRIVES[request.param]
    log = tmp_path_factory.mktemp(request.param) / "drive.log"
    watch, code = watched_run(log, robot, "random", seed, 10, FAULTS)
    assert code == 0
    assert watch.steps > 300
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)
    return robot, log


def test_both_analyses_pass(drive: tuple[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    codes = both_analyses(drive[1])
    capsys.readouterr()
    assert codes == [0, 0]


@pytest.mark.parametrize("drive", LIVE, indirect=True)
def test_the_live_judges_pass(drive: tuple[str, Path]) -> None:
    beyond_m = [j.tracker.max_beyond_allowance_m for j in live_judges(*drive)]
    assert max(beyond_m) <= 1e-4, beyond_m


@pytest.mark.parametrize("drive", TAMPERED, indirect=True)
def test_x_10_mm_off_fails_live(drive: tuple[str, Path], tmp_path: Path) -> None:
    """X raised 10 mm from 5 s on: both live judges more than 5 mm beyond the allowance."""
    robot, log = drive
    tampered = tmp_path / "t.log"
    assert raise_x_10_mm(log, tampered, TAMPER_FROM_S) > 100
    beyond_m = [j.tracker.max_beyond_allowance_m for j in live_judges(robot, tampered)]
    assert min(beyond_m) > 5e-3, beyond_m


def test_bus_time_going_back_starts_the_scan_afresh() -> None:
    """A new time base (a rig restarted, a bus replayed: tests/test_mqtt_robustness.py's fuzz of
    10 s, then a rig from 0 s) is no lateness: the frames heard in order after it are not read
    late. Fed to one scan across the jump, every one of them is (the case this guards)."""
    before = [(9.0 + 0.02 * k, k % 16) for k in range(40)]
    after = [(0.001 + 0.02 * k, (k + 9) % 16) for k in range(40)]  # 7..12 on: all read late
    halves = LateHalves()
    for t_s, counter in before:
        halves.heard("x", t_s, counter)
    assert [halves.heard("x", t_s, c) for t_s, c in after] == [None] * len(after)
    one = LateScan(POSE_PERIOD_S)
    one.feed(*map(list, zip(*before, strict=True)))
    late, _ = one.feed(*map(list, zip(*after, strict=True)))
    assert all(late)
