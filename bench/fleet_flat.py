"""One fleet worker bridged to mosquitto, stepped flat out: CPU per robot-tick with MQTT, no skips.

``bench/fleet.py`` measures the fleet in real time; on a shared, loaded machine its trials skip
releases (a period or more behind), and a skip changes the work (the skipped releases' samples sent
late, back to back; a drive run ahead falling back), so its CPU figures drift with the load. Here
``run_fleet`` (one worker: the fleet, the bridge with its live judge, one MQTT connection per robot
to a mosquitto on loopback) runs under a clock that is never late: every tick is released as soon
as the bridge handled the previous tick's frames (its slices, a loop turn each, as in real time)
and the MQTT tasks had their loop turn, and the report's ``cpu_s`` (this process, while the clock
ran) over robots x ticks is the CPU per robot-tick of everything a worker does. Verdicts are
printed too. Pair trees in alternation:

    .venv/bin/python bench/fleet_flat.py [--robots 50] [--ticks 600] [--repeat 3] \
        [--publish-hz 10] [--firmware python] [--young-gc-every 1] [--parts]

``--firmware c`` runs the C port on every board (``odocan fleet --firmware c``). ``--parts``
splits ``cpu_s`` (this process's CPU while the clock ran), each part in us of process time per
robot-tick flat out, per robot-release in real time (ticks run plus releases skipped: a skipped
release's encoder sample is still stepped, sent and judged, inside the next tick's step), each
counted while the clock runs only, as ``cpu_s``:

* ``step``: ``Fleet.step`` (the boards, the drives, the frames onto the bus; a late tick's
  catch-up of the releases it skipped included);
* ``bridge frame handling``: ``Bridge._handle`` (E2E, decode, live judge, publications and their
  JSON queued);
* ``young GC passes``: the generation-0 collections (one after each tick,
  ``fleetrun.TickCollector``; the automatic collector's too);
* ``the rest``: ``cpu_s`` less those three (paho, the socket writes, the loop, status and rates,
  the command reader's thread): not negative, each part being inside ``cpu_s``;
* the socket writes per robot-tick (counted over the whole run);
* the MQTT side split out: the publications queued from the frame handling (``RobotLink.publish``:
  topic, JSON, the link's deque; inside the frame handling's figure), the telemetry bursts handed
  to paho (``LinkClient.publish_batch``), the socket writes (``LinkClient.flush`` and
  ``_write_soon``), the QoS-1 acknowledgements and pings read (``LinkClient._read_all``),
  ``status`` and ``rates`` made and queued (``Bridge._publish_status``, ``_publish_rates``);
  ``the loop and the rest``: the rest less these (the event loop, the tasks' wake-ups, the clock);
* ``after the clock``: what step, frame handling and young GC spent after the clock stopped (the
  bridge's final drain of the frames it fell behind on: in real time with skipped releases most
  of its handling), not in ``cpu_s``. Counted in the frame handling's figure, as it once was, it
  made the rest negative (-87 us per robot-release, 228 of 300 releases skipped).

``status`` and ``rates`` run on the wall clock (1 Hz a robot): flat out on a loaded machine a tick
takes longer than 10 ms of wall, so they weigh more per robot-tick than in real time.

The bridge's frame handling alone, on recorded frames, with a digest of what it publishes (two
trees compared without the fleet, paho and the loop around it): ``bench/bridge_frames.py``.
``--young-gc-every N`` makes the worker's young GC pass one every N ticks
(``TickCollector.every_ticks``; 0: none while the clock runs); without it each tree runs its own
product's rule: a pass after every tick before the fleetcut pass, none since (issue #13; a
worker makes no cyclic garbage): ``--young-gc-every 1`` on this tree is the old rule. Rarer
passes cost about as much CPU in all as one a tick (its survivors live 20-100 ticks), in longer
pauses: 16 ms every 50 ticks, 43 ms every 200, 50 robots at load 9.

``--clock real`` runs the same worker under the product's clock (``sim.fleet.run_realtime``:
each tick released at ``k * 10 ms`` of the wall clock, the loop asleep in between, late releases
skipped), with the same parts, the skipped releases and the drives' fall-backs from running
ahead (``sim.lookahead``: only a gap that halts the boards makes a drive fall back, then run
tick by tick until ``sim.fleet.BLOCK_TICKS`` ticks pass without a skip; a skipped release's
MOTOR_CMD is sent late with its sample, ``SimNode.drive_skipped``);
``--clock both`` alternates a flat and a real run per ``--repeat``: the pair shows what running
in real time adds to the same work. In real time the figures are per robot-release (ticks run
plus releases skipped: a skipped release's encoder sample is still sent, and judged) as well as
per robot-tick run (``bench/fleet.py``'s figure, which a skipping run inflates).

The script runs unchanged on trees since the bridge's ``run_fleet`` (copy it there to pair).
Before, the clock released every tick at once (a ``NeverLate`` clock in ``run_realtime``): the
bridge, one 64-frame slice a loop turn, fell behind and handled most of the frames in its final
drain, after ``cpu_s`` stopped, so the figure was too low (and lower for a slower bridge).

The budget (issue #13, fleet100 pass; ``--robots 50 --ticks 600 --firmware c --parts``, load
0.9-1.9, us per robot-tick, pure / ``ODOCAN_ACCEL=1``): total 172.5 / 139.9; step 43.5 / 42.7;
frame handling 94.3 / 66.6 (the publications' JSON and queueing in it 6.2 / 6.0); young GC 8.5 /
7.7; the rest 26.2 / 22.9: telemetry bursts to paho 3.5 / 3.2, socket writes 6.8 / 5.5,
acknowledgements 1.6 / 1.5, status 0.9 / 0.7, rates 3.8 / 2.8, the loop 9.7 / 9.2. The young
pass found no garbage in 600 ticks; ``--young-gc-every 0`` saves its 6-11 us (least of 3).
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import os
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from fleet import start_mosquitto  # bench/fleet.py

import odocan.host.mqtt.fleetrun as fleetrun
from odocan.host.mqtt.bridge import Bridge
from odocan.host.mqtt.fleetrun import FleetRun, run_fleet
from odocan.sim import robot
from odocan.sim.cboard import FIRMWARES
from odocan.sim.fleet import Fleet, FleetConfig, run_realtime
from odocan.sim.realtime import DeadlineStats

TICK_S = 0.01


async def run_flat(
    fleet: Fleet, *, duration_s: float, on_batch: Callable[[Any], None] | None = None,
    stop: asyncio.Event | None = None, stats: DeadlineStats | None = None, **_: Any,
) -> DeadlineStats:
    """``fleetrun``'s ``run_realtime`` without a clock: tick k is stepped once the bridge
    handled every frame offered before it (``Bridge._consume``'s slices, a loop turn each) and
    the links had a loop turn to write; no tick is late, none skipped."""
    stats = stats if stats is not None else DeadlineStats(TICK_S, TICK_S / 2)
    bridge = _bridge_of(on_batch)
    k = 0
    while k * TICK_S < duration_s - 1e-9 and (stop is None or not stop.is_set()):
        await asyncio.sleep(0)  # the links' writes, the periodic task
        while isinstance(bridge, Bridge) and (bridge._pending or not bridge.queue.empty()):
            await asyncio.sleep(0)
        stats.record(0.0)
        fleet.step(k)
        batch = fleet.take_batch()
        if on_batch is not None:
            on_batch(batch)
        k += 1
    while isinstance(bridge, Bridge) and (bridge._pending or not bridge.queue.empty()):
        await asyncio.sleep(0)  # the last tick's frames inside the clock too
    await asyncio.sleep(0)
    return stats


def _bridge_of(on_batch: Any) -> Bridge | None:
    """The bridge whose ``offer`` ``on_batch`` is, or calls (``fleetrun.TickCollector``)."""
    for _ in range(3):
        owner = getattr(on_batch, "__self__", None)
        if isinstance(owner, Bridge) or owner is None:
            return owner
        on_batch = getattr(owner, "on_batch", None)
    return None


class Parts:
    """Process time spent in ``Fleet.step`` and ``Bridge._handle``, and in the young GC passes
    (``fleetrun.TickCollector``'s, one a tick: ``gc.callbacks``); the links' socket writes.

    Each part counts while the clock runs only (``clocked``), as ``cpu_s`` and the MQTT parts
    do: in real time a worker that skipped releases is behind, and its bridge handled most of
    the frames in its final drain, after the clock stopped (measured, 50 robots at load 6.4,
    228 of 300 releases skipped: 47 of the 52 us of frame handling per robot-release came after
    it), so "the rest" (``cpu_s`` less the parts) read -87 us. What a part spent after the clock
    is said apart (``after_s``), outside ``cpu_s``."""

    clock = staticmethod(time.process_time)  # a test's own clock in its place

    def __init__(self) -> None:
        self.step_s = self.handle_s = self.young_gc_s = 0.0
        self.after_s = dict.fromkeys(("step", "handle", "young_gc"), 0.0)  # after the clock
        self._gc_t0_s = 0.0
        self.senders: list[Any] = []
        self.mqtt_s = dict.fromkeys(MQTT_PARTS, 0.0)  # CPU s of each, while the clock ran
        self.clocked = False  # the clock runs (``clocked``): the parts count

    def add(self, part: str, seconds: float) -> None:
        """``seconds`` of ``part`` (``step``, ``handle``, ``young_gc``): in its figure while
        the clock runs, else in ``after_s`` (not in ``cpu_s``)."""
        if not self.clocked:
            self.after_s[part] += seconds
        elif part == "step":
            self.step_s += seconds
        elif part == "handle":
            self.handle_s += seconds
        else:
            self.young_gc_s += seconds

    def timed_part(self, function: Callable[..., Any], part: str) -> Callable[..., Any]:
        """``function``, its process time added to ``part`` (``add``)."""
        def timed(*args: Any) -> Any:
            t0_s = self.clock()
            try:
                return function(*args)
            finally:
                self.add(part, self.clock() - t0_s)

        return timed

    def _on_gc(self, phase: str, info: dict[str, Any]) -> None:
        if info["generation"] != 0:
            return
        if phase == "start":
            self._gc_t0_s = self.clock()
        else:
            self.add("young_gc", self.clock() - self._gc_t0_s)

    fall_backs = replans = 0  # the drives run ahead (``sim.lookahead``) that fell back, replanned

    def install(self) -> None:
        """Wrap the two parts, count every link's ``CoalescedSend`` and the drives' fall-backs."""
        from odocan.host.mqtt import client
        from odocan.sim.lookahead import PlannedVehicle

        fall_back, replan = PlannedVehicle._fall_back, PlannedVehicle.replan

        def counted_fall_back(vehicle: PlannedVehicle) -> None:
            Parts.fall_backs += 1
            fall_back(vehicle)

        def counted_replan(vehicle: PlannedVehicle, t_s: float, first_block_ticks: int) -> bool:
            Parts.replans += 1
            return replan(vehicle, t_s, first_block_ticks)

        setattr(PlannedVehicle, "_fall_back", counted_fall_back)  # noqa: B010
        setattr(PlannedVehicle, "replan", counted_replan)  # noqa: B010

        parts = self
        made = client.CoalescedSend.__init__

        def making(sender: Any, paho: Any) -> None:
            made(sender, paho)
            parts.senders.append(sender)

        setattr(Fleet, "step", self.timed_part(Fleet.step, "step"))  # noqa: B010 (a bench's)
        setattr(Bridge, "_handle", self.timed_part(Bridge._handle, "handle"))  # noqa: B010
        setattr(client.CoalescedSend, "__init__", making)  # noqa: B010
        gc.callbacks.append(self._on_gc)
        self._time_mqtt()

    def _time_mqtt(self) -> None:
        """Process time of each of ``MQTT_PARTS``' functions, while the clock runs only
        (``cpu_s`` leaves out the set-up and the stop); an inner call of a part inside another
        (a write inside a status's queueing) counts in the outer one only."""
        from odocan.host.mqtt import client, link

        owners = {"publish": link.RobotLink, "status": Bridge, "rates": Bridge}
        busy = [False]
        for part, name in MQTT_FUNCTIONS:
            owner = owners.get(part, client.LinkClient)
            setattr(owner, name, self._timed(getattr(owner, name), part, busy))

    def _timed(self, function: Callable[..., Any], part: str,
               busy: list[bool]) -> Callable[..., Any]:
        parts = self

        def timed(*args: Any) -> Any:
            if busy[0] or not parts.clocked:
                return function(*args)
            busy[0] = True
            t0_s = time.process_time()
            try:
                return function(*args)
            finally:
                parts.mqtt_s[part] += time.process_time() - t0_s
                busy[0] = False

        return timed

    def clocked_run(self, run: Callable[..., Any]) -> Callable[..., Any]:
        """``run`` (the fleet's clock) with ``clocked`` set while it runs."""
        async def clocked(*args: Any, **kwargs: Any) -> Any:
            self.clocked = True
            try:
                return await run(*args, **kwargs)
            finally:
                self.clocked = False

        return clocked

    def line(self, cpu_s: float, robot_ticks: int) -> str:
        """The parts in us per robot-tick, and the socket writes per robot-tick (per
        robot-release in real time: ``robot_ticks`` counts the skipped releases too)."""
        per = robot_ticks / 1e6
        rest = (cpu_s - self.step_s - self.handle_s - self.young_gc_s) / per
        writes = sum(sender.writes for sender in self.senders) / robot_ticks
        mqtt = self.mqtt_s
        loop = rest - sum(v for k, v in mqtt.items() if k != "publish") / per
        split = ", ".join(f"{MQTT_PARTS[k]} {v / per:.1f}" for k, v in mqtt.items())
        after = ", ".join(f"{AFTER_PARTS[k]} {v / per:.1f}" for k, v in self.after_s.items())
        line = (f"  step {self.step_s / per:.1f}, bridge frame handling "
                f"{self.handle_s / per:.1f}, young GC passes {self.young_gc_s / per:.1f}, the "
                f"rest {rest:.1f} us; {writes:.3f} socket writes per robot-tick (the whole run); "
                f"drives fell back {Parts.fall_backs}, replanned {Parts.replans}\n"
                f"  MQTT, us per robot-tick: {split}; the loop and the rest {loop:.1f}\n"
                f"  after the clock (not in cpu_s), us per robot-tick: {after}")
        self.step_s = self.handle_s = self.young_gc_s = 0.0
        self.after_s = dict.fromkeys(self.after_s, 0.0)
        self.mqtt_s = dict.fromkeys(MQTT_PARTS, 0.0)
        Parts.fall_backs = Parts.replans = 0
        self.senders.clear()
        return line


MQTT_PARTS = {  # --parts' MQTT split: part -> its name on the line
    "publish": "publications queued in the frame handling (JSON)",
    "batch": "telemetry bursts to paho", "write": "socket writes",
    "read": "acknowledgements read", "status": "status", "rates": "rates",
}
AFTER_PARTS = {"step": "step", "handle": "bridge frame handling (its drain)",
               "young_gc": "young GC passes"}
MQTT_FUNCTIONS = (("publish", "publish"), ("batch", "publish_batch"), ("write", "flush"),
                  ("write", "_write_soon"), ("read", "_read_all"),
                  ("status", "_publish_status"), ("rates", "_publish_rates"))
PARTS: Parts | None = None  # --parts
REAL_TIME = run_realtime  # the product's clock (--clock real), as fleetrun imports it


def one_run(robots: int, ticks: int, publish_hz: float = 10.0,
            firmware: str = "python", clock: str = "flat") -> str:
    """One run of ``robots`` for ``ticks`` ticks (``clock``: flat out or real time); its line
    of figures."""
    ticking = run_flat if clock == "flat" else REAL_TIME
    setattr(fleetrun, "run_realtime",  # noqa: B010
            ticking if PARTS is None else PARTS.clocked_run(ticking))
    with tempfile.TemporaryDirectory() as tmp:
        started = start_mosquitto(Path(tmp))
        if started is None:
            raise SystemExit("mosquitto is not installed")
        proc, url = started
        try:
            run = FleetRun(fleet=FleetConfig(robots=robots, robot=robot.load("pmir"),
                                             firmware=firmware),
                           duration_s=ticks * TICK_S, broker=url, publish_hz=publish_hz,
                           client_prefix=f"bench-flat-{time.time_ns()}")
            report = asyncio.run(run_fleet(run))
        finally:
            proc.terminate()
            proc.wait()
    verdicts = Counter(r["verdict"] for r in report["per_robot"].values())
    per_us = report["cpu_s"] / (report["robots"] * report["ticks"]) * 1e6
    releases = report["ticks"] + report["skipped_releases"]
    per_release = report["cpu_s"] / (report["robots"] * releases) * 1e6
    how = "flat out" if clock == "flat" else (
        f"in real time (deadline_miss_ratio {report['deadline_miss_ratio']:.4f}; "
        f"{per_release:.1f} us per robot-release)")
    line = (f"{robots} robots, {report['ticks']} ticks {how}: {per_us:.1f} us CPU per "
            f"robot-tick (fleet + bridge + MQTT), {report['skipped_releases']} skipped, "
            f"verdicts {dict(verdicts)}, {firmware} firmware, load {os.getloadavg()[0]:.2f}")
    if PARTS is not None:
        line += "\n" + PARTS.line(report["cpu_s"], report["robots"] * releases)
    return line


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=50)
    parser.add_argument("--ticks", type=int, default=600)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--hold-s", type=float, default=None, metavar="S",
                        help="the bridge's frame hold (fleetrun.HOLD_S; 0: every frame judged "
                             "as it comes; trees since host.mqtt.framehold)")
    parser.add_argument("--publish-hz", type=float, default=10.0,
                        help="the bridge's pose telemetry rate per robot (FleetRun.publish_hz)")
    parser.add_argument("--firmware", choices=FIRMWARES, default="python",
                        help="every board's firmware (FleetConfig.firmware)")
    parser.add_argument("--young-gc-every", type=int, default=None, metavar="N",
                        help="the worker's young GC pass every N ticks (0: none while the "
                             "clock runs; default: the tree's own rule)")
    parser.add_argument("--parts", action="store_true",
                        help="the CPU of the step, of the bridge's frame handling, the rest")
    parser.add_argument("--clock", choices=("flat", "real", "both"), default="flat",
                        help="flat out (default), the product's real-time clock, or both "
                             "alternately (a pair per --repeat)")
    args = parser.parse_args()
    if args.young_gc_every is not None:
        fleetrun.TickCollector.every_ticks = args.young_gc_every or 1 << 62
    if args.hold_s is not None:
        setattr(fleetrun, "HOLD_S", args.hold_s)  # noqa: B010 (read by run_fleet)
    if args.parts:
        global PARTS
        PARTS = Parts()
        PARTS.install()
    clocks = ("flat", "real") if args.clock == "both" else (args.clock,)
    for _ in range(args.repeat):
        for clock in clocks:
            print(one_run(args.robots, args.ticks, args.publish_hz, args.firmware, clock),
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
