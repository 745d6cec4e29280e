"""A campaign for the no-re-placement rule (``host.judge.gapseen``, issue #11, rule 5): on odd
robots (a 1 cm wheelbase with 16-bit counters; a 2 m one with 32-bit counters and unequal
wheels), random bus faults on the motor controller's frames (bursts, drops, duplicates, delays,
bit flips), a firmware stalled (its MCU halted, its mailbox overrun) and a motor controller
stalled (silent, then on with or without a catch-up frame), drawn from a seed:

* the correct firmware never FAILs, whole log and streamed (the rule must never blame it);
* a firmware that wraps its steps of more than half a turn, or drops steps of more than
  ``BIG_COUNTS`` counts, FAILs whenever its pose is wrong: its final pose more than ``WRONG_M``
  from the correct firmware's on the same drive (the lockstep rig is deterministic: the same
  seed, the same frames; the correct firmware's own pose is not dead reckoning of every count,
  it merges the steps the bus lost for it too); behind frames lost only (no frame refused:
  the firmware's pages then prove what it took), its position alone FAILs it. Before the rule
  the gaps' allowances absorbed it (its TURNS still failed a wrapping one);
* the live judge (the monitor's model and the bridge, ``host.judge.livegapseen``) fed the same
  log says what ``analyze`` says: a POSE WRONG latched exactly when it FAILs.
"""

from __future__ import annotations

import math
import random
from pathlib import Path

import can
import pytest

import odocan.firmware.odometry as odometry
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.sim.board import TICK_S
from odocan.sim.faultspec import FaultSpec
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.sweeps import sample
from tests.test_sender_stall_drop import live_judges
from tests.test_sender_stall_step import _streamed
from tests.test_wrap_after_gaps import ONE_CM_TOML, _wrapping_firmware

WIDE_TOML = """name = "wide32"
counts_per_rev = 4096
wheel_radius_left_m = 0.05
wheel_radius_right_m = 0.0502
wheelbase_m = 2.0
counter_bits = 32
"""
DRIVE_TICKS = 1500  # 15 s
BIG_COUNTS = 40  # the step-dropping firmware integrates no step of more counts than this
WRONG_M = 0.001  # a final pose this far from the correct firmware's is wrong


SEEDS = range(12)  # even: the 1 cm robot; from QUIET_FROM: losses only (no frame refused)
QUIET_FROM = 6


def _faults(rng: random.Random, quiet: bool) -> str:
    """Random bus faults on the motor controller's frames; ``quiet``: frames lost only (in
    bursts and alone), none the firmware would refuse (duplicated, delayed, flipped)."""
    lost = f"burst={rng.uniform(0.01, 0.06):.3f}:{rng.randint(2, 10)}," \
           f"drop={rng.uniform(0.0, 0.02):.3f},seed={rng.randint(0, 999)}"
    if quiet:
        return lost
    return (f"{lost},dup={rng.uniform(0.0, 0.01):.3f},"
            f"delay={rng.uniform(0.0, 0.01):.3f}:{rng.randint(2, 30)},"
            f"flip={rng.uniform(0.0, 0.01):.3f}")


