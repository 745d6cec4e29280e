"""The fleet step under a fixed pattern of skipped releases: CPU per robot-tick, frames digest.

A real-time fleet on a loaded machine skips releases (``sim.fleet.run_realtime``): the skipped
releases' driver commands and samples go out late (``SimNode.drive_skipped``), served by each
robot's drive run ahead (``sim.lookahead``); before that change a skipped MOTOR_CMD never came,
so every drive fell back and ran tick by tick until ``sim.fleet.BLOCK_TICKS`` ticks passed
without a skip. ``bench/fleet_flat.py --clock real`` shows that under the load of the moment;
here the same loop runs without a clock, skipping ``--gap`` releases after every ``--every``
ticks run (0: none), so the work is the same on every run and two trees compare in pairs, or under
``valgrind --tool=callgrind`` (PYTHONHASHSEED=0; the instructions of ``--ticks 0``, the fleet's
construction, subtracted) without the load in the figure:

    .venv/bin/python bench/fleet_skips.py [--robots 20] [--ticks 300] [--every 30] [--gap 2] \
        [--firmware c] [--digest]

A gap of ``--gap 9`` or more releases halts the boards (``sim.board.HALT_AFTER_S``): its
samples go out alone, no driver command; at an isolated halt (``sim.fleet.HOLD_CALM_TICKS``
after the previous one) each drive runs the rest of its block again without the gap's commands
(``PlannedVehicle.hold``), at halts that recur it falls back. ``--every 30 --gap 9``: recurring
halts; ``--every 200 --gap 9 --ticks 800``: isolated ones.

``--digest``: a SHA-256 over every frame the host observers heard (robot, stamp to the ns,
identifier, payload), the same on a tree that changes only the cost (lockstep is deterministic:
same seed, same bytes). Prints the CPU per robot-tick run and per robot-release, the drives that
ran ahead again (blocks; of them run again for a halt) and those still fallen back at the end.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.sim import robot
from odocan.sim.fleet import Batch, Fleet, FleetConfig, frame_fields
from odocan.sim.lookahead import PlannedVehicle


def _digest_batch(digest: hashlib._Hash, batch: Batch) -> None:
    """Every frame of ``batch`` into ``digest``: robot, stamp (ns), identifier, payload."""
    for index, frame in batch:
        stamp_s, can_id, data = frame_fields(frame)
        digest.update(f"{index} {round(stamp_s * 1e9)} {can_id:03X} {data.hex()}\n".encode())


def run(args: argparse.Namespace) -> str:
    """One run of the pattern; its summary line."""
    config = FleetConfig(robots=args.robots, robot=robot.load(args.robot), firmware=args.firmware)
    digest = hashlib.sha256()
    with Fleet(config) as fleet:
        k = ran = 0
        cpu_s = 0.0
        while k < args.ticks:
            t0_s = time.process_time()
            fleet.step(k)
            batch = fleet.take_batch()
            cpu_s += time.process_time() - t0_s
            if args.digest:
                _digest_batch(digest, batch)
            k, ran = k + 1, ran + 1
            if args.every and ran % args.every == 0:
                k += args.gap
        vehicles = [rig.vehicle for rig in fleet.rigs if isinstance(rig.vehicle, PlannedVehicle)]
        blocks = sum(v.blocks for v in vehicles)
        holds = sum(v.holds for v in vehicles)
        fallen = sum(v.fell_back for v in vehicles)
        halts = fleet.halts
    per_tick = cpu_s / max(args.robots * ran, 1) * 1e6
    per_release = cpu_s / max(args.robots * k, 1) * 1e6
    line = (f"{args.robots} robots, {ran} ticks run of {k} releases (every {args.every}: "
            f"{args.gap} skipped), firmware {args.firmware}: fleet step {per_tick:.1f} us per "
            f"robot-tick, {per_release:.1f} per robot-release; halts {halts}; blocks {blocks} "
            f"(run again for a halt {holds}), fallen back at the end {fallen}")
    return line + (f"; frames digest {digest.hexdigest()[:16]}" if args.digest else "")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=20)
    parser.add_argument("--ticks", type=int, default=300, help="releases (run or skipped)")
    parser.add_argument("--every", type=int, default=30, help="ticks run between skips (0: none)")
    parser.add_argument("--gap", type=int, default=2, help="releases skipped each time")
    parser.add_argument("--robot", default="pmir")
    parser.add_argument("--firmware", choices=("python", "c"), default="c")
    parser.add_argument("--digest", action="store_true")
    args = parser.parse_args()
    if args.robots < 1 or args.ticks < 0 or args.every < 0 or args.gap < 0:
        print("error: --robots must be >= 1, --ticks, --every and --gap >= 0", file=sys.stderr)
        return 2
    print(run(args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
