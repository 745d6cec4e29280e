"""A fleet's drives stay planned through an isolated loop halt (issue #13), with the frames of
the plain vehicle: a halt's gap sends the skipped releases' encoder samples alone (no driver
MOTOR_CMD: the halt judges' rule, ``sim.fleet.Fleet._sample_skipped``), so each robot keeps its
latest command through the gap. Before, the drive's block had predicted the gap's commands,
fell back at the first one that did not come and ran as a plain vehicle (the costly tick) until
a block's ticks passed without a halt. Now the block is run again without them
(``PlannedVehicle.hold``): the same counts and poses, call for call. Halts that recur within
``HOLD_CALM_TICKS`` still make the drives fall back (there the plain drive costs less than a
hold at every halt: ``Fleet._isolated_halt``)."""

from __future__ import annotations

from itertools import pairwise

import pytest

from odocan.firmware import frames as fr
from odocan.sim.fleet import BLOCK_TICKS, HOLD_CALM_TICKS, Fleet, FleetConfig, frame_fields
from odocan.sim.lookahead import PlannedVehicle
from odocan.sim.robot import load

# Fleet ticks run: halts (gaps of >= 9.5 periods) >= HOLD_CALM_TICKS apart: one of 10 periods,
# one of 13 across robot 0's block start at 300, one of 60 (past the drivetrain's 0.5 s command
# timeout: the wheels stop in the gap); and skips of two releases (no halt) between them.
_GAPS = [(40, 50), (295, 308), (520, 580)]
_TICKS = [k for k in range(7 * BLOCK_TICKS)
          if not any(a <= k < b for a, b in _GAPS) and k % 30 not in (18, 19)]
# ... and halts that recur: 58 and 62 ticks after the previous one
_RECURRING = [(40, 50), (95, 108), (160, 170)]
# (the run ends before a block's ticks pass without a halt: the fleet's replan)
_RECURRING_TICKS = [k for k in range(250) if not any(a <= k < b for a, b in _RECURRING)]

Frames = list[tuple[float, int, bytes]]


def halted_run(lookahead: bool, robot: str, ticks: list[int] = _TICKS, robots: int = 3
               ) -> tuple[list[Frames], list[PlannedVehicle], int]:
    """Each robot's frames (t, id, payload) over the fleet ticks ``ticks``, its planned
    vehicles (lookahead) and the fleet's halts."""
    seen: list[Frames] = [[] for _ in range(robots)]
    config = FleetConfig(robots=robots, robot=load(robot), lookahead=lookahead)
    with Fleet(config) as fleet:
        for k in ticks:
            fleet.step(k)
            for i, frame in fleet.take_batch():
                seen[i].append(frame_fields(frame))
        vehicles = [rig.vehicle for rig in fleet.rigs]
        halts = fleet.halts
    planned = [v for v in vehicles if isinstance(v, PlannedVehicle)]
    assert len(planned) == (robots if lookahead else 0)
    return seen, planned, halts


@pytest.mark.parametrize("robot", ["pmir", "kobuki"])
def test_a_halted_fleet_s_drives_stay_planned_with_the_plain_vehicle_s_frames(robot: str) -> None:
    planned, vehicles, halts = halted_run(True, robot)
    assert halts == len(_GAPS)  # the premise: every gap halted the boards, far apart
    assert all(b[1] - a[1] >= HOLD_CALM_TICKS for a, b in pairwise(_GAPS))
    assert not any(v.fell_back for v in vehicles)  # on main: every drive, from the first halt
    assert all(v.holds >= halts for v in vehicles)  # each gap withheld a predicted command
    plain, _, plain_halts = halted_run(False, robot)
    assert plain_halts == halts
    for mine, theirs in zip(planned, plain, strict=True):
        assert len(mine) > len(_TICKS)  # an encoder frame a tick run at least
        assert mine == theirs  # every frame, stamp and byte: MOTOR_CMDs and samples too


def test_the_blocks_still_start_on_each_robot_s_own_ticks() -> None:
    """A hold runs the block again to its own end: the next blocks start on the ticks they
    would have started on without the halts (the fleet's blocks stay spread, one robot a
    tick), so the blocks run ahead are those of the unhalted run plus one a hold."""
    _, halted, _ = halted_run(True, "pmir")
    _, steady, _ = halted_run(True, "pmir", list(range(7 * BLOCK_TICKS)))
    assert [v.blocks - v.holds for v in halted] == [v.blocks for v in steady]
    assert not any(v.holds for v in steady)


def test_the_halt_sends_no_driver_command_in_its_gap() -> None:
    """The frames a hold keeps are the halt's rule: the gap's encoder samples, each at its own
    release, and no MOTOR_CMD stamped inside the gap (the robot drives its latest command)."""
    frames, _, _ = halted_run(True, "pmir", robots=1)
    for start, stop in _GAPS:
        inside = [f for f in frames[0] if start * 0.01 - 1e-9 <= f[0] < stop * 0.01 - 1e-9]
        assert [f[1] for f in inside if f[1] == fr.MOTOR_CMD_ID] == []
        samples = [round(f[0] * 100) for f in inside if f[1] == fr.WHEEL_ENCODERS_ID]
        assert samples == list(range(start, stop))


def test_halts_that_recur_make_the_drives_fall_back_as_before_with_the_same_frames() -> None:
    planned, vehicles, halts = halted_run(True, "pmir", _RECURRING_TICKS)
    assert halts == len(_RECURRING)
    assert all(v.holds == 1 for v in vehicles)  # the first halt only
    assert all(v.fell_back for v in vehicles)  # the second one: a plain vehicle since
    assert planned == halted_run(False, "pmir", _RECURRING_TICKS)[0]
