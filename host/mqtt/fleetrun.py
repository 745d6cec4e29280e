"""A fleet in real time, bridged to MQTT: what ``odocan fleet`` and ``bench/fleet.py`` run.

``run_fleet`` starts N robots (``sim.fleet``), optionally the bridge (one ``RobotLink`` per robot,
the fleet's frames offered to it each tick), runs for ``duration_s`` and returns the report:

```
{"robots": N, "transport": "odocan" | "virtual", "firmware": "python" | "c",
 "duration_s": ..., "duration_asked_s": ..., "period_s": 0.01,
 "deadline_miss_ratio": ...,
 "ticks": ..., "late_ticks": ..., "skipped_releases": ..., "max_lateness_ms": ...,
 "broker": "mqtt://127.0.0.1:PORT" | null, "embedded_broker": bool,
 "bridge": {"frames_in": ..., "frames_dropped": ..., "telemetry_dropped": ..., ...} | null,
 "per_robot": {"robot001": {"seed": ..., "frames": {"WHEEL_ENCODERS": ..., ...},
                            "frames_total": ..., "commands_accepted": ...,
                            "commands_rejected": ..., "deadline_miss_ratio": ...,
                            "pose_vs_reference": {"max_dpos_m": ..., "max_dheading_rad": ...,
                                                  "samples": ...} | null,
                            "pose_vs_truth": {...} | null,
                            "halt_stretches": {...} (a robot the loop halted: haltstretch),
                            "distance": {...}, "twist": {...} (ODOM_TWIST judged live, as
                            the status's; wrong, a PASS becomes FAIL, as the bridge's),
                            "verdict": "PASS" | "FAIL" | "UNJUDGED" | null, "reason": ...}, ...}}
```

Per robot, the on-board pose is judged against the float64 reference the bridge's tracker steps
with the robot's own accepted encoder frames (``host.judge.tracking.PoseTracker``, paired by
ENC_COUNTER, its start fitted by ``host.judge.livefit``), by the live judge's rule, ``analyze``'s
(``livefit.pose_wrong``): FAIL when a sample's position error beyond its loss allowance exceeds
one LSB (0.1 mm) or its heading error one LSB of HEADING, or with no pose at all; else PASS.
When the loop fell a whole period behind (skipped releases), each robot still sent one
encoder frame per release, the skipped ones' late, each sampled at its own release
(``sim.fleet.Fleet.step``, as ``odocan sim`` does): no step spans several cycles, so the pose
is judged as any other (a firmware that lost frames or time meanwhile has the judges' loss
allowance; before, a skip put several periods under one COUNTER step, which kobuki's firmware
refused, and the robot was UNJUDGED). A loop 10 periods or more behind halts every board
(``sim.board.HALT_AFTER_S``: the firmwares lose frames no judge sees them lose): a robot that
was halted is judged on its samples before the first halt and, after it, stretch by stretch
between the halts, each re-started at the firmware's pose (``host.mqtt.overload``,
``host.mqtt.haltstretch``; ``watch_halts``): FAIL when a sample before or a stretch was wrong,
PASS when the stretches judged samples (the re-starts at the halts not judged, said), else as
before the stretches (UNJUDGED with the numbers of the overload). The error
against the ground truth (SIM_TRUTH) is reported, never judged: it is the odometry's own drift, not
the firmware's arithmetic. When the bridge dropped frames (queue full), the references miss encoder
steps, so no robot is judged (UNJUDGED) and the run fails for that reason instead of blaming a
correct firmware. Without the bridge nothing watches the poses: ``verdict`` is null.
Each robot is judged once, by the bridge's end rule (``host.mqtt.fleetjudge.FleetEndRule``)
when the watch ended, after the clock stopped and before the links say ``offline``: its entry
here and the ``watch_verdict`` its retained ``offline`` status carries are that one judgement
(with the loop's deadline figures against ``max_miss_ratio``, ``loop``).
``failures(report, max_miss_ratio)`` is the run's verdict: the thresholds broken, one line each.

``bridge`` holds ``Bridge.counters()``: frames dropped or failed, telemetry dropped (buffer full)
or not kept while offline, QoS-1 publications dropped or refused by the broker, commands expired,
reconnects. A broker that cannot be reached at the start is a ``BrokerError`` (no traceback).

``cpu_s`` is the CPU time (s) the process spent while the clock ran: every thread, so the fleet,
the bridge and the MQTT I/O, not the set-up; ``cpu_s / (robots * ticks)`` is the CPU per
robot-tick, a figure other load on the machine barely moves (``bench/fleet.py``).

``deadline_miss_ratio`` is the share of 10 ms encoder cycles that started more than half a period
late (``sim.realtime.DeadlineStats``).
"""

