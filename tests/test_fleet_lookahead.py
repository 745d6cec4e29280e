"""The fleet runs its robots' drives ahead in blocks (``sim.lookahead``) without changing a byte,
and spreads the blocks' work: the first ones before the clock, the later ones one robot a tick."""

from __future__ import annotations

from odocan.firmware import frames as fr
from odocan.sim.fleet import BLOCK_TICKS, Fleet, FleetConfig, frame_fields
from odocan.sim.lookahead import PlannedVehicle
from odocan.sim.robot import load


def fleet_frames(lookahead: bool, robots: int, ticks: int) -> list[object]:
    """Every robot's frames (index, t, id, payload) of ``ticks`` fleet ticks."""
    seen: list[object] = []
    with Fleet(FleetConfig(robots=robots, robot=load("pmir"), lookahead=lookahead)) as fleet:
        for k in range(ticks):
            fleet.step(k)
            seen.extend((i, frame_fields(frame)) for i, frame in fleet.take_batch())
        for rig in fleet.rigs:
            vehicle = rig.vehicle
            assert isinstance(vehicle, PlannedVehicle) is lookahead
            assert not isinstance(vehicle, PlannedVehicle) or not vehicle.fell_back  # it held
    return seen


def test_the_fleet_sends_the_same_frames_with_and_without_the_lookahead() -> None:
    ticks = BLOCK_TICKS + 300  # past every robot's first block and into its second
    with_blocks = fleet_frames(True, 5, ticks)
    assert len(with_blocks) > 5 * ticks  # an encoder frame a tick at least
    assert with_blocks == fleet_frames(False, 5, ticks)


def test_the_blocks_run_before_the_clock_then_one_robot_a_tick() -> None:
    robots = 24
    with Fleet(FleetConfig(robots=robots, robot=load("pmir"))) as fleet:
        vehicles = [rig.vehicle for rig in fleet.rigs]
        assert all(isinstance(v, PlannedVehicle) for v in vehicles)
        blocks = [v.blocks for v in vehicles]  # type: ignore[attr-defined]
        assert blocks == [1] * robots  # the first ones when the fleet is built
        per_tick = []
        for k in range(BLOCK_TICKS + 2):  # every robot's second block starts in these ticks
            fleet.step(k)
            now = [v.blocks for v in vehicles]  # type: ignore[attr-defined]
            per_tick.append(sum(b - a for a, b in zip(blocks, now, strict=True)))
            blocks = now
    assert blocks == [2] * robots
    assert max(per_tick) == 1
    assert per_tick[0] == 0  # the clock's first tick runs no block


def skipping_frames(lookahead: bool, robots: int) -> tuple[list[object], list[int]]:
    """Frames of a fleet whose loop skips ticks 150-152 (a release a whole period late: the
    robots' predicted commands of those ticks never come), and each drive's blocks run."""
    seen: list[object] = []
    with Fleet(FleetConfig(robots=robots, robot=load("pmir"), lookahead=lookahead)) as fleet:
        for k in [*range(150), *range(153, 2 * BLOCK_TICKS + 200)]:
            fleet.step(k)
            seen.extend((i, frame_fields(frame)) for i, frame in fleet.take_batch())
        vehicles = [rig.vehicle for rig in fleet.rigs]
        blocks = [v.blocks if isinstance(v, PlannedVehicle) else 0 for v in vehicles]
        assert not any(isinstance(v, PlannedVehicle) and v.fell_back for v in vehicles)
    return seen, blocks


def test_after_skipped_ticks_the_drives_run_ahead_again_with_the_same_frames() -> None:
    with_blocks, blocks = skipping_frames(True, 4)
    # before the skip: the first block and one or two more; after it: every 100 ticks again
    assert min(blocks) >= (2 * BLOCK_TICKS + 200 - 150) // BLOCK_TICKS + 1
    assert with_blocks == skipping_frames(False, 4)[0]


def drive_frames(skip: bool) -> tuple[list[list[tuple[float, int, bytes]]], list[PlannedVehicle]]:
    """Each robot's MOTOR_CMD and WHEEL_ENCODERS frames (t, id, payload) over 3 blocks of a
    fleet whose loop skips two releases every 30 ticks (``skip``) or none, and its vehicles."""
    robots = 3
    seen: list[list[tuple[float, int, bytes]]] = [[] for _ in range(robots)]
    with Fleet(FleetConfig(robots=robots, robot=load("kobuki"))) as fleet:
        for k in range(3 * BLOCK_TICKS + 1):  # its last tick not skipped (300 % 30 == 0)
            if skip and k % 30 in (28, 29):
                continue
            fleet.step(k)
            for i, frame in fleet.take_batch():
                fields = frame_fields(frame)
                if fields[1] in (fr.MOTOR_CMD_ID, fr.WHEEL_ENCODERS_ID):
                    seen[i].append(fields)
        vehicles = [rig.vehicle for rig in fleet.rigs]
    assert all(isinstance(v, PlannedVehicle) for v in vehicles)
    return seen, vehicles  # type: ignore[return-value]


