"""The bridge's frame handling alone (the live judge's per-frame path): CPU per robot-tick and per
frame of each message, on a fleet's frames recorded once, and a digest of what it publishes.

``bench/fleet_flat.py --parts`` gives the bridge's share of a worker (``Bridge._handle``) with
the fleet stepping and paho writing around it; here the frames of a lockstep fleet (``--robots``,
``--ticks``; the worker's own: ``Fleet.take_batch``) are recorded first, then fed to one
``RobotTelemetry`` per robot as ``Bridge._handle`` feeds them (each identifier's plan, else
``feed_fields``), every publication encoded (``topics.dumps``), under the worker's GC regime
(``fleetrun.TickCollector``: the set-up frozen, the automatic collector off, the tree's young
passes, counted in: one after each tick before issue #13's fleetcut pass, none since;
``--young-gc-every N``): nothing else runs, so two trees compare in alternating pairs
with little noise. ``--by-message`` adds each message's frames per robot-tick and CPU per frame
(``process_time`` around each frame: the figures include that clock's own cost, ~1 us a
frame).

The digest (sha-256 of every publication in order, the wall clock ``unix_s`` pinned, then each
robot's ``status`` and ``rates``) is the same for two trees whose bridge publishes the same bytes
from the same frames: a faster per-frame path must leave it unchanged. Pair trees in
alternation (the recording is made with the tree that records; pass it with ``--frames``):

    PYTHONPATH=. .venv/bin/python bench/bridge_frames.py --robots 50 --ticks 600 \
        --record /tmp/fleet50.pkl
    PYTHONPATH=<tree> .venv/bin/python bench/bridge_frames.py --frames /tmp/fleet50.pkl \
        [--repeat 3] [--by-message] [--group 10]

``--group N`` feeds the same frames N robots at a time: robots 0..N-1 over every tick, then the
next N (a young GC pass after each group's tick). The work is the same frame for frame (each
robot's judge sees its own frames in the same order; the digest differs only by the order of
the robots' publications), only the state touched between two ticks of a robot shrinks from
all robots' to N's: what a worker's size costs in memory, not in work (issue #13: 50 robots
137 us, in groups of 10 93 us, of 5 84 us per robot-tick, least of 3 at load 8).

``--batch-ticks K`` feeds each robot its frames K ticks at a time: every tick's frames are
buffered per robot, and robot ``i`` is handed what it has buffered at the ticks ``k`` with
``k % K == i % K`` (the flushes spread over the ticks, as a worker would spread them over its
robots' publication phases) and at the end; a young GC pass after each tick as before. Each
robot's judge sees its own frames in the same order (the digest differs only by the order of
the robots' publications); its state stays hot over K ticks of frames instead of one.

``frames`` on the line is the sha-256 of the recording: the fleet's step (``--firmware``: its
boards', python or c) compiled must send the same frames. ``ODOCAN_ACCEL=1`` runs the per-frame
path and the step compiled by mypyc (``host.accel``; the first run builds it, minutes); the line
says how many modules were compiled. Issue #13, 50 robots,
``--batch-ticks 10``, least of 6 alternating at load 3.5-5: pure 83.2 us, compiled 46.8 us per
robot-tick (1.8x), digest 5c38e3fdc759fa9e both.
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import hashlib
import os
import pickle
import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import odocan.host.mqtt.fleetrun as fleetrun
import odocan.host.mqtt.topics as topics
from odocan.host import accel
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.fleetrun import publish_phase_s
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from odocan.sim.contract import database
from odocan.sim.fleet import Fleet, FleetConfig, robot_name

# the bridge's entry for a fleet's frames (``_feed`` in the trees before it was public)
# the worker's young GC pass every this many ticks (``fleetrun.TickCollector.every_ticks``: 1
# on trees before issue #13's fleetcut pass, which has none, 0; ``--young-gc-every``)
YOUNG_EVERY = getattr(fleetrun.TickCollector, "every_ticks", 1)
FEED = getattr(RobotTelemetry, "feed_fields", None) or getattr(RobotTelemetry, "_feed")  # noqa: B009
Recording = tuple[int, list[list[tuple[int, tuple[float, int, bytes]]]]]  # robots, batches


def record(robots: int, ticks: int, firmware: str = "python") -> Recording:
    """The frames a lockstep fleet of ``robots`` hands its bridge over ``ticks`` ticks."""
    config = FleetConfig(robots=robots, robot=robot.load("pmir"))
    if firmware != "python":  # the trees before FleetConfig.firmware: python only
        config = dataclasses.replace(config, firmware=firmware)
    fleet = Fleet(config)
    batches = []
    try:
        for k in range(ticks):
            fleet.step(k)
            batches.append([(i, f if type(f) is tuple else
                             (f.timestamp, f.arbitration_id, bytes(f.data)))
                            for i, f in fleet.take_batch()])
    finally:
        fleet.close()
    return robots, batches


def telemetries(robots: int) -> list[RobotTelemetry]:
    """One ``RobotTelemetry`` per robot, as ``fleetrun`` makes the bridge's endpoints."""
    config = FleetConfig(robots=robots, robot=robot.load("pmir"))
    p = config.robot
    return [RobotTelemetry(robot_name(i), Geometry.of(p), config.integrator,
                           counter_bits=p.counter_bits, publish_hz=10.0,
                           publish_phase_s=publish_phase_s(i, 10.0), now_s=0.0,
                           profile_name=p.name)
            for i in range(robots)]