from __future__ import annotations

import asyncio
import gc
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any

from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerError, BrokerURL, first_error
from odocan.host.mqtt.clientids import DEFAULT_PREFIX
from odocan.host.mqtt.fleetjudge import (
    DEFAULT_MAX_MISS_RATIO,
    FleetEndRule,
    halted_of,
    watch_halts,
    watched_verdict,
)
from odocan.host.mqtt.framehold import HOLD_S
from odocan.host.mqtt.options import broker_for
from odocan.host.mqtt.ticktrace import TickTrace, from_env
from odocan.host.protocol.secoc import SecocSigner
from odocan.host.stopped import Stopped
from odocan.sim import interrupts
from odocan.sim.board import TICK_S
from odocan.sim.contract import cycle_ticks
from odocan.sim.fleet import Fleet, FleetConfig, run_realtime
from odocan.sim.provision import robot_key
from odocan.sim.realtime import DeadlineStats
from odocan.sim.releasegate import ReleaseGate, phased_start_s


@dataclass(frozen=True)
class FleetRun:
    """What to run: the fleet, for how long, and whether (and where) to bridge it."""

    fleet: FleetConfig
    duration_s: float
    bridge: bool = True
    broker: BrokerURL | None = None  # None: an embedded amqtt broker
    publish_hz: float = 10.0
    client_prefix: str = DEFAULT_PREFIX
    connect_timeout_s: float = 5.0
    command_expiry_s: float = 5.0
    # SecOC (fleet.secoc_key): robots whose bridge is given no key (a misprovisioned bridge: the
    # firmware refuses their secured commands, NACK AUTH_MISSING); every other bridge signs
    secoc_unsigned: frozenset[str] = frozenset()
    # the deadline_miss_ratio its run may reach (``--max-miss-ratio``): each robot's ``offline``
    # status says whether its loop broke it (``fleetjudge.loop_figures``)
    max_miss_ratio: float = DEFAULT_MAX_MISS_RATIO
    # (monotonic epoch, fraction of a period): where this worker's clock starts among the
    # machine's workers (``sim.releasegate.phased_start_s``); None: when it is ready
    clock_phase: tuple[float, float] | None = None


StartHook = Callable[[int, "BrokerURL | None"], None]
ProgressHook = Callable[[DeadlineStats], None]
PROGRESS_PERIOD_S = 0.5


async def run_fleet(
    run: FleetRun, *, on_start: StartHook | None = None, on_progress: ProgressHook | None = None
) -> dict[str, Any]:
    """Run the fleet in real time (bridged when ``run.bridge``); returns the report.
    ``on_start(robots, telemetry broker)`` is called when the clock starts (signals handled);
    ``on_progress(deadline stats so far)`` every ``PROGRESS_PERIOD_S`` while it runs."""
    with Fleet(run.fleet) as fleet:
        trace = from_env(fleet.names[0])  # bench-only (``ODOCAN_TICK_TRACE``), else None
        if not run.bridge:
            stats, cpu_s, stopped = await _paced(fleet, run, None,
                                                 lambda: _started(on_start, fleet, None),
                                                 on_progress, trace)
            return {**_report(run, fleet, stats, None, None, False), "cpu_s": cpu_s,
                    "stopped": stopped, **durations(run.duration_s, stopped)}
        async with broker_for(run.broker) as (url, embedded):
            # each robot judged once, when the watch ends: its report entry, its offline status
            rule = FleetEndRule(fleet, lambda: bridge.frames_dropped + bridge.frames_failed,
                                run.max_miss_ratio)
            bridge = Bridge(_endpoints(fleet, run), end_rule=rule, config=BridgeConfig(
                broker=url, publish_hz=run.publish_hz, client_prefix=run.client_prefix,
                connect_timeout_s=run.connect_timeout_s, command_expiry_s=run.command_expiry_s,
                hold_s=HOLD_S),  # each robot's frames judged in one go (framehold)
                gate=ReleaseGate())  # no slice just before a tick
            watch_halts(fleet, [robot.telemetry for robot in bridge.robots])
            if trace is not None:
                _trace_bridge(trace, bridge)
            stop = asyncio.Event()
            try:
                async with asyncio.TaskGroup() as tg:
                    tg.create_task(bridge.run(stop=stop), name="bridge")
                    await _all_connected(bridge, run.connect_timeout_s + 5.0)
                    stats, cpu_s, stopped = await _paced(
                        fleet, run, bridge.offer, lambda: _started(on_start, fleet, url),
                        on_progress, trace, bridge.gate)
                    rule.stats = stats  # the clock stopped: the loop's figures are final
                    rule.stopped = stopped is not None  # by a signal, before its duration
                    stop.set()
            except BaseExceptionGroup as group:
                raise first_error(group) from None
            return {**_report(run, fleet, stats, bridge, url, embedded, rule.entries),
                    "cpu_s": cpu_s,
                    "stopped": stopped, **durations(run.duration_s, stopped)}


