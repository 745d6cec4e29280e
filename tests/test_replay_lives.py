"""``odocan replay`` lives a log's firmware reboot (issue #11, ``host.judge.replay_lives``).

Lockstep runs of pmir on the circle (``tests.test_first_second_reboot.drive``: the MCU reset by
``FirmwareBoard.reboot`` at tick 300, 3 s into a 4 s drive), every frame heard. The correct
firmware is shown correct independently of the judges (``tests.independent_checker``: float64
odometry of the tests, restarted at (0, 0, 0) on the frame it primed on after the reset). A
replay that ran one firmware life across the reset FAILed that correct firmware (its poses
after the reset 1.3 m off the replay's); lived life by life, each life is compared on its own
and the two agree frame for frame: PASS, exit 0.

A wrong firmware still FAILs (exit 1, a FAIL line naming the departure, never UNJUDGED): one
pose of the log tampered (X +10 mm or +1 m, re-encoded with cantools, its E2E CRC fixed with
the frame's own COUNTER), in a log without reboots and in the life after the reboot; and every
pose of the life after the reboot 10 mm off (a life compared as a log cut mid-drive, re-anchored
on its first poses, absorbed that and PASSed).

A log whose recorder started 0.5 s before the MCU's power-up, every ODOM_STATUS stamped 50 ms
late (a gateway: ``tests.test_powerup_primed_late``): the status frames put the priming frame 5
frames late, where the replay, comparing nothing (UNJUDGED), or re-anchored, PASSed a firmware
1 m off (before 0a4f51d5). The first life is now tried from a few frames before too
(``replay_lives.fit_first_prime``): the correct firmware is identical from the frame it primed
on (its FIFO drained at its first tick, 1.00 s, it primes on the next frame: 0.51 s into the
log); one 10 mm or 1 m off FAILs.
"""

from __future__ import annotations

import functools
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests import host_frames as hf
from tests import independent_checker as ic
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import (
    DB,
    _decoded,
    _reset_seen,
    _robot,
    _written,
    _wrong,
    drive,
)
from tests.test_powerup_primed_late import _status_late
from tests.test_stall_beyond_window import PMIR

REBOOT_TICK = 300  # 3.00 s: mid-drive
NO_REBOOT = 10**6  # past the drive's end: one life
LSB_PER_M = 10_000  # ODOM_POSE_X: 0.1 mm
POWER_UP_TICK = 100  # the MCU's first tick; the recorder starts 50 ticks before
STATUS_LATE_S = 0.05


def _one_pose_off(messages: tuple[can.Message, ...], after_s: float,
                  bias_lsb: int) -> tuple[can.Message, ...]:
    """The frames with the first ODOM_POSE_X at or after ``after_s`` ``bias_lsb`` off (E2E
    re-protected with the frame's own COUNTER): a firmware wrong at one pose."""
    out, done = [], False
    for m in messages:
        if not done and m.arbitration_id == fr.ODOM_POSE_X_ID and m.timestamp >= after_s:
            signals = _decoded(m)
            signals["X"] += bias_lsb
            data = bytearray(DB.encode_message(m.arbitration_id, signals, scaling=False))
            hf.p02_protect(data, int(signals["COUNTER"]), fr.ODOM_POSE_X_DATA_IDS)
            m = can.Message(arbitration_id=m.arbitration_id, data=bytes(data),
                            is_extended_id=False, timestamp=m.timestamp)
            done = True
        out.append(m)
    assert done
    return tuple(out)


def _replayed(capsys: pytest.CaptureFixture[str], path: Path) -> tuple[int, list[str]]:
    """``odocan replay`` of ``path``: its exit code and its verdict lines."""
    code = main(["replay", str(path), "--robot", "pmir", "--integrator", "exact"])
    out = capsys.readouterr().out
    return code, [line for line in out.splitlines()
                  if line.startswith(("replay:", "FAIL", "UNJUDGED", "  - "))]


