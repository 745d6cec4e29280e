"""The lockstep rig end to end: determinism, the watchdog, counter wraps, the DBC's cycle times.

Frames are recorded by python-can listeners on the rig's host handle (``can.Logger``, a
``can.BufferedReader``) and decoded with cantools from the DBC, as a host tool would see them.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.ecu import (
    ENCODER_PERIOD_US,
    POSE_PERIOD_TICKS,
    RECOVERY_FRAMES,
    STATUS_PERIOD_TICKS,
    WATCHDOG_TICKS,
)
from odocan.firmware.hal import TICK_PERIOD_US
from odocan.sim.board import TICK_S, TX_LATENCY_S
from odocan.sim.contract import cycle_time_s, database, message
from odocan.sim.errors import ErrorModel
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import RobotProfile, load
from odocan.sim.scenarios import get_scenario
from tests import dbc_typed

PMIR = load("pmir")
EPS_S = 1e-6


def run_rig(
    config: RigConfig,
    seconds: float,
    listeners: list[can.Listener],
    before_tick: Callable[[LockstepRig, int], None] | None = None,
    counter_offset: tuple[int, int] = (0, 0),
) -> None:
    """Run ``config`` for ``seconds``; ``before_tick(rig, k)`` is called before each tick."""
    with LockstepRig(config, listeners) as rig:
        rig.vehicle.drivetrain.counter_offset = counter_offset
        for k in range(round(seconds / TICK_S)):
            if before_tick is not None:
                before_tick(rig, k)
            rig.step()


def recorded(config: RigConfig, seconds: float, **kwargs: Any) -> list[can.Message]:
    """Every frame of a run, in bus order."""
    reader = can.BufferedReader()
    run_rig(config, seconds, [reader], **kwargs)
    messages = []
    while (msg := reader.get_message(0)) is not None:
        messages.append(msg)
    return messages


def decode(msg: can.Message) -> dict[str, Any]:
    """Raw signal values of one frame (choices as names only for STATE and PAGE)."""
    return dict(
        dbc_typed.decode(
            database(), msg.arbitration_id, msg.data, scaling=False, decode_choices=False
        )
    )


# --- determinism -----------------------------------------------------------------------------


def _log(tmp_path: Path, name: str, seed: int) -> bytes:
    path = tmp_path / f"{name}.log"
    config = RigConfig(robot=PMIR, scenario="random", seed=seed, errors=ErrorModel(slip=0.01))
    run_rig(config, 5.0, [can.Logger(path)])
    return path.read_bytes()


def test_same_seed_gives_byte_identical_candump_logs(tmp_path: Path) -> None:
    first = _log(tmp_path, "a", seed=3)
    second = _log(tmp_path, "b", seed=3)
    other = _log(tmp_path, "c", seed=4)
    assert first.count(b"\n") > 1500  # 5 s at 3.5 frames per 10 ms
    assert first == second
    assert first != other


# --- the watchdog ----------------------------------------------------------------------------


class EncoderGate:
    """The motor controller's bus handle with a switch that swallows its WHEEL_ENCODERS frames."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.open = True

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.open or msg.arbitration_id != fr.WHEEL_ENCODERS_ID:
            self.bus.send(msg, timeout)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return self.bus.recv(timeout)


def _gated_run(gap: tuple[int, int] | None) -> list[can.Message]:
    """The straight scenario (5 s), encoder frames silenced for ticks [gap[0], gap[1])."""

    def before_tick(rig: LockstepRig, k: int) -> None:
        if k == 0:
            rig.motor_controller.bus = EncoderGate(rig.motor_controller.bus)  # type: ignore[assignment]
        gate = rig.motor_controller.bus
        assert isinstance(gate, EncoderGate)
        gate.open = gap is None or not gap[0] <= k < gap[1]

    return recorded(RigConfig(robot=PMIR, scenario="straight"), 5.0, before_tick=before_tick)


def _states(messages: list[can.Message]) -> list[tuple[float, str]]:
    """(timestamp, STATE name) of every ODOM_STATUS summary page."""
    out = []
    for msg in messages:
        if msg.arbitration_id == fr.ODOM_STATUS_ID:
            signals = dbc_typed.decode(database(), fr.ODOM_STATUS_ID, msg.data)
            if signals["PAGE"] == "SUMMARY":
                out.append((msg.timestamp, str(signals["STATE"])))
    return out


