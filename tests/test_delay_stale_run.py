"""A correct firmware locked on a stale run of encoder frames is not FAILed (issue #11, rule 5).

``odocan run --robot kobuki --scenario figure8 --seed 843 --duration 9 --faults delay=0.1:200``:
from 4.26 s WHEEL_ENCODERS frames held back 200 ms (20 periods, 4 back on the 4-bit COUNTER)
came among the on-time ones, and the firmware's E2E window locked on them: it took the late
COUNTER 0, 3, 8 to 12, 15 (4.36 to 4.51 s), 9 (4.61 s) and 7 (4.75 s), refused the on-time ones
between (WRONG_SEQUENCE; the on-time 9 at 4.73 s REPEATED), and took the on-time 8 at 4.88 s,
a step of 1312 / 1783 counts it judged again over the periods since the late 9's sample
(firmware/sampledoubt.py): no COUNTER_RESET. Its every step is within 1/1000 LSB of the float64
arc (``tests.fw_watch``), 0.25 mm off the truth.

The judges FAILed it at 288.6 mm / 291.5 mrad (whole and streamed) and 289.5 mm (live):

* ``e2e_evidence.sent_times`` read an ODOM_POSE_Y held back 10 sends (200 ms) as sent 7 ahead,
  and the on-time ones after it as late; a late one naming the firmware's ENC_COUNTER 15 of the
  late frame of 4.51 s then "proved" the on-time COUNTER 15 of 4.63 s taken: the host took the
  10 on-time frames the firmware refused, and its reference re-primed at 4.63 and 4.88 s where
  the firmware did not. Such a frame (``lapped``, as ``latenames.LateScan`` reads it) now
  proves nothing.
* The live step gate (``livepose.StepGate``) had no second chance over the doubted periods:
  it refused the 4.88 s step over 17 periods and re-primed at 4.90 s (136.9 mm off).

The firmware's own E2E record is the reference for the host's encoder verdicts; the poses are
the Python firmware's, each step watched.
"""

from __future__ import annotations

from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.e2e_evidence import send_readings
from odocan.sim.robot import load
from tests.fw_e2e import firmware_verdicts, host_disagreements
from tests.judges_cli import both_analyses, correct_drive, x_10_mm_off_fails

DRIVE = ("kobuki", "figure8", 843, 9, "delay=0.1:200")


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[bool]]:
    """The drive, recorded by the watched Python firmware (run exits 0: it FAILed before), and
    whether the firmware's E2E receiver took each WHEEL_ENCODERS frame, in bus order."""
    log = tmp_path_factory.mktemp("stale") / "drive.log"
    with firmware_verdicts() as verdicts:
        correct_drive(log, *DRIVE)
    return log, verdicts


def test_the_host_takes_the_encoder_frames_the_firmware_took(
        drive: tuple[Path, list[bool]]) -> None:
    """``check_frames`` takes exactly the frames the firmware's receiver took (it took the 10
    on-time frames of 4.63 to 4.72 s the firmware refused)."""
    log, firmware = drive
    encoder_frames, wrong = host_disagreements(log, firmware)
    assert encoder_frames == len(firmware) > 800
    assert sum(firmware) < len(firmware) - 100  # the delay makes it refuse many
    assert wrong == []


def test_analyze_passes_it_whole_and_streamed(drive: tuple[Path, list[bool]]) -> None:
    """Both analyses PASS the correct firmware (both FAILed it at 288.6 mm)."""
    assert both_analyses(drive[0]) == [0, 0]


def test_the_live_judge_passes_it(drive: tuple[Path, list[bool]]) -> None:
    """The monitor model: its pose vs its reference within one LSB each (289.5 mm, then
    136.9 mm with the evidence fixed alone)."""
    monitor = BusMonitor(load("kobuki"))
    with can.LogReader(str(drive[0])) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    ref = monitor.tracker.vs_reference
    assert ref.max_dpos_m <= POSITION_LSB_M
    assert ref.max_dheading_rad <= HEADING_LSB_RAD
    assert monitor.tracker.counter_restarts == 0  # the firmware never re-primed


def test_a_wrong_pose_after_the_stale_run_still_fails(drive: tuple[Path, list[bool]],
                                                      tmp_path: Path) -> None:
    """No new false PASS: every ODOM_POSE_X after 5 s raised 10 mm FAILs both analyses by the
    position."""
    assert x_10_mm_off_fails(drive[0], tmp_path / "tampered.log", 5.0, 100) == []


def test_a_pose_frame_held_back_a_lap_half_is_not_read() -> None:
    """A 20 ms sender's frame held back 10 sends (as the drive's ODOM_POSE_Y at 4.701 s): its
    COUNTER reads 7 ahead of the frame before it, a period after it. It is not read (the third
    list), and the on-time frames after it stay in order, heard when sent."""
    period = 0.02
    sends = list(range(20, 30))
    stamps = [k * period for k in sends]
    counters = [k % 16 for k in sends]
    at = 4  # after send 23, the frame of send 14 (10 sends back), heard with 24
    stamps.insert(at, stamps[at - 1] + period)
    counters.insert(at, 14 % 16)
    ordered, sent, unread = send_readings(np.array(stamps), np.array(counters, dtype=np.int64),
                                          period)
    assert unread == [k == at for k in range(len(stamps))]
    assert all(ordered[k] for k in range(len(stamps)) if k != at)
    assert [s for k, s in enumerate(sent) if k != at] == pytest.approx(
        [s for k, s in enumerate(stamps) if k != at])
