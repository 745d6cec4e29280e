"""Drives with two MCU faults and a bus fault that FAILed the correct firmware, from the outside
sweep of issue #11 (a FAIL must never blame a correct firmware, a PASS never hide a wrong pose).
The Python firmware is watched at every step (``tests.fw_watch``: within 1/1000 LSB of its
float64 arc), so a FAIL of the untampered drive blames a correct one.

kobuki square 655, 9 s, ``stall=2.9:0.2,reboot=6.2:0.2,delay=0.1:20``: every judge FAILed
(837.6 mm / 1565 mrad, DISTANCE 941.8 mm, "the pose at 6.430 s lies 807.7 mm beyond any the
firmware can resume at after its stall") and told the reboot at 6.52 s (fitted). The new
firmware's boot summary (6.401 s, COUNTER 0, UPTIME 0) was taken for a frame the bus held back:
its COUNTER lay behind the old firmware's latest (7) and no in-order frame of the last eight
carried 0 -- because the old firmware's own COUNTER 0 had come late (5.821 s, after COUNTER 1)
and filled that hole. A hole is filled once: a second frame of that COUNTER repeats one heard,
so it is no held-back frame (``host.judge.livelatestatus``, one rule for the whole-log, streamed
and live judges). The reboot is now told at 6.40 s (power-up): 0.055 mm, PASS.

pmir square 645, 9 s, ``busoff=2.7:0.2,stall=4.7:0.3,delay=0.3:55``: FAIL, 19.3 mm / 31.5 mrad
off the reference (plus 0.040 mm allowance). The host took WHEEL_ENCODERS COUNTER 4 (5.000 s,
CTRL_UPTIME 6), sent while the MCU was halted, then COUNTER 15 (5.005 s, held 55 ms on the bus,
CTRL_UPTIME 5), the frame the firmware resumed on; CTRL_UPTIME "went back" between them, so the
reference re-primed on a controller restart the firmware never saw. 11 COUNTERs in 5 ms lie
beyond any window the firmware's E2E can have reached: such a pair never followed each other in
the firmware, and tells no restart (``host.judge.ctrlrestart.window_periods``, the whole-log and
streamed references' rule; the live one's ``in_window``). Now 0.049 mm, PASS.

Its tamper, +10 mm from 5.3 s (0.3 s after the stall), PASSed every analyze (0.079 mm beyond):
from COUNTER 15 on the host's numbers run a lap ahead of the sender's, and the frames it took
after it were all held back, so the refused on-time frames were numbered from a held one (5.5
periods late) a lap behind the host's numbers, and the gaps at 5.145, 5.195 and 5.285 s, which
they fill, kept ``gapbound``'s allowance (12.4 mm). A frame is never early: one numbered more
than half a lap before the least late of the 64 before it gained a lap
(``host.judge.gapfill.lapped_numbers``). Now FAIL, 9.80 mm beyond (the live judge: 9.54 mm).

kobuki circle 652, 9 s, ``busoff=3.1:0.3,stall=5.5:0.2,delay=0.3:55``: run and analyze pinned
(strict xfail, ``UNFIXED``: DISTANCE); the live judge PASSes its pose (POSE WRONG 194.5 mm before
it counted the firmware's doubted periods: ``tests/test_live_doubt.py``).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.judge.ctrlrestart import ctrl_restarts, in_window, window_periods
from odocan.host.judge.gapfill import lapped_numbers, late_seq, on_time_anchors
from odocan.host.judge.livelatestatus import StatusOrder, held_back
from odocan.host.judge.monitor import BusMonitor
from odocan.sim.robot import load
from tests.fw_watch import Watch
from tests.judges_cli import STREAMS, analyze, raw_signals, watched_run, x_10_mm_off_fails

Drive = tuple[Path, Watch, int]  # the log, the firmware's watch, run's exit code
UNFIXED = (
    "kobuki circle 652: DISTANCE 1.99 mm beyond its tolerance (44.0 mm before reprime444), the "
    "pose within 0.056 mm. The firmware is wrong (tests/test_distance_late.py): after the bus-off "
    "it integrates COUNTER 3 and 4, sent before the COUNTER 5 it had integrated (held by the "
    "delay, then by the bus-off), as steps of -104 and +52 counts after +156 where the wheels "
    "turned +104, every count forward; after the stall COUNTER 0 after 3 (-156): DISTANCE 50.0 mm "
    "above the wheels' path. A firmware that drops such a frame before its E2E check (commits "
    "ea44d5b3, a0114f90 of branch distlate, reverted) PASSes here, but the judges then read its "
    "held pose after a bus-off as a hold: kobuki random 241, delay=0.3:55,busoff=1:1,drop=0.05, "
    "a +10 mm pose step after the bus-off PASSed (1344 mm re-placement allowance; "
    "tests/test_edge_tamper.py)")
# name: (robot, scenario, seed, duration s, faults, the faults' end s: the tamper from there,
#        None or the strict xfail's reason)
DRIVES = {
    "reboot_held_hole": ("kobuki", "square", 655, 9, "stall=2.9:0.2,reboot=6.2:0.2,delay=0.1:20",
                         6.7, None),
    "stall_uptime_back": ("pmir", "square", 645, 9, "busoff=2.7:0.2,stall=4.7:0.3,delay=0.3:55",
                          6.0, None),
    "busoff_restart_run": ("kobuki", "circle", 652, 9,
                           "busoff=3.1:0.3,stall=5.5:0.2,delay=0.3:55", 5.8, UNFIXED),
}


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[str, Drive]:
    name = str(request.param)
    robot, scenario, seed, duration, faults, _, _ = DRIVES[name]
    log = tmp_path_factory.mktemp(name) / "drive.log"
    watch, code = watched_run(log, robot, scenario, seed, duration, faults)
    return name, (log, watch, code)


def test_the_firmware_integrates_the_frames_it_took(drive: tuple[str, Drive]) -> None:
    _, (_, watch, _) = drive
    assert watch.steps > 300, watch.steps
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)


def test_run_and_both_analyzes_pass_the_correct_firmware(
        drive: tuple[str, Drive], tmp_path: Path, request: pytest.FixtureRequest,
        capsys: pytest.CaptureFixture[str]) -> None:
    name, (log, _, code) = drive
    if (unfixed := DRIVES[name][6]) is not None:
        request.applymarker(pytest.mark.xfail(strict=True, reason=unfixed))
    codes = [code, *(analyze(log, s, tmp_path / f"{s}.json") for s in STREAMS)]
    out = capsys.readouterr().out
    assert codes == [0, 0, 0], out[-2500:]


def test_the_live_judge_passes_the_correct_firmware(drive: tuple[str, Drive]) -> None:
    """The monitor's judge fed the log frame by frame: its position error beyond its allowance
    within the 0.1 mm tolerance (kobuki 655: 837.6 mm before; kobuki 652: 194.5 mm before the
    live judge counted the firmware's doubted periods, ``livepose.StepGate``)."""
    name, (log, _, _) = drive
    monitor = BusMonitor(load(DRIVES[name][0]))
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    assert monitor.tracker.max_beyond_allowance_m <= 1e-4, monitor.tracker.max_beyond_allowance_m


@pytest.mark.parametrize("stream", STREAMS)
def test_plus_10_mm_after_the_faults_fails_by_the_position(
        drive: tuple[str, Drive], stream: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    name, (log, _, _) = drive
    if DRIVES[name][6] is not None:
        pytest.skip("not fixed: the untampered drive FAILs already")
    wrong = x_10_mm_off_fails(log, tmp_path / "t.log", DRIVES[name][5], 50)
    capsys.readouterr()
    assert wrong == []


# --- kobuki 655: the boot summary repeats a COUNTER the old firmware's late frame filled ------


def _status(log: Path) -> list[tuple[float, dict[str, int]]]:
    """(time s since the first ODOM_STATUS, raw signals) of the log's ODOM_STATUS frames."""
    rows = raw_signals(log, ("ODOM_STATUS",))
    return [(t - rows[0][0], {k: int(v) for k, v in s.items()}) for t, _, s in rows]


def test_655_the_boot_summary_repeats_a_counter_a_late_frame_filled(
        drive: tuple[str, Drive]) -> None:
    """The premise, from the log alone: the boot summary (UPTIME 0 after UPTIME 6, COUNTER 0)
    lies 1..7 COUNTER steps behind the old firmware's latest frame, and the old firmware's own
    COUNTER 0 came within its last lap behind a later frame (held back)."""
    name, (log, _, _) = drive
    if name != "reboot_held_hole":
        pytest.skip("kobuki 655's premise")
    status = _status(log)
    boot = next(k for k, (t, s) in enumerate(status)
                if t > 6.2 and s["PAGE"] == 0 and s["UPTIME"] == 0)
    assert status[boot][1]["COUNTER"] == 0
    assert 0 < status[boot - 1][1]["COUNTER"] <= 7
    lap = [s["COUNTER"] for _, s in status[boot - 10:boot]]
    assert lap.count(0) == 1, lap
    assert lap[lap.index(0) - 1] == 1, lap  # the old 0 came after 1
    summaries = [s for _, s in status[:boot] if s["PAGE"] == 0]
    assert summaries[-1]["UPTIME"] == 6


def test_a_hole_is_filled_once() -> None:
    """The old firmware's COUNTER 0 held behind 1 (late), its 2..7 in order, then a new
    firmware's COUNTER 0 and 1: the new 0 repeats the COUNTER the late frame filled, no held-back
    frame, and its summary (UPTIME 0 after 5) is not passed over (before: held back, so it told
    no reboot)."""
    counters = [14, 15, 1, 0, 2, 3, 4, 5, 6, 7, 0, 1]
    order = StatusOrder()
    assert [order.hear(c) for c in counters] == [False] * 3 + [True] + [False] * 8
    said: list[tuple[int, str] | None] = [(5, "OK") if c % 2 == 0 else None
                                          for c in counters[:10]]
    assert held_back(counters, [*said, (0, "OK"), None])[-2] is False
    # two late frames of other COUNTERs each fill their own hole; a third 0 after 1 again repeats
    order = StatusOrder()
    assert [order.hear(c) for c in [14, 15, 1, 0, 3, 2, 0]] == [False] * 3 + [True, False,
                                                                                True, False]


# --- pmir 645: CTRL_UPTIME "back" between frames that never followed each other on board ------


def test_645_the_host_pair_lies_beyond_any_window(drive: tuple[str, Drive]) -> None:
    """The premise, from the log alone: after the stall, a frame of CTRL_UPTIME 6 and, within
    10 ms, one of CTRL_UPTIME 5 whose COUNTER lies 11 on (the one the first pose after the
    stall names)."""
    name, (log, _, _) = drive
    if name != "stall_uptime_back":
        pytest.skip("pmir 645's premise")
    rows = raw_signals(log, ("WHEEL_ENCODERS", "ODOM_POSE_X"))
    t0 = rows[0][0]
    enc = [(t - t0, s) for t, n, s in rows if n == "WHEEL_ENCODERS" and 4.95 < t - t0 < 5.02]
    pairs = [(a, b) for a, b in itertools.pairwise(enc)
             if a[1]["CTRL_UPTIME"] == 6 and b[1]["CTRL_UPTIME"] == 5]
    assert len(pairs) == 1, enc
    (ta, a), (tb, b) = pairs[0]
    assert tb - ta < 0.01
    assert (b["COUNTER"] - a["COUNTER"]) % 16 == 11
    named = next(s for t, n, s in rows if n == "ODOM_POSE_X" and t - t0 > tb)
    assert named["ENC_COUNTER"] == b["COUNTER"]


def test_a_restart_is_told_only_within_the_firmware_s_window() -> None:
    """CTRL_UPTIME 6 then 5, young counts: a restart 11 COUNTERs on after 5 ms is none (no
    firmware took the two in a row), 1 on after 10 ms and 11 on after 300 ms (a window grown
    over a silence) are; the live rule alike."""
    uptime, young = np.array([6, 5]), np.array([True, True])
    told = [bool(ctrl_restarts(uptime, young, np.array([dt]), 0.01, np.array([4, 4 + step]))[0])
            for dt, step in ((0.005, 11), (0.01, 1), (0.3, 11))]
    assert told == [False, True, True]
    assert [in_window(11, 0.005, 0.01), in_window(1, 0.01, 0.01), in_window(0, 0.3, 0.01),
            in_window(0, 0.1, 0.01)] == [False, True, True, False]
    assert window_periods(np.array([0.0, 0.005, 0.02, 1.0]), 0.01).tolist() == [1, 2, 3, 16]


def test_refused_frames_are_numbered_as_the_host_numbered_the_lap() -> None:
    """pmir 645's numbering in small: COUNTER 0..4 on time, then COUNTER 15 held back 5.5
    periods taken as 11 ahead (number 15, a lap ahead of the sender's -1), then COUNTER 5 on
    time, refused: it is number 21 of the host's numbering (before: 5, a lap behind, so the gap
    it fills lacked it)."""
    seq = np.array([0, 1, 2, 3, 4, 15])
    time_s = np.array([0.0, 0.01, 0.02, 0.03, 0.04, 0.045])
    counter = seq % 16
    assert lapped_numbers(seq, time_s, 0.01).tolist() == [0] * 5 + [16]
    anchor = on_time_anchors((seq, time_s, counter), 0.01)
    # an on-time frame before the held one, numbered as the host numbers after it (a lap on)
    assert int(anchor[0][-1]) - round(float(anchor[1][-1]) * 100) == 16
    k = np.array([5])
    at = (anchor[0][k], anchor[1][k], anchor[2][k])
    assert late_seq(np.array([5]), np.array([0.05]), at, 0.01).tolist() == [21]
    # a frame held back (the 15 at 0.215: sent at 0.15, 6.5 periods late) gains no lap
    assert lapped_numbers(seq, np.array([0.0, 0.01, 0.02, 0.03, 0.04, 0.215]), 0.01
                          ).tolist() == [0] * 6


def test_645_plus_10_mm_right_after_the_stall_fails(
        drive: tuple[str, Drive], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    name, (log, _, _) = drive
    if name != "stall_uptime_back":
        pytest.skip("pmir 645's tamper")
    wrong = x_10_mm_off_fails(log, tmp_path / "t.log", 5.3, 50)
    capsys.readouterr()
    assert wrong == []
