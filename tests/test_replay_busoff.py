"""``odocan replay`` of a bus-off: the replayed firmware lives it as the recording one did, so a
correct firmware's log replays PASS and its bus is the log's, and a pose raised 10 mm after the
bus-off FAILs (issue #11 item 4, rule 5).

Found by the outside trial: kobuki random 516, 10 s, ``busoff=4.0:0.3`` (the bus silent
3.99 .. 4.31 s, run and analyze PASS) replayed UNJUDGED, exit 1, "none of the log's 484 on-board
poses could be paired". Three causes, each one a way the replay's firmware lived another bus:

* the encoder frame after the 32-period silence has the COUNTER of the one before it (two whole
  laps); the replay's numbering took a step of 0 for 1 and added the laps to it, 33 periods, so
  every pose after named a frame one tick off, the pose phase was voted odd, and the replay
  paired none (``replay_track.encoder_ticks``);
* the replayed board, bus-off, still put its poses and status on the bus, where the recording
  one's were refused: the judge of the replayed bus read poses inside the gap and FAILed it by
  0.1003 mm (``replay_deaf.DeafBus``);
* the bus-off was replayed deaf up to the firmware's first frame after it (a pose period after
  the recovery), so the encoder frame of 4.31 s, which the recording firmware took (its E2E
  check counted a repeated COUNTER), was lost (``replay_arrival._bus_back``).

Replayed right, the log with its poses raised 10 mm from the first one after the bus-off then
PASSed: the offset's jump across the bus-off's hole was held to the gap bound of its 32 periods,
121.8 mm, although a bus-off firmware heard nothing there and took the gap as the replay's one
merged step (``replay_jumps.JumpModel.deaf_through``).

The firmware is proven right by the tests' watch (every step integrated again in float64,
``tests.fw_watch``), not by the judges; the log is read back with python-can, the tamper made
with cantools (``tests.log_edit``).
"""

from __future__ import annotations

from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.judge.replay_track import encoder_ticks
from odocan.sim import contract
from tests.judges_cli import cli, correct_drive, raise_x_10_mm

FIRMWARE_IDS = {m.frame_id for m in contract.database().messages if m.senders == ["ODOM_MCU"]}
DRIVE = ("kobuki", "random", 516, 10, "busoff=4.0:0.3")
BUS_OFF_S = (4.0, 4.31)


def _firmware_frames(log: Path) -> list[tuple[float, int, bytes]]:
    return [(round(m.timestamp, 6), m.arbitration_id, bytes(m.data))
            for m in can.LogReader(str(log)) if m.arbitration_id in FIRMWARE_IDS]


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The drive recorded by the Python firmware, watched: it must be right."""
    log = tmp_path_factory.mktemp("busoff") / "drive.log"
    correct_drive(log, *DRIVE)
    return log


def test_a_silence_of_whole_counter_laps_is_numbered_by_its_periods() -> None:
    period_s = contract.cycle_time_s("WHEEL_ENCODERS")
    for laps in (1, 2, 5):
        times = np.array([0.0, period_s, period_s * (1 + 16 * laps)])
        ticks = encoder_ticks(times, np.array([14, 15, 15], dtype=np.int64))
        assert ticks.tolist() == [0, 1, 1 + 16 * laps]


def test_the_correct_firmware_replays_pass_and_its_bus_is_the_logs(drive: Path,
                                                                   tmp_path: Path) -> None:
    replayed = tmp_path / "replayed.log"
    done = cli("replay", str(drive), "--log", str(replayed))
    assert done.returncode == 0, done.stdout[-2500:]
    logged = _firmware_frames(drive)
    # the bus-off is in the log: the firmware sent nothing while it lasted
    assert not [f for f in logged if BUS_OFF_S[0] < f[0] < BUS_OFF_S[1]]
    assert len(logged) > 1500
    assert _firmware_frames(replayed) == logged


@pytest.mark.parametrize("from_s", [4.2, 4.5])  # from the first pose after it; mid-stretch
def test_plus_10_mm_from_after_the_bus_off_fails(drive: Path, tmp_path: Path,
                                                 from_s: float) -> None:
    out = tmp_path / "raised.log"
    assert raise_x_10_mm(drive, out, from_s) > 50
    done = cli("replay", str(out))
    assert done.returncode == 1, done.stdout[-2500:]
    assert "FAIL" in done.stdout