def test_watchdog_degrades_without_encoder_frames_and_recovers() -> None:
    gap = (150, 200)  # 0.5 s of silence from t = 1.5 s, the robot driving at 0.5 m/s
    messages = _gated_run(gap)
    encoders = [m.timestamp for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    last_before = max(t for t in encoders if t < gap[0] * TICK_S)
    first_after = min(t for t in encoders if t >= gap[0] * TICK_S)
    assert first_after - last_before == pytest.approx((gap[1] - gap[0] + 1) * TICK_S)
    states = _states(messages)
    status_s = STATUS_PERIOD_TICKS * TICK_S
    before = [s for t, s in states if t <= last_before]
    assert len(before) >= 10
    assert set(before[1:]) == {"OK"}
    degraded_at = min(t for t, s in states if s == "DEGRADED")
    deadline = last_before + WATCHDOG_TICKS * TICK_S + status_s + TX_LATENCY_S + EPS_S
    assert last_before < degraded_at <= deadline
    ok_again_at = min(t for t, s in states if s == "OK" and t > degraded_at)
    assert first_after < ok_again_at
    assert ok_again_at <= first_after + RECOVERY_FRAMES * TICK_S + status_s + TX_LATENCY_S + EPS_S
    assert {s for t, s in states if t >= ok_again_at} == {"OK"}


def test_first_encoder_frame_after_a_gap_carries_the_distance_driven_meanwhile() -> None:
    def final_x(messages: list[can.Message]) -> int:
        poses = [m for m in messages if m.arbitration_id == fr.ODOM_POSE_X_ID]
        return int(decode(poses[-1])["X"])

    with_gap, without = final_x(_gated_run((150, 200))), final_x(_gated_run(None))
    assert without > 19_000  # 0.1 mm: about 2 m driven
    assert abs(with_gap - without) <= 10  # 1 mm: a straight line is one step or fifty


# --- counter wraps ---------------------------------------------------------------------------


def _robot(bits: int) -> RobotProfile:
    return dataclasses.replace(PMIR, counter_bits=bits)


def _wrap_offsets(scenario: str, bits: int, margin: int) -> tuple[int, int]:
    """Counters ``margin`` counts before the wrap each wheel will drive through."""
    left, right = get_scenario(scenario, PMIR).command_at(0.1)
    top = 1 << bits
    return (
        top - margin if left > 0 else margin,
        top - margin if right > 0 else margin,
    )


def _wire_wraps(messages: list[can.Message], bits: int) -> tuple[int, int]:
    """How many times each wheel's counter wrapped on the wire (a jump of more than half its
    range: 2^15 for a 16-bit counter, 2^23 for the low 24 bits of a 32-bit one)."""
    half = 1 << (min(bits, 24) - 1)
    wraps = [0, 0]
    prev: tuple[int, int] | None = None
    for msg in messages:
        if msg.arbitration_id != fr.WHEEL_ENCODERS_ID:
            continue
        signals = decode(msg)
        now = (int(signals["LEFT_COUNT"]), int(signals["RIGHT_COUNT"]))
        if prev is not None:
            for i in (0, 1):
                wraps[i] += abs(now[i] - prev[i]) > half
        prev = now
    return wraps[0], wraps[1]


def _pose_series(messages: list[can.Message]) -> list[tuple[int, ...]]:
    """Raw (X, HEADING) and (Y, TURNS) of every pose frame, in order."""
    keys = {fr.ODOM_POSE_X_ID: ("X", "HEADING"), fr.ODOM_POSE_Y_ID: ("Y", "TURNS")}
    out = []
    for msg in messages:
        if msg.arbitration_id in keys:
            signals = decode(msg)
            out.append(tuple(int(signals[k]) for k in keys[msg.arbitration_id]))
    return out


@pytest.mark.parametrize("bits", [16, 32])
@pytest.mark.parametrize("scenario", ["spin", "straight"])
def test_pose_is_unchanged_by_counter_wraps(scenario: str, bits: int) -> None:
    config = RigConfig(robot=_robot(bits), scenario=scenario, integrator="exact")
    seconds = get_scenario(scenario, PMIR).default_duration_s
    mid = (1 << (bits - 1)) + (1 << 22)  # far from every wrap, on the wire too
    plain = recorded(config, seconds, counter_offset=(mid, mid))
    wrapping = recorded(config, seconds, counter_offset=_wrap_offsets(scenario, bits, 300))
    assert _wire_wraps(plain, bits) == (0, 0)
    # Each wheel wraps once; a 32-bit counter crosses 2^32 (or 0) where its 24-bit wire wraps.
    assert _wire_wraps(wrapping, bits) == (1, 1)
    a, b = _pose_series(plain), _pose_series(wrapping)
    assert len(a) == len(b) > 100
    worst = max(abs(p - q) for u, v in zip(a, b, strict=True) for p, q in zip(u, v, strict=True))
    assert worst <= 1  # raw LSBs of X, Y (0.1 mm), HEADING (BAM16), TURNS
    moved = max(abs(u[0]) for u in a[0::2]) if scenario == "straight" else len({u[1] for u in a})
    assert moved > 100


# --- the DBC's cycle times -------------------------------------------------------------------


def test_firmware_cycle_constants_agree_with_the_dbc() -> None:
    def cycle_us(name: str) -> int:
        cycle_ms = message(name).cycle_time  # GenMsgCycleTime
        assert cycle_ms is not None, name
        return int(cycle_ms) * 1000

    assert cycle_us("WHEEL_ENCODERS") == ENCODER_PERIOD_US == TICK_PERIOD_US
    for name in ("ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST"):
        assert cycle_us(name) == POSE_PERIOD_TICKS * TICK_PERIOD_US, name
    assert cycle_us("ODOM_STATUS") == STATUS_PERIOD_TICKS * TICK_PERIOD_US


RIG_CYCLIC = (
    "WHEEL_ENCODERS",
    "MOTOR_CMD",
    "ODOM_POSE_X",
    "ODOM_POSE_Y",
    "ODOM_TWIST",
    "ODOM_STATUS",
    "SIM_TRUTH",
)


def test_rig_frames_keep_the_dbc_cycle_times() -> None:
    messages = recorded(RigConfig(robot=PMIR, scenario="circle"), 3.0)
    instants: dict[int, set[float]] = defaultdict(set)
    for msg in messages:
        instants[msg.arbitration_id].add(round(msg.timestamp, 6))
    for name in RIG_CYCLIC:
        times = sorted(instants[database().get_message_by_name(name).frame_id])
        assert len(times) >= 10, name
        periods = {round(b - a, 6) for a, b in itertools.pairwise(times)}
        assert periods == {cycle_time_s(name)}, name
