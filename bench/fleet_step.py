"""The fleet step and the bridge's frame intake, CPU per robot-tick, without MQTT or a clock.

Steps ``--robots`` robots of ``sim.fleet`` for ``--ticks`` ticks in this process and feeds each
robot's frames to its own ``RobotTelemetry`` (the bridge's per-frame work: E2E, decode, the
live judge), timing both apart with the process clock (other load on the machine barely moves
it, though a loaded machine inflates CPU time itself: compare trees in interleaved pairs). One
line per ``--firmware`` and ``--lookahead`` (the robots' drives run ahead in staggered blocks,
``sim.lookahead``, as the fleet does by default; the first blocks run when the fleet is built,
outside the timed ticks, as before a real-time fleet's clock starts):

    .venv/bin/python bench/fleet_step.py [--robots 20] [--ticks 500] [--firmware python c] \
        [--lookahead on off]

The script runs unchanged on a tree from before the batch intake (``feed`` instead of
``feed_frame``; no ``FleetConfig.firmware``: python only; no ``FleetConfig.lookahead``: the
tree's own, printed as "tree default"), so it can be copied there to pair.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from odocan.sim.fleet import Fleet, FleetConfig


def has_lookahead() -> bool:
    """Whether this tree's fleet has the lookahead switch (``FleetConfig.lookahead``)."""
    return any(f.name == "lookahead" for f in dataclasses.fields(FleetConfig))


def cost_us(robots: int, ticks: int, firmware: str, lookahead: str) -> tuple[float, float]:
    """(fleet step, bridge intake) CPU us per robot-tick with ``firmware`` on every board and
    the drives run ahead or not (``lookahead`` on/off; ignored on a tree without the switch)."""
    profile = robot.load("pmir")
    geometry = Geometry.of(profile)
    extra: dict[str, object] = {} if firmware == "python" else {"firmware": firmware}
    if has_lookahead():
        extra["lookahead"] = lookahead == "on"
    with Fleet(FleetConfig(robots=robots, robot=profile, **extra)) as fleet:
        telemetry = [RobotTelemetry(name, geometry, "exact", counter_bits=profile.counter_bits)
                     for name in fleet.names]
        feed = [getattr(t, "feed_frame", t.feed) for t in telemetry]
        step_s = intake_s = 0.0
        for k in range(ticks):
            t0_s = time.process_time()
            fleet.step(k)
            batch = fleet.take_batch()
            t1_s = time.process_time()
            for index, frame in batch:
                feed[index](frame)
            intake_s += time.process_time() - t1_s
            step_s += t1_s - t0_s
    per = robots * ticks
    return step_s / per * 1e6, intake_s / per * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=20)
    parser.add_argument("--ticks", type=int, default=500)
    parser.add_argument("--firmware", nargs="+", choices=("python", "c"), default=["python"])
    parser.add_argument("--lookahead", nargs="+", choices=("on", "off"), default=["on"])
    args = parser.parse_args()
    for firmware in args.firmware:
        for lookahead in args.lookahead if has_lookahead() else ["tree default"]:
            step_us, intake_us = cost_us(args.robots, args.ticks, firmware, lookahead)
            print(f"{args.robots} robots, {args.ticks} ticks, firmware {firmware}, lookahead "
                  f"{lookahead}: fleet step {step_us:.1f} us, bridge intake {intake_us:.1f} us "
                  "per robot-tick")
    return 0


if __name__ == "__main__":
    sys.exit(main())