def durations(asked_s: float, stopped: dict[str, Any] | None) -> dict[str, float]:
    """The report's ``duration_s``, the wall-clock seconds that ran (``stopped.done`` when a
    signal ended the run early), and ``duration_asked_s``, the ``--duration`` asked for."""
    done_s = asked_s if stopped is None else float(stopped["done"])
    return {"duration_s": done_s, "duration_asked_s": asked_s}


def _started(on_start: StartHook | None, fleet: Fleet, url: BrokerURL | None) -> None:
    if on_start is not None:
        on_start(len(fleet.names), url)


async def _paced(
    fleet: Fleet, run: FleetRun, on_batch: Any, started: Callable[[], None],
    on_progress: ProgressHook | None = None, trace: TickTrace | None = None,
    gate: ReleaseGate | None = None,
) -> tuple[DeadlineStats, float, dict[str, Any] | None]:
    """Run the fleet until ``run.duration_s`` or SIGINT/SIGTERM, whichever comes first: a
    signal ends the run early, and the report is still written. Returns the deadline figures,
    the CPU seconds this process spent meanwhile (every thread: loop, bridge, MQTT I/O), and the
    report's ``stopped`` (``host.stopped``) when a signal ended it before its duration.
    ``trace`` (``host.mqtt.ticktrace``, bench-only) times each tick's parts; ``gate`` is told
    the releases; the clock starts at ``run.clock_phase`` (``sim.releasegate``)."""
    duration_s = run.duration_s
    stop = asyncio.Event()
    signals: list[int] = []
    loop = asyncio.get_running_loop()

    def on_signal(signum: int) -> None:
        signals.append(signum)
        stop.set()

    handlers = ExitStack()  # the loop's until the run ends, the CLI's latching ones back after
    handlers.enter_context(interrupts.loop_handlers_installed(loop, on_signal))
    await _phase_wait(run.clock_phase)
    started()
    collector = TickCollector(on_batch)
    stats = DeadlineStats(TICK_S, TICK_S / 2)
    after_tick: Callable[[Any], None] = collector.after_tick
    if trace is not None:
        stats = trace.stats(TICK_S, TICK_S / 2)
        after_tick = trace.collector_hook(on_batch, collector.collect_due)
        trace.time_handles()
        if on_progress is not None:
            on_progress = trace.counting(lambda _: "progress", on_progress)
    watcher = None
    if on_progress is not None:
        watcher = asyncio.create_task(_watch(stats, on_progress), name="fleet-progress")
    cpu0_s = time.process_time()
    try:
        await run_realtime(fleet, duration_s=duration_s, on_batch=after_tick, stop=stop,
                           stats=stats, gate=gate)
        done_s = stats.ticks * TICK_S
        stopped = (Stopped(signals[0], round(done_s, 6), duration_s).as_dict()
                   if signals and done_s < duration_s else None)
        return stats, time.process_time() - cpu0_s, stopped
    finally:
        if watcher is not None:
            watcher.cancel()
        collector.close()
        if trace is not None:
            trace.write()
        handlers.close()


async def _phase_wait(phase: tuple[float, float] | None) -> None:
    """Until this worker's clock may start (``FleetRun.clock_phase``; at once when None)."""
    if phase is not None:
        now_s = time.monotonic()
        await asyncio.sleep(phased_start_s(*phase, TICK_S, now_s) - now_s)