def grouped(recording: Recording, size: int) -> Recording:
    """``recording``'s frames as ``size``-robot groups, each over every tick (``--group``)."""
    robots, batches = recording
    return robots, [[(i, f) for i, f in batch if start <= i < start + size]
                    for start in range(0, robots, size) for batch in batches]


def batched(recording: Recording, ticks: int) -> Recording:
    """``recording``'s frames handed to each robot ``ticks`` ticks at a time (``--batch-ticks``):
    one batch per tick, holding the frames buffered by the robots flushed at that tick."""
    robots, batches = recording
    held: list[list[tuple[int, tuple[float, int, bytes]]]] = [[] for _ in range(robots)]
    out = []
    for k, batch in enumerate(batches):
        for i, f in batch:
            held[i].append((i, f))
        flushed: list[tuple[int, tuple[float, int, bytes]]] = []
        for i in range(k % ticks, robots, ticks):
            flushed += held[i]
            held[i] = []
        out.append(flushed)
    out.append([item for frames in held for item in frames])
    return robots, out


def run_once(recording: Recording, by_message: Counter[str] | None,
             frames: Counter[str]) -> tuple[float, str, int]:
    """Feed the recording once: CPU s, the digest, the publications made."""
    robots, batches = recording
    names = {m.frame_id: m.name for m in database().messages}
    tels, digest, published = telemetries(robots), hashlib.sha256(), 0
    feed = FEED  # unbound: feed(telemetry, t_s, can_id, data, extended)
    # each robot's plans by 11-bit id, as ``Bridge._handle`` calls them (trees since
    # ``host.mqtt.liveplan``; before, every frame through ``feed``)
    plans = [getattr(telemetry, "plans", {}) for telemetry in tels]
    clock = time.process_time
    gc.collect()
    gc.freeze()
    gc.disable()
    ticks = 0
    try:
        start_s = clock()
        for batch in batches:
            for index, (t_s, can_id, data) in batch:
                t0_s = clock() if by_message is not None else 0.0
                plan = plans[index].get(can_id)
                for _, payload in (plan(t_s, data) if plan is not None
                                   else feed(tels[index], t_s, can_id, data, False)):
                    digest.update(topics.dumps(payload))
                    published += 1
                if by_message is not None:
                    name = names.get(can_id, hex(can_id))
                    by_message[name] += clock() - t0_s
                    frames[name] += 1
            ticks += 1
            if YOUNG_EVERY and ticks % YOUNG_EVERY == 0:
                gc.collect(0)
        cpu_s = clock() - start_s
    finally:
        gc.enable()
        gc.unfreeze()
    for telemetry in tels:
        digest.update(topics.dumps(telemetry.status()[1]) + topics.dumps(telemetry.rates(1.0)[1]))
    return cpu_s, digest.hexdigest()[:16], published


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=50)
    parser.add_argument("--ticks", type=int, default=600)
    parser.add_argument("--record", metavar="PATH", help="record the frames there, then stop")
    parser.add_argument("--frames", metavar="PATH", help="a recording (else one made now)")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--young-gc-every", type=int, default=None, metavar="N",
                        help="a young GC pass every N ticks (0: none; default: the tree's "
                             "worker's rule, fleetrun.TickCollector)")
    parser.add_argument("--group", type=int, default=0, metavar="N",
                        help="the robots fed N at a time over every tick (0: all, by tick)")
    parser.add_argument("--batch-ticks", type=int, default=1, metavar="K",
                        help="each robot fed its frames K ticks at a time, flushes spread")
    parser.add_argument("--firmware", default="python",
                        help="the recording fleet's boards' firmware (python, c)")
    parser.add_argument("--by-message", action="store_true",
                        help="CPU per frame of each message (the clock read per frame)")
    args = parser.parse_args()
    if args.young_gc_every is not None:
        global YOUNG_EVERY
        YOUNG_EVERY = args.young_gc_every
    recording: Recording
    if args.frames:
        recording = pickle.loads(Path(args.frames).read_bytes())
    else:
        recording = record(args.robots, args.ticks, args.firmware)
    frames_digest = hashlib.sha256(pickle.dumps(recording)).hexdigest()[:16]
    if args.record:
        Path(args.record).write_bytes(pickle.dumps(recording))
        return 0
    setattr(topics.time, "time", lambda: 1.0)  # noqa: B010 (this process's wall clock pinned:
    # ``unix_s`` in the digest)
    robots, batches = recording
    robot_ticks = robots * len(batches)
    how = f" in groups of {args.group}" if args.group else ""
    how += f" ({len(accel.active())} modules compiled)" if accel.active() else ""
    if args.group:
        recording = grouped(recording, args.group)
    if args.batch_ticks > 1:
        how += f", {args.batch_ticks} ticks a batch"
        recording = batched(recording, args.batch_ticks)
    for _ in range(args.repeat):
        by_message: Counter[str] | None = Counter() if args.by_message else None
        frames: Counter[str] = Counter()
        cpu_s, digest, published = run_once(recording, by_message, frames)
        print(f"{robots} robots, {len(batches)} ticks{how}: {cpu_s / robot_ticks * 1e6:.1f} us CPU "
              f"per robot-tick, {published} publications, digest {digest}, "
              f"frames {frames_digest}, "
              f"load {os.getloadavg()[0]:.2f}", flush=True)
        for name, spent_s in (by_message or Counter[str]()).most_common():
            print(f"  {name:16s} {frames[name] / robot_ticks:5.2f} a robot-tick, "
                  f"{spent_s / frames[name] * 1e6:6.1f} us a frame, "
                  f"{spent_s / cpu_s * 100:4.1f}% of the CPU", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