def test_a_robot_whose_loop_skipped_releases_keeps_running_ahead_and_moving_as_without() -> None:
    """Two releases skipped every 30 ticks (a loaded real-time loop): each skipped release's
    driver command (open loop, a function of time) and encoder sample go out late, served from
    the drive's block, so no drive falls back (it did at every skip: +37 % CPU a robot-tick) and
    the robots move as they would have: the same commands and samples, stamped the same."""
    skipping, vehicles = drive_frames(True)
    assert not any(v.fell_back for v in vehicles)
    assert all(v.blocks >= 3 for v in vehicles)  # a block every BLOCK_TICKS, skips or not
    steady, _ = drive_frames(False)
    for heard, lockstep in zip(skipping, steady, strict=True):
        assert len(heard) > 3 * BLOCK_TICKS - 2  # a sample a release, skipped ones too
        assert heard == lockstep
    assert drive_frames(True)[0] == skipping  # deterministic run to run


def halt_then_skips(lookahead: bool) -> tuple[list[object], list[PlannedVehicle]]:
    """Frames of a fleet whose drives fall back at tick 45 (a read of their drivetrain's
    state, which no block can serve), whose loop then halts the boards once (releases 50-61
    skipped: 13 periods) and skips two releases every 30 ticks, and its vehicles."""
    seen: list[object] = []
    ticks = [k for k in range(6 * BLOCK_TICKS) if not 50 <= k < 62 and k % 30 not in (28, 29)]
    with Fleet(FleetConfig(robots=3, robot=load("kobuki"), lookahead=lookahead)) as fleet:
        for k in ticks:
            fleet.step(k)
            seen.extend((i, frame_fields(frame)) for i, frame in fleet.take_batch())
            if k == 45:
                for rig in fleet.rigs:
                    rig.vehicle.wheel_speeds_mps()
            if k == 62 and lookahead:  # the premise: fallen back, the halt replans nothing
                assert all(v.fell_back for v in fleet._planned)  # type: ignore[union-attr]
        assert fleet.halts == 1
        vehicles = [rig.vehicle for rig in fleet.rigs]
    return seen, vehicles  # type: ignore[return-value]


def test_after_a_fall_back_and_a_halt_the_drives_run_ahead_again_while_the_loop_keeps_skipping(
) -> None:
    """A drive that fell back runs ahead again once a block's ticks ran without a halt (a
    halt itself no longer makes a drive fall back: tests/test_fleet_halt_plan.py); skips that
    halt nothing cost no plan, so they do not hold the replan back (before, it waited for a
    block without any skip, which a loop skipping every 30 ticks never has), with the same
    frames."""
    planned, vehicles = halt_then_skips(True)
    assert not any(v.fell_back for v in vehicles)
    assert planned == halt_then_skips(False)[0]


def test_a_workers_blocks_are_spread_over_the_block_period() -> None:
    """The blocks of a worker's shard (``odocan fleet --workers 2``: 50 robots of 100) come
    spread over the whole period, not one a tick through half of it and none in the other half
    (a block is ~1 ms of CPU: half a second of ticks each 1 ms heavier made the real-time
    fleet's late ticks)."""
    for first in (0, 50):
        with Fleet(FleetConfig(robots=50, robot=load("pmir"), first=first)) as fleet:
            vehicles = [rig.vehicle for rig in fleet.rigs]
            blocks = [v.blocks for v in vehicles]  # type: ignore[attr-defined]
            per_tick = []
            for k in range(BLOCK_TICKS + 2):
                fleet.step(k)
                now = [v.blocks for v in vehicles]  # type: ignore[attr-defined]
                per_tick.append(sum(b - a for a, b in zip(blocks, now, strict=True)))
                blocks = now
        assert sum(per_tick) == 50  # every robot's second block
        window = 10
        busiest = max(sum(per_tick[k:k + window]) for k in range(len(per_tick) - window + 1))
        assert busiest <= 6, f"{busiest} blocks in {window} ticks (shard from {first})"