class TickCollector:
    """The cyclic GC of a real-time fleet worker: no collection in the middle of a tick.

    Made after the set-up: one full collection, then ``gc.freeze()`` (the long-lived set-up
    objects leave the collector's generations) and the automatic collector off. The automatic
    collector ran large collections at unpredictable points (a gen-0 pass 2-9 ms of CPU, gen-1
    8-20 ms, gen-2 20-55 ms, 50 robots, ``gc.callbacks``): a pause of half a period makes a late
    tick, one of a period a skipped release (UNJUDGED). No generation is collected while the
    clock runs: a worker makes no cyclic garbage (a 50-robot worker run 1 500 ticks without any
    pass left 0 unreachable objects for ``close``'s full collection), so a young pass after each
    tick (``gc.collect(0)``, as before issue #13's fleetcut pass) only walked the tick's
    survivors (~2 000 objects, 7-11 us per robot-tick, 5-7 % of a worker) to find nothing, and
    rarer passes pause longer (16 ms every 50 ticks). A guard against a leak: once the young
    generation's count (tracked objects made less those freed since the latest pass) passes
    ``young_bound`` (a worker's plateaus at ~5.6 k a robot: 280 k at 50), one young pass.
    ``every_ticks`` (``bench/fleet_flat.py --young-gc-every``) brings back a pass every N ticks.
    ``close`` runs the full collection, turns the collector back on as it was and unfreezes."""

    every_ticks = 0  # a young collection after every this many ticks (0: only past the bound)
    young_bound = 2_000_000  # a young collection past this count (a leak: ~0.4 s of CPU)

    def __init__(self, on_batch: Callable[[Any], None] | None) -> None:
        self.on_batch = on_batch
        self.was_enabled = gc.isenabled()
        gc.collect()
        gc.freeze()
        gc.disable()
        self.unreachable = 0  # found by ``close``'s full collection (cyclic garbage left)
        self.ticks = 0  # since the latest young collection

    def after_tick(self, batch: Any) -> None:
        """The tick's frames to ``on_batch``; a young collection only when one is due (the
        class docstring)."""
        if self.on_batch is not None:
            self.on_batch(batch)
        self.collect_due()

    def collect_due(self) -> int:
        """A tick ended: the young collection when one is due; the objects it freed (0: none
        ran)."""
        self.ticks += 1
        if ((self.every_ticks and self.ticks >= self.every_ticks)
                or gc.get_count()[0] > self.young_bound):
            self.ticks = 0
            return gc.collect(0)
        return 0

    def close(self) -> None:
        """The full collection left for the end; the collector as it was before."""
        self.unreachable = gc.collect()
        if self.was_enabled:
            gc.enable()
        gc.unfreeze()


def _trace_bridge(trace: TickTrace, bridge: Bridge) -> None:
    """What the bridge runs, counted by ``trace`` between ticks: each link's publications by
    leaf, the command reader's hand-overs to the event loop."""
    for link in bridge.links:
        link.publish = trace.counting(str, link.publish)  # type: ignore[method-assign]
    for commands in bridge.commands.robots.values():
        commands.wake.set = trace.counting(  # type: ignore[method-assign]
            lambda _: "reader", commands.wake.set)
    bridge._feed = trace.count_fed(bridge._feed)  # type: ignore[method-assign,assignment]


async def _watch(stats: DeadlineStats, on_progress: ProgressHook) -> None:
    """``on_progress(stats)`` every ``PROGRESS_PERIOD_S`` until cancelled."""
    while True:
        await asyncio.sleep(PROGRESS_PERIOD_S)
        on_progress(stats)


async def _all_connected(bridge: Bridge, timeout_s: float) -> None:
    """Start the clock once every link is up (telemetry from tick 0 reaches the broker)."""
    try:
        async with asyncio.timeout(timeout_s):
            for link in bridge.links:
                await link.connected.wait()
    except TimeoutError:
        down = sum(not link.connected.is_set() for link in bridge.links)
        raise BrokerError(f"{down} of {len(bridge.links)} robots not connected to "
                          f"{bridge.config.broker} within {timeout_s:g} s") from None


def _endpoints(fleet: Fleet, run: FleetRun) -> list[RobotEndpoint]:
    p = run.fleet.robot
    geometry = Geometry.of(p)
    return [RobotEndpoint(name, fleet.host_bus(i), geometry, run.fleet.integrator,
                          counter_bits=p.counter_bits, signer=_signer(run, name),
                          profile_name=p.name,
                          publish_phase_s=publish_phase_s(run.fleet.first + i, run.publish_hz))
            for i, name in enumerate(fleet.names)]


