"""``sim.lookahead.PlannedVehicle`` is a plain ``Vehicle`` call for call, bit for bit: while its
forecast holds, when it misses (a command it did not predict, one that never came, other speeds,
a time off the tick grid, a read of the drivetrain's state), with slip noise and a truth trace;
and the lockstep rig's frames do not depend on it."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest

from odocan.host.io.logs import FrameCollector
from odocan.sim import lookahead
from odocan.sim.errors import ErrorModel
from odocan.sim.lookahead import BLOCK_TICKS, PlannedVehicle
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from odocan.sim.vehicle import Vehicle

TICK_S = 0.01
ERRORS = ErrorModel(ed=1.002, eb=1.01, slip=0.01)


def speeds(k: int) -> tuple[float, float]:
    """A drive with turns, a hard start (rate-limited) and whole mm/s, as MOTOR_CMD carries."""
    t = k * TICK_S
    left = round(1000 * (0.4 + 0.3 * math.sin(0.7 * t))) / 1000.0
    right = round(1000 * (0.4 + 0.3 * math.sin(1.3 * t + 1.0))) / 1000.0
    return left, right


def forecast(k: int, t_s: float) -> tuple[float, float] | None:
    return speeds(k) if k % 2 == 0 else None


Call = Callable[[Vehicle, int], None]


def rig_tick(vehicle: Vehicle, k: int) -> None:
    """The lockstep rig's calls in tick k: the driver's command, the sample, a truth at 10."""
    t_s = 0.0 + k * TICK_S
    if k % 2 == 0:
        vehicle.command(*speeds(k), t_s)
    vehicle.advance_to(t_s)


def observe(vehicle: Vehicle, ticks: int, tick: Call = rig_tick) -> list[object]:
    """Every tick's encoder counts, every tenth tick's truth (as the rig reads them)."""
    seen: list[object] = []
    for k in range(ticks):
        tick(vehicle, k)
        seen.append(vehicle.encoder_counts())
        if k % 10 == 3:
            seen.append(vehicle.truth())
    return seen


def pair(trace_hz: int = 0) -> tuple[Vehicle, PlannedVehicle]:
    profile = load("pmir")
    plain = Vehicle(profile, ERRORS, seed=5, trace_hz=trace_hz)
    planned = PlannedVehicle(profile, ERRORS, seed=5)
    if trace_hz:  # the same truth with a trace, as a plain Vehicle(trace_hz=...) keeps it
        planned._truth = type(planned._truth)(
            planned.actual_wheelbase_m, planned.substep_hz, trace_stride=1000 // trace_hz
        )
    planned.plan(forecast, TICK_S)
    return plain, planned


def test_a_held_forecast_gives_the_plain_vehicle_s_counts_and_poses_bit_for_bit() -> None:
    plain, planned = pair()
    ticks = 3 * BLOCK_TICKS + 17
    assert observe(planned, ticks) == observe(plain, ticks)
    assert not planned.fell_back
    assert planned.t_s == plain.t_s


def extra_command(vehicle: Vehicle, k: int) -> None:
    rig_tick(vehicle, k)
    if k == BLOCK_TICKS + 31:  # the firmware or the host sends MOTOR_CMD: not predicted
        vehicle.command(-0.2, 0.3, k * TICK_S)


def missing_command(vehicle: Vehicle, k: int) -> None:
    t_s = k * TICK_S
    if k % 2 == 0 and k != 2 * BLOCK_TICKS - 40:  # a MOTOR_CMD lost on the way
        vehicle.command(*speeds(k), t_s)
    vehicle.advance_to(t_s)


def other_speeds(vehicle: Vehicle, k: int) -> None:
    t_s = k * TICK_S
    if k % 2 == 0:
        left, right = speeds(k)
        vehicle.command(left, right + (0.001 if k == 150 else 0.0), t_s)
    vehicle.advance_to(t_s)


def off_grid(vehicle: Vehicle, k: int) -> None:
    rig_tick(vehicle, k)
    if k == 77:
        vehicle.advance_to(k * TICK_S + 0.004)


def command_off_grid(vehicle: Vehicle, k: int) -> None:
    rig_tick(vehicle, k)
    if k == 140:
        vehicle.command(0.1, 0.1, k * TICK_S + 0.005)


def speeds_read(vehicle: Vehicle, k: int) -> None:
    rig_tick(vehicle, k)
    if k == 260:
        assert vehicle.wheel_speeds_mps()[0] > 0.0


@pytest.mark.parametrize(
    "tick", [extra_command, missing_command, other_speeds, off_grid, command_off_grid, speeds_read]
)
def test_a_missed_forecast_falls_back_to_the_plain_vehicle_bit_for_bit(tick: Call) -> None:
    plain, planned = pair()
    ticks = 3 * BLOCK_TICKS
    assert observe(planned, ticks, tick) == observe(plain, ticks, tick)
    assert planned.fell_back
    # and the noise stream carries on where the plain vehicle's is
    assert planned._rng.standard_normal() == plain._rng.standard_normal()


def test_the_truth_trace_is_the_plain_vehicle_s() -> None:
    plain, planned = pair(trace_hz=100)
    observe(plain, 2 * BLOCK_TICKS + 5)
    observe(planned, 2 * BLOCK_TICKS + 5)
    mine, theirs = planned.truth_trace(), plain.truth_trace()
    assert mine.t_s.size == theirs.t_s.size > 200
    for name in ("t_s", "x_m", "y_m", "heading_rad", "distance_m"):
        assert getattr(mine, name).tolist() == getattr(theirs, name).tolist()
    assert planned.fell_back


def test_time_still_cannot_run_backwards() -> None:
    _, planned = pair()
    observe(planned, 20)
    with pytest.raises(ValueError, match="runs backwards"):
        planned.advance_to(0.05)


def rig_frames(lookahead: bool, seconds: float) -> list[object]:
    collector = FrameCollector()
    config = RigConfig(
        robot=load("kobuki"), scenario="random", seed=3, errors=ERRORS, lookahead=lookahead
    )
    with LockstepRig(config, [collector]) as rig:
        rig.run(seconds)
        vehicle = rig.vehicle
        assert isinstance(vehicle, PlannedVehicle) is lookahead
        assert not isinstance(vehicle, PlannedVehicle) or not vehicle.fell_back  # it held
    frames = collector.arrays()
    return [frames.timestamp_s.tolist(), frames.can_id.tolist(), frames.data.tobytes()]


def test_the_rig_sends_the_same_frames_with_and_without_the_lookahead() -> None:
    assert lookahead.BLOCK_TICKS * TICK_S < 6.0  # several blocks in the run
    assert rig_frames(True, 16.0) == rig_frames(False, 16.0)


@pytest.mark.parametrize("t_s", [math.nan, math.inf])
def test_a_time_that_is_not_finite_is_refused(t_s: float) -> None:
    _, planned = pair()
    observe(planned, 5)
    with pytest.raises(ValueError, match="finite"):
        planned.advance_to(t_s)


def halted(gap: range, late_command: int | None = None) -> Call:
    """The rig's calls with a halt over the ticks ``gap``: told before its first tick (the
    fleet's ``SimNode.hold_halted``), then each gap tick's sample alone, no command; with
    ``late_command``: the predicted command of that tick before the gap never came."""

    def tick(vehicle: Vehicle, k: int) -> None:
        if k == gap.start and isinstance(vehicle, PlannedVehicle):
            vehicle.hold(gap)
        if k in gap:
            vehicle.advance_to(k * TICK_S)
        elif k == late_command:
            pass
        else:
            rig_tick(vehicle, k)

    return tick


@pytest.mark.parametrize(
    ("gap", "holds"),
    [
        (range(150, 162), 1),  # inside a block, after some of its calls
        (range(200, 260), 1),  # past the drivetrain's 0.5 s command timeout: the wheels stop
        (range(BLOCK_TICKS - 5, BLOCK_TICKS + 9), 1),  # across a block's end: the next reads it
        (range(BLOCK_TICKS, BLOCK_TICKS + 12), 0),  # from a block's first tick: nothing to redo
        (range(0, 12), 0),  # before any call: the first block reads it
    ],
)
def test_a_held_halt_keeps_the_plan_and_the_plain_vehicle_s_counts_and_poses(
    gap: range, holds: int
) -> None:
    plain, planned = pair()
    ticks = 2 * BLOCK_TICKS + 40
    assert observe(planned, ticks, halted(gap)) == observe(plain, ticks, halted(gap))
    assert not planned.fell_back
    assert planned.holds == holds
    assert planned.blocks == 3 + holds  # the blocks still start every BLOCK_TICKS ticks


def test_a_halt_after_a_command_that_never_came_falls_back_bit_for_bit() -> None:
    plain, planned = pair()
    tick = halted(range(150, 162), late_command=148)
    assert observe(planned, 300, tick) == observe(plain, 300, tick)
    assert planned.fell_back
    assert planned.holds == 0
