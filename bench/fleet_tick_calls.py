"""How evenly a worker's fleet step spreads its work over the ticks: calls per tick, counted.

The CPU of single ticks cannot be compared on a loaded machine (and callgrind counts whole
processes); the number of Python and C calls ``Fleet.step`` makes in a tick is the same from run
to run, whatever the load, and follows its work (a robot's lookahead block, ~1 ms of CPU, is
~2 600 calls). For a shard of ``--robots`` robots from ``--first`` (``odocan fleet --workers 2``
with 100 robots: 50 from 0 and 50 from 50), the ticks after the first blocks: the median and
largest calls per tick, the busiest and quietest 10-tick windows' means, and each half second's
mean (before ``sim.fleet.block_phase``: robot ``i``'s block on tick ``i``, so a 50-robot shard
ran one block a tick through one half of each second and none in the other: 5 998 against
3 369 calls a tick; after: 4 736 against 4 631).

    PYTHONPATH=<tree> .venv/bin/python bench/fleet_tick_calls.py [--robots 50] [--first 0] \
        [--ticks 300] [--firmware c]

(the tree measured is the one ``PYTHONPATH`` names: the script runs unchanged on older trees)
"""

from __future__ import annotations

import argparse
import statistics
import sys

from odocan.sim import robot
from odocan.sim.fleet import BLOCK_TICKS, Fleet, FleetConfig


def calls_per_tick(robots: int, first: int, ticks: int, firmware: str) -> list[int]:
    """The calls (Python and C) each of ``ticks`` fleet ticks made (step and take_batch)."""
    count = 0

    def profile(_frame: object, event: str, _arg: object) -> None:
        nonlocal count
        if event in ("call", "c_call"):
            count += 1

    per_tick = []
    config = FleetConfig(robots=robots, robot=robot.load("pmir"), firmware=firmware, first=first)
    with Fleet(config) as fleet:
        for k in range(ticks):
            count = 0
            sys.setprofile(profile)
            fleet.step(k)
            fleet.take_batch()
            sys.setprofile(None)
            per_tick.append(count)
    return per_tick


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=50)
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--ticks", type=int, default=3 * BLOCK_TICKS)
    parser.add_argument("--firmware", default="c")
    args = parser.parse_args()
    if args.ticks < 2 * BLOCK_TICKS or args.robots < 1 or args.first < 0:
        parser.exit(2, f"fleet_tick_calls: --ticks must be >= {2 * BLOCK_TICKS}, --robots >= 1 "
                       "and --first >= 0\n")
    body = calls_per_tick(args.robots, args.first, args.ticks, args.firmware)[BLOCK_TICKS:]
    tens = [statistics.mean(body[i:i + 10]) for i in range(0, len(body) - 9, 10)]
    halves = [round(statistics.mean(body[i:i + BLOCK_TICKS // 2]))
              for i in range(0, len(body) - BLOCK_TICKS // 2 + 1, BLOCK_TICKS // 2)]
    print(f"{args.robots} robots from {args.first}, ticks {BLOCK_TICKS}-{args.ticks - 1}: calls "
          f"a tick median {statistics.median(body):.0f}, max {max(body)}; 10-tick windows "
          f"{max(tens):.0f} busiest, {min(tens):.0f} quietest; half seconds {halves}")


if __name__ == "__main__":
    main()