def publish_phase_s(index: int, publish_hz: float) -> float:
    """When robot ``index`` (fleet-wide) publishes its first pose after its first sample (s of
    bus time): pairs of robots take turns over the publication period, a pose cycle apart, so a
    worker's telemetry (and its socket writes) is spread over the ticks of a period instead of
    every robot's landing on the same one (odd robots already run a tick out of phase)."""
    if publish_hz <= 0:
        return 0.0
    cycle_s = cycle_ticks("ODOM_POSE_Y", TICK_S) * TICK_S
    turns = max(1, int(1.0 / publish_hz / cycle_s + 1e-9))
    return (index // 2) % turns * cycle_s


def _signer(run: FleetRun, name: str) -> SecocSigner | None:
    """Robot ``name``'s SecOC signer: its own key, derived from the fleet key as its firmware's
    was (``sim.provision``); None without a fleet key or for a robot in ``secoc_unsigned``."""
    key = run.fleet.secoc_key
    if key is None or name in run.secoc_unsigned:
        return None
    return SecocSigner(robot_key(key, name))


def _report(
    run: FleetRun, fleet: Fleet, stats: DeadlineStats, bridge: Bridge | None,
    url: BrokerURL | None, embedded: bool, judged: dict[str, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """The report (module docstring); ``judged``: each robot's verdict entry as the bridge's
    end rule made it when the watch ended (``FleetEndRule.entries``, the verdicts the
    ``offline`` statuses carry), None: judged here (``watched_verdict``)."""
    per_robot = {}
    dropped = 0 if bridge is None else bridge.frames_dropped + bridge.frames_failed
    for i, name in enumerate(fleet.names):
        frames = fleet.frame_counts(i)
        entry: dict[str, Any] = {"seed": run.fleet.seed + run.fleet.first + i, "frames": frames,
                                 "frames_total": sum(frames.values()),
                                 "deadline_miss_ratio": stats.deadline_miss_ratio}
        if bridge is not None:
            robot = bridge.robots[i]
            entry["commands_accepted"] = robot.commands_sent
            entry["commands_rejected"] = robot.commands_rejected
            entry.update(judged[name] if judged is not None else
                         watched_verdict(robot.telemetry, dropped, halted_of(fleet, i, stats)))
        else:
            entry.update(pose_vs_reference=None, pose_vs_truth=None, verdict=None,
                         reason="no bridge: the poses were not watched")
        per_robot[name] = entry
    return {
        "robots": run.fleet.robots,
        "first_robot": fleet.names[0],
        "transport": run.fleet.transport,
        "firmware": run.fleet.firmware,
        "period_s": stats.period_s,
        "deadline_miss_ratio": stats.deadline_miss_ratio,
        "ticks": stats.ticks,
        "late_ticks": stats.late_ticks,
        "skipped_releases": stats.skipped_releases,
        "max_lateness_ms": round(stats.max_lateness_s * 1e3, 3),
        "broker": str(url) if url is not None else None,
        "embedded_broker": embedded,
        "tolerance": {"position_m": POSITION_LSB_M, "heading_rad": HEADING_LSB_RAD},
        "bridge": None if bridge is None else bridge.counters(),
        "per_robot": per_robot,
    }


def failures(report: dict[str, Any], max_miss_ratio: float) -> list[str]:
    """The thresholds a fleet report breaks, one line each (empty: the run passes)."""
    out = []
    ratio = report["deadline_miss_ratio"]
    if ratio > max_miss_ratio:
        out.append(f"deadline_miss_ratio {ratio:.4f} > --max-miss-ratio {max_miss_ratio:g}")
    robots = report["per_robot"]
    for verdict, what in (("FAIL", "failed their verdict"),
                          ("UNJUDGED", "not judged")):
        names = [name for name, r in robots.items() if r.get("verdict") == verdict]
        if names:
            first = robots[names[0]]["reason"]
            out.append(f"{len(names)} of {len(robots)} robots {what} ({names[0]}: {first})")
    return out


def run_verdict(report: dict[str, Any], max_miss_ratio: float) -> str:
    """The run's word: PASS (no threshold broken), FAIL (a robot FAILed, or the loop missed
    its deadlines), else UNJUDGED (robots not judged, none FAILed: a signal that stopped the
    run before a robot's first pose blames no firmware, as ``run``'s partial UNJUDGED)."""
    if not failures(report, max_miss_ratio):
        return "PASS"
    failed = any(r.get("verdict") == "FAIL" for r in report["per_robot"].values())
    return "FAIL" if failed or report["deadline_miss_ratio"] > max_miss_ratio else "UNJUDGED"