def _drive(tmp_path: Path, seed: int, firmware: str,
           monkeypatch: pytest.MonkeyPatch) -> tuple[tuple[int, int], Path, Path]:
    """One drive drawn from ``seed`` with ``firmware`` (correct, wrap, drop): the firmware's
    final position (Q40 m), the bus's log and the robot's profile."""
    rng = random.Random(seed)
    robot = tmp_path / f"robot{seed}.toml"
    robot.write_text(ONE_CM_TOML if seed % 2 == 0 else WIDE_TOML)
    if firmware == "wrap":
        _wrapping_firmware(monkeypatch)
    elif firmware == "drop":
        whole = odometry.Odometry.step_deltas

        def step_deltas(self: odometry.Odometry, d_left: int, d_right: int) -> None:
            if max(abs(d_left), abs(d_right)) <= BIG_COUNTS:
                whole(self, d_left, d_right)

        monkeypatch.setattr(odometry.Odometry, "step_deltas", step_deltas)
    halt_at, halt_n = rng.randint(300, 1000), rng.choice([0, rng.randint(20, 150)])
    mute_at, mute_n = rng.randint(300, 1000), rng.choice([0, rng.randint(20, 150)])
    catch_up = rng.random() < 0.5
    heard: list[can.Message] = []
    profile = load(robot)
    scenario = get_scenario("random", profile, seed=seed, duration_s=DRIVE_TICKS * TICK_S)
    with FaultRig(robot=str(robot), scenario=scenario,
                  sim_faults=FaultSpec.parse(_faults(rng, seed >= QUIET_FROM)), seed=seed) as rig:
        rig.observers.append(lambda _k, frames: heard.extend(frames))
        rig.halted = lambda k: halt_at <= k < halt_at + halt_n
        send = rig.sim.tick

        def tick(k: int) -> None:
            if not mute_at <= k < mute_at + mute_n:
                send(k)
            if catch_up and mute_n and k == mute_at + mute_n:
                rig.sim.motor_controller.sample_and_send()

        rig.sim.tick = tick  # type: ignore[method-assign]
        rig.run(DRIVE_TICKS * TICK_S)
        odo = rig.ecu.odometry
        final = (odo.x_q40_m, odo.y_q40_m)
    path = tmp_path / f"drive{seed}-{firmware}.log"
    path.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                            f"{m.data.hex().upper()}\n" for m in heard))
    return final, path, robot


def _verdicts(path: Path, robot: Path) -> tuple[bool, float, bool]:
    """analyze's verdict and its position error beyond the allowance (m), whole log, and
    whether the streamed judge (``--stream always``: a life the stream cannot judge goes to the
    whole-log judge) and the live judges (no POSE WRONG latched: a pass) say the same."""
    result = analyze(read_log(path), load(robot), "exact")
    onboard = result.report["onboard_vs_reference"]
    same = _streamed(path, path.parent, str(robot)) == onboard
    for name, tracker in live_judges(path, robot):
        live = (tracker.wrongs.count == 0, tracker.max_beyond_allowance_m > POSITION_LSB_M)
        assert live == (result.passed, onboard["max_position_error_beyond_allowance_m"]
                        > POSITION_LSB_M), (name, tracker.wrongs.summary(), onboard)
    return result.passed, onboard["max_position_error_beyond_allowance_m"], same


@pytest.mark.parametrize("seed", SEEDS)
def test_a_correct_firmware_never_fails(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        seed: int) -> None:
    _, path, robot = _drive(tmp_path, seed, "correct", monkeypatch)
    passed, _, same = _verdicts(path, robot)
    assert passed
    assert same


@pytest.mark.parametrize(("seed", "firmware"), sample(  # tests.sweeps
    [(seed, firmware) for seed in SEEDS for firmware in ("wrap", "drop")], 3,
    [(0, "wrap"), (1, "drop"), (QUIET_FROM, "wrap"), (QUIET_FROM + 1, "drop")]))
def test_a_wrong_firmware_fails_when_its_pose_is_wrong(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, seed: int, firmware: str
) -> None:
    (tmp_path / "right").mkdir()
    right, _, _ = _drive(tmp_path / "right", seed, "correct", monkeypatch)
    wrong, path, robot = _drive(tmp_path, seed, firmware, monkeypatch)
    passed, beyond_m, same = _verdicts(path, robot)
    assert same
    error_m = math.hypot(wrong[0] - right[0], wrong[1] - right[1]) / 2**40
    if error_m > WRONG_M:
        assert not passed, error_m
        if seed >= QUIET_FROM:  # its position alone FAILs it (not only its TURNS)
            assert beyond_m > POSITION_LSB_M, error_m
