"""Pose frames late on the bus prove nothing of the encoder frames (issue #11, rule 5).

``e2e_evidence.pose_evidence`` reads the place of a pose frame on the bus as the time the
firmware sent it. Under ``delay=0.5:150`` (kobuki, seed 703, 4 s) the ODOM_POSE_X frames sent at
0.361 and 0.421 s were both heard 150 ms late, the second naming ENC_COUNTER 7: the evidence took
the on-time WHEEL_ENCODERS COUNTER 7 at 0.55 s for the frame it named (it named the 7 at
0.39 s) and made the host take it, where the firmware had refused it (its window 0 after the late
COUNTER 8 it took first); the reference integrated it and analyze FAILed the correct firmware
209 mm / 183 mrad off. The firmware's own record (its receiver's statuses, which the judges
never see) is the reference here: the host's E2E must take exactly the frames it took.
"""

from __future__ import annotations

import random
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.e2e_evidence import heard_in_order, sent_times
from odocan.sim.robot import load
from tests.fw_e2e import firmware_verdicts, host_disagreements


def _firmware_verdicts(log: Path, seed: int, faults: str) -> list[bool]:
    """Run the Python firmware; whether its E2E receiver took each WHEEL_ENCODERS frame it
    checked, in the order it checked them (the bus order)."""
    with firmware_verdicts() as verdicts:
        main(["run", "--robot", "kobuki", "--duration", "4", "--seed", str(seed), "--faults",
              faults, "--firmware", "python", "--log", str(log)])
    return verdicts


# 703: the drive above; 1 to 6: the sweep (their FAILs left are the placements',
# tests/test_combo_faults.py)
@pytest.mark.parametrize(("seed", "faults"), [(703, "delay=0.5:150"), *(
    (seed, "delay=0.5:150") for seed in range(1, 7)), (6, "delay=0.5:100")])
def test_the_host_takes_the_encoder_frames_the_firmware_took(
        seed: int, faults: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "drive.log"
    firmware = _firmware_verdicts(log, seed, faults)
    capsys.readouterr()
    encoder_frames, wrong = host_disagreements(log, firmware)
    assert encoder_frames == len(firmware) > 300
    assert sum(firmware) < len(firmware) - 100  # the delay makes it refuse many
    assert wrong == []


def test_the_live_judge_passes_it_too(tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """The monitor model (live): its pose vs its reference within one LSB each (it was 124 mm
    and 183 mrad off the correct firmware; the whole and streamed judges:
    ``tests/test_combo_faults.py``)."""
    log = tmp_path / "drive.log"
    main(["run", "--robot", "kobuki", "--duration", "4", "--seed", "703", "--faults",
          "delay=0.5:150", "--firmware", "python", "--log", str(log)])
    capsys.readouterr()
    monitor = BusMonitor(load("kobuki"))
    with can.LogReader(log) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    ref = monitor.tracker.vs_reference
    assert ref.max_dpos_m <= POSITION_LSB_M
    assert ref.max_dheading_rad <= HEADING_LSB_RAD


def test_heard_in_order_against_the_sends() -> None:
    """A 20 ms sender whose frames are each held back 150 ms with probability 0.5 (or 15 ms,
    or not at all): a frame is in order when no frame heard before it was sent after it, told
    here from the send numbers the bus order hides."""
    rng = random.Random(11)
    period = 0.02
    sends = [(k * period + rng.choice((0.0, 0.0, 0.015, 0.15)), k) for k in range(400)]
    heard = sorted(sends)  # bus order: by the time each frame came (no two alike)
    top, expected, expected_s = -1, [], []
    for t, k in heard:
        expected.append(k > top)
        if k > top:
            top, top_late = k, t - k * period
        # a late one: sent k * period, taken as sent as late as the latest-sent heard before
        expected_s.append(t if k == top else k * period + top_late)
    stamps = np.array([t for t, _ in heard])
    counters = np.array([k % 16 for _, k in heard], dtype=np.int64)
    got = heard_in_order(stamps, counters, period)
    assert got == expected
    assert 50 < expected.count(False) < 250  # the late ones: the test sees some of each
    assert sent_times(stamps, counters, period)[1] == pytest.approx(expected_s, abs=1e-9)


def test_a_repeat_is_not_in_order() -> None:
    stamps = np.array([0.0, 0.02, 0.02, 0.04])
    assert heard_in_order(stamps, np.array([3, 4, 4, 5], dtype=np.int64), 0.02) == [
        True, True, False, True]