def test_a_correct_firmware_rebooted_mid_drive_replays_identical_life_by_life(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    messages = drive(REBOOT_TICK)
    path = _written(messages, tmp_path / "reboot.log")
    own = ic.check(path, _robot(), "exact", lambda _t: (0.0, 0.0, 0.0),
                   reboots_t_s=[_reset_seen(messages, REBOOT_TICK)])
    assert own.samples > 100
    assert own.passed  # the firmware is correct across its reset
    code, lines = _replayed(capsys, path)
    assert code == 0, lines
    assert not any(line.startswith(("FAIL", "UNJUDGED")) for line in lines), lines
    lives = [line for line in lines if line.startswith("replay: life ")]
    assert len(lives) == 2, lines
    assert lives[1].startswith("replay: life 1 from t=3.00 s (a fresh firmware)"), lines
    for life in lives:
        assert "max difference 0.0000 mm, 0.0000 mrad" in life, lines


@pytest.mark.parametrize("bias_m", [0.010, 1.0])
@pytest.mark.parametrize(("reboot_tick", "after_s"), [(NO_REBOOT, 2.0), (REBOOT_TICK, 3.5)])
def test_one_wrong_pose_fails_the_replay(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], bias_m: float, reboot_tick: int,
    after_s: float
) -> None:
    """``after_s`` 3.5: in the life after the reboot (the reset at 3.00 s)."""
    messages = drive(reboot_tick)
    right = _written(messages, tmp_path / "right.log")
    assert _replayed(capsys, right)[0] == 0  # the control: the untampered log PASSes
    wrong = _written(_one_pose_off(messages, after_s, round(bias_m * LSB_PER_M)),
                     tmp_path / "wrong.log")
    code, lines = _replayed(capsys, wrong)
    assert code == 1, lines
    assert "FAIL: the replayed firmware departs from the log's" in lines, lines
    assert not any(line.startswith("UNJUDGED") for line in lines), lines
    said = [line for line in lines if "its position differs from the log's" in line]
    assert said, lines
    if reboot_tick == REBOOT_TICK:
        assert all(line.startswith("  - life 1 (from t=3.00 s)") for line in said), lines


def test_every_pose_of_the_life_after_the_reboot_off_fails_the_replay(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    wrong = _written(_wrong(drive(REBOOT_TICK), REBOOT_TICK, round(0.010 * LSB_PER_M)),
                     tmp_path / "wrong.log")
    code, lines = _replayed(capsys, wrong)
    assert code == 1, lines
    assert "FAIL: the replayed firmware departs from the log's" in lines, lines
    assert any(line.startswith("  - life 1 (from t=3.00 s): its position differs from the log's"
                               " by up to 10.0000 mm") for line in lines), lines


@functools.cache
def powered_up_in_the_log() -> tuple[can.Message, ...]:
    """pmir on the circle, the MCU halted for its first second, its FIFO drained at its first
    tick (it primes on the next frame); the frames from 0.5 s before that tick on, 3 s, every
    ODOM_STATUS ``STATUS_LATE_S`` late."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario("circle", PMIR, duration_s=60.0)) as rig:
        def drain(k: int) -> None:
            if k == POWER_UP_TICK:
                while rig.fw_bus.recv(0) is not None:
                    pass
        rig.observers.append(
            lambda k, got: heard.extend(got) if k >= POWER_UP_TICK - 50 else None)
        rig.before_board.append(drain)
        rig.halted = lambda k: k < POWER_UP_TICK
        rig.run(POWER_UP_TICK * TICK_S + 3.0)
    return _status_late(tuple(heard), STATUS_LATE_S)


@pytest.mark.parametrize("bias_m", [0.0, 0.010, 1.0])
def test_a_power_up_in_the_log_is_replayed_from_the_frame_it_primed_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], bias_m: float
) -> None:
    messages = powered_up_in_the_log()
    if bias_m:
        messages = _wrong(messages, 0, round(bias_m * LSB_PER_M))
    code, lines = _replayed(capsys, _written(messages, tmp_path / "powerup.log"))
    if not bias_m:
        assert code == 0, lines
        assert any(line.startswith("replay: life 0 from t=0.51 s (a fresh firmware)") and
                   line.endswith("identical, max difference 0.0000 mm, 0.0000 mrad")
                   for line in lines), lines
        assert not any(line.startswith(("FAIL", "UNJUDGED")) for line in lines), lines
        return
    assert code == 1, lines
    assert "FAIL: the replayed firmware departs from the log's" in lines, lines
    assert not any(line.startswith("UNJUDGED") for line in lines), lines
    assert any(line.startswith("  - life 0 (from t=") and
               "its position differs from the log's" in line for line in lines), lines
