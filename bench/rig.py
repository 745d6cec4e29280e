"""Lockstep rig throughput: the real-time factor, the per-tick budget by part, the transport's cost.

1. **Real-time factor.** One robot (pmir, random smooth drive for the whole run, exact
   integrator) runs in the lockstep rig for ``--seconds`` of simulated time (default one hour),
   on the ``odocan`` transport and, with ``--virtual``, on python-can ``virtual``; the host
   listener is ``host.io.logs.FrameCollector``, as in ``odocan run``. Wall and CPU time.
2. **Per-tick budget by part** (``--budget-seconds``, default 300 s simulated): the same rig with
   a timer around each part (exclusive times: a part's nested parts are subtracted; the timers'
   own cost, measured on a no-op, is taken out of "the rest"). Each part's share of the timed run
   is then applied to the CPU time per tick of the plain run (1.), so the µs add up to it. The
   scenario's drive runs ahead in blocks (``sim.lookahead``): a block's drivetrain, encoder counts
   and truth are one part, the checks of the rig's calls against it "motors and encoders"; the
   sim node's frames of a block are packed at once (``sim.simplan``: one part) and sent from
   that plan a tick at a time (another: the sends' own cost is the transport's, the motor
   controller's E2E check of MOTOR_CMD is in "E2E", the vehicle's checks in "motors and
   encoders"). The host's FrameCollector hears the frames once per simulated second
   (``sim.tickloop``: it is passive).
3. **The transport, µs per frame per receiver** (CPU time). The frames the rig put on the bus
   are replayed through three fresh handles with no simulation (per tick the sim handle drains
   and sends, the firmware handle drains and sends, the host handle drains: each frame reaches
   two receivers), on ``odocan`` and on python-can ``virtual``; messages are built beforehand.

Targets (issue #13): real-time factor >= 360x as a whole process, transport <= 2 us per frame per
receiver. The machine is shared: wall time counts the other processes too, CPU time (this
process's) does not, so both are printed; the budget and the transport use CPU time. Prints
figures, asserts nothing.
Run: ``.venv/bin/python bench/rig.py [--seconds S] [--budget-seconds S] [--virtual]
[--bitrate B ...] [--firmware c] [--whole] [--profile]`` (``--bitrate``: the rig also timed on a
bit-timed bus; ``--firmware c``: the board runs the C port through ctypes, ``sim.cboard``;
``--whole``: ``odocan run`` of ``--seconds`` timed as a child process, CPU and wall, then with
``--log`` to a file of each ``--whole-log`` suffix, default a candump ``.log``).
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.firmware import frames as fr
from odocan.firmware.e2e import E2EReceiver
from odocan.host.io.logs import FrameCollector
from odocan.sim import motor_controller
from odocan.sim.board import TICK_S
from odocan.sim.lookahead import PlannedVehicle
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from odocan.sim.scenarios import RandomScenario
from odocan.sim.transport import OdocanBus, _Wire

SIM_IDS = frozenset({fr.WHEEL_ENCODERS_ID, fr.MOTOR_CMD_ID, fr.SIM_TRUTH_ID})
CLOCK = time.perf_counter  # the budget's timer (cheap; CPU clocks are system calls)
RTF_TARGET = 360.0
FIRMWARE = ["python"]  # the board's firmware: "python" (firmware/) or "c" (--firmware c)
TRANSPORT_TARGET_US = 2.0


class _Recorder(can.Listener):
    """Keeps every frame the host handle received."""

    def __init__(self) -> None:
        self.messages: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.messages.append(msg)


def make_rig(
    seconds: float,
    listeners: list[can.Listener],
    channel: str,
    transport: str = "odocan",
    bitrate: int | None = None,
) -> LockstepRig:
    """The benchmarked rig: pmir, a random drive lasting the whole run, the firmware ``FIRMWARE``
    names (``--firmware``)."""
    config = RigConfig(
        robot=load("pmir"),
        scenario="random",
        seed=7,
        channel=channel,
        transport=transport,
        bitrate=bitrate,
        firmware=FIRMWARE[0],
        lookahead=True,  # as odocan run
    )
    rig = LockstepRig(config, listeners)
    assert rig.driver is not None
    rig.driver.scenario = RandomScenario(7, duration_s=seconds)
    return rig


def time_rig(
    seconds: float, transport: str, bitrate: int | None = None
) -> tuple[float, float, int, str]:
    """(wall s, CPU s, ticks, bus load note) of the rig over ``seconds`` simulated."""
    listeners: list[can.Listener] = [FrameCollector()]
    with make_rig(seconds, listeners, f"bench-rig-{transport}", transport, bitrate) as rig:
        wall, cpu = time.perf_counter(), time.process_time()
        rig.run(seconds)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        timing = getattr(rig.host_bus, "timing", None)
        load = "" if timing is None else f", bus load {timing.busy_bits / bitrate / seconds:.1%}"
        return wall, cpu, rig.ticks, load


# --- the per-tick budget ---------------------------------------------------------------------


class Budget:
    """Exclusive wall time per part: ``wrap(obj, name, part)`` times every call of a method."""

    def __init__(self) -> None:
        self.totals: dict[str, float] = {}
        self.calls = 0
        self._stack: list[float] = []  # per open call: time spent in nested parts
        self._wrapped: list[tuple[Any, str, Any]] = []

    def wrap(self, obj: Any, name: str, part: str) -> None:
        inner: Callable[..., Any] = getattr(obj, name)
        self._wrapped.append((obj, name, getattr(obj, "__dict__", {}).get(name)))
        self.totals.setdefault(part, 0.0)
        stack, totals, clock = self._stack, self.totals, CLOCK

        def timed(*args: Any, **kwargs: Any) -> Any:
            self.calls += 1
            stack.append(0.0)
            start = clock()
            try:
                return inner(*args, **kwargs)
            finally:
                elapsed = clock() - start
                nested = stack.pop()
                totals[part] += elapsed - nested
                if stack:
                    stack[-1] += elapsed

        setattr(obj, name, timed)

    def restore(self) -> None:
        """Undo every wrap (module functions get their own back, methods their class's)."""
        for obj, name, own in reversed(self._wrapped):
            if own is None:
                delattr(obj, name)
            else:
                setattr(obj, name, own)


def timer_overhead_s(calls: int = 200_000) -> float:
    """CPU s one timed call adds to the part around it (a wrapped no-op minus a bare one)."""

    class Noop:
        def f(self) -> None:
            pass

    bare, timed, b = Noop(), Noop(), Budget()
    b.wrap(timed, "f", "noop")
    costs = []
    for obj in (bare, timed):
        f = obj.f
        start = CLOCK()
        for _ in range(calls):
            f()
        costs.append(CLOCK() - start)
    return max(costs[1] - costs[0], 0.0) / calls


def budget(seconds: float) -> dict[str, float]:
    """Each part's share of a timed run of ``seconds`` simulated (the shares sum to 1)."""
    collector = FrameCollector()
    with make_rig(seconds, [collector], "bench-budget") as rig:
        b = Budget()
        for bus in rig._buses:
            b.wrap(bus, "send", "transport: send (a copy per receiver)")
            if isinstance(bus, OdocanBus):  # the nodes' sends (BusNode.send_frame)
                b.wrap(bus, "send_data", "transport: send (a copy per receiver)")
            b.wrap(bus, "recv", "transport: recv")
            if isinstance(bus, OdocanBus):  # the host's tick at once
                b.wrap(bus, "drain", "transport: recv")
        # The board's common tick takes its frames from its handle's queue (no drain).
        b.wrap(rig.board, "_take_lean", "transport: recv")
        # The wire's delivery itself (the board's HAL transmit goes straight to it).
        b.wrap(_Wire, "deliver_data", "transport: send (a copy per receiver)")
        b.wrap(rig, "step", "rig and node glue (the rest)")
        b.wrap(rig.motor_controller, "send_frame", "node send glue (BusNode.send_frame)")
        b.wrap(rig.truth, "send_frame", "node send glue (BusNode.send_frame)")
        b.wrap(rig.board, "send_frame", "node send glue (BusNode.send_frame)")
        b.wrap(rig.board, "transmit", "node send glue (BusNode.send_frame)")  # the HAL's
        assert rig.driver is not None
        b.wrap(rig.driver, "send_frame", "node send glue (BusNode.send_frame)")
        b.wrap(rig.driver.scenario, "command_at", "scenario (RandomScenario.command_at)")
        vehicle = rig.vehicle
        b.wrap(vehicle, "advance_to", "vehicle: motors and encoders")
        b.wrap(vehicle, "command", "vehicle: motors and encoders")
        b.wrap(vehicle, "encoder_counts", "vehicle: motors and encoders")
        b.wrap(vehicle, "truth", "vehicle: ground truth (vehicle.truth)")
        if isinstance(vehicle, PlannedVehicle):  # the scenario's drive, run a block ahead
            b.wrap(vehicle, "_start_block", "vehicle: a block run ahead (sim.lookahead)")
            # a planned tick's calls, by its substep
            b.wrap(vehicle, "served_command", "vehicle: motors and encoders")
            b.wrap(vehicle, "served_advance", "vehicle: motors and encoders")
        # The sim node's frames of a block packed at once, then sent a tick at a time.
        b.wrap(motor_controller, "plan_ticks", "sim: a block's frames packed (sim.simplan)")
        b.wrap(rig.sim, "_send_planned", "sim: a planned tick (sends, E2E, vehicle)")
        for name in dir(fr):  # both sides call them through the module
            if name.startswith(("pack_", "unpack_")):
                b.wrap(fr, name, "codecs: pack/unpack (E2E CRC included)")
        b.wrap(E2EReceiver, "check", "E2E receive checks (sim and firmware)")
        b.wrap(rig.board.ecu, "isr_can_rx", "firmware: receive ISR")
        b.wrap(rig.board.ecu, "tick", "firmware: tick (odometry, scheduling)")
        b.wrap(collector, "on_message_received", "host: FrameCollector")
        b.wrap(collector, "on_frames", "host: FrameCollector")
        start = CLOCK()
        try:
            rig.run(seconds)
        finally:
            b.restore()
        total = CLOCK() - start - b.calls * timer_overhead_s()
        rest = "rig and node glue (the rest)"
        b.totals[rest] = max(total - sum(t for p, t in b.totals.items() if p != rest), 0.0)
        return {part: t / total for part, t in b.totals.items()}


# --- the transport alone ---------------------------------------------------------------------


def record(seconds: float) -> tuple[list[can.Message], int]:
    """The frames the host handle received over ``seconds`` simulated, and the tick count."""
    recorder = _Recorder()
    with make_rig(seconds, [recorder], "bench-record") as rig:
        rig.run(seconds)
        return recorder.messages, rig.ticks


def schedule(messages: list[can.Message], ticks: int) -> list[tuple[list[can.Message], ...]]:
    """Per tick: (frames the sim handle sent, frames the firmware handle sent), fresh copies."""
    plan: list[tuple[list[can.Message], list[can.Message]]] = [([], []) for _ in range(ticks)]
    for msg in messages:
        k = min(ticks - 1, int(msg.timestamp / TICK_S + 1e-6))
        copy = can.Message(
            timestamp=msg.timestamp,
            arbitration_id=msg.arbitration_id,
            is_extended_id=False,
            data=bytes(msg.data),
        )
        plan[k][0 if msg.arbitration_id in SIM_IDS else 1].append(copy)
    return plan


def _drain(bus: can.BusABC) -> None:
    recv = bus.recv
    while recv(0) is not None:
        pass


def time_replay(plan: list[tuple[list[can.Message], ...]], interface: str) -> float:
    """Wall time (s) of the rig's sends and receives through three bare handles."""
    buses: list[can.BusABC] = [
        OdocanBus("bench-replay", preserve_timestamps=True)
        if interface == "odocan"
        else can.Bus(interface=interface, channel="bench-replay", preserve_timestamps=True)
        for _ in range(3)
    ]
    sim, board, host = buses
    start = time.process_time()
    for sim_frames, board_frames in plan:
        _drain(sim)
        for msg in sim_frames:
            sim.send(msg)
        _drain(board)
        for msg in board_frames:
            board.send(msg)
        _drain(host)
    elapsed = time.process_time() - start
    for bus in buses:
        bus.shutdown()
    return elapsed


def profile(seconds: float, top: int) -> None:
    """Print the top of a cProfile of the rig (by own time)."""
    with make_rig(seconds, [FrameCollector()], "bench-profile") as rig:
        profiler = cProfile.Profile()
        profiler.runcall(rig.run, seconds)
    print(f"\nprofile of {seconds:g} simulated seconds (top {top} by own time):")
    pstats.Stats(profiler).sort_stats("tottime").print_stats(top)


# --- report ----------------------------------------------------------------------------------


def report_rtf(seconds: float, runs: list[tuple[str, int | None]]) -> float:
    """Print the rig's speed on each (transport, bitrate); the CPU s per tick of the first."""
    per_tick: list[float] = []
    for transport, bitrate in runs:
        wall, cpu, ticks, load = time_rig(seconds, transport, bitrate)
        per_tick.append(cpu / ticks)
        rtf = seconds / wall
        verdict = "met" if rtf >= RTF_TARGET else "NOT met"
        bus = "instant" if bitrate is None else f"bit-timed at {bitrate} bit/s{load}"
        print(
            f"lockstep rig on {transport} ({bus}), pmir, random drive, {FIRMWARE[0]} firmware, "
            f"{seconds:g} s simulated"
        )
        print(f"  wall time       {wall:>9.2f} s  ({wall / ticks * 1e6:.1f} us per tick)")
        print(f"  CPU time        {cpu:>9.2f} s  ({cpu / ticks * 1e6:.1f} us per tick)")
        print(
            f"  real-time factor{rtf:>9.0f} x  (CPU: {seconds / cpu:.0f} x; rig only, "
            f"target >= {RTF_TARGET:.0f}x as a whole process: {verdict})"
        )
    return per_tick[0]


def report_whole_process(seconds: float, log: Path | None = None) -> None:
    """``odocan run --scenario random --duration S`` as a child process (what the target counts:
    start-up, the run and the judge), with ``--log`` when given: wall time and the child's CPU
    time (user + system)."""
    argv = [sys.executable, "-m", "odocan", "run", "--scenario", "random", "--duration",
            f"{seconds:g}", "--firmware", FIRMWARE[0]]
    argv += [] if log is None else ["--log", str(log)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    verdict = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else done.stderr
    print(f"\nwhole process: {' '.join(argv[1:])} (exit {done.returncode}: {verdict[:40]})")
    print(
        f"  wall {wall:.2f} s ({seconds / wall:.0f}x real time), CPU {cpu:.2f} s "
        f"({seconds / cpu:.0f}x; target >= {RTF_TARGET:.0f}x: "
        f"{'met' if seconds / cpu >= RTF_TARGET else 'NOT met'} in CPU)"
    )


def report_budget(seconds: float, cpu_per_tick_s: float) -> None:
    shares = budget(seconds)
    print(
        f"\nper-tick budget by part (shares of a timed {seconds:g} s run, applied to the plain "
        f"run's {cpu_per_tick_s * 1e6:.1f} us of CPU per tick)"
    )
    for part, share in sorted(shares.items(), key=lambda item: -item[1]):
        print(f"  {part:<42} {share * cpu_per_tick_s * 1e6:>7.2f} us  {100 * share:>5.1f} %")


def report_transport(seconds: float) -> None:
    messages, ticks = record(seconds)
    receptions = 2 * len(messages)
    print(
        f"\ntransport alone: the rig's {len(messages)} frames of {seconds:g} s replayed, "
        f"each to 2 receivers"
    )
    for interface in ("odocan", "virtual"):
        elapsed = time_replay(schedule(messages, ticks), interface)
        per = elapsed / receptions * 1e6
        note = (
            f"  (target <= {TRANSPORT_TARGET_US:g} us: "
            f"{'met' if per <= TRANSPORT_TARGET_US else 'NOT met'})"
            if interface == "odocan"
            else ""
        )
        print(
            f"  {interface:<8} {per:>6.2f} us per frame per receiver "
            f"({elapsed / ticks * 1e6:.1f} us per tick){note}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3600.0, help="simulated time (s)")
    parser.add_argument(
        "--budget-seconds", type=float, default=300.0, help="simulated time of the budget run"
    )
    parser.add_argument("--virtual", action="store_true", help="also time the rig on virtual")
    parser.add_argument(
        "--bitrate",
        type=int,
        action="append",
        default=[],
        help="also time the rig bit-timed at this bitrate (repeatable)",
    )
    parser.add_argument(
        "--firmware",
        choices=("python", "c"),
        default="python",
        help="the board's firmware: python (firmware/) or c (firmware/c through ctypes)",
    )
    parser.add_argument(
        "--whole",
        action="store_true",
        help="also time `odocan run --scenario random --duration SECONDS` as a whole process",
    )
    parser.add_argument(
        "--whole-log", nargs="*", default=[".log"], metavar="SUFFIX",
        help="--whole also times the run with --log to a file of each suffix (.log .asc .blf)",
    )
    parser.add_argument("--profile", action="store_true", help="also print a cProfile top")
    parser.add_argument("--top", type=int, default=25, help="profile rows to print")
    args = parser.parse_args()
    FIRMWARE[0] = args.firmware
    runs: list[tuple[str, int | None]] = [("odocan", None)]
    runs += [("virtual", None)] if args.virtual else []
    runs += [("odocan", bitrate) for bitrate in args.bitrate]
    cpu_per_tick_s = report_rtf(args.seconds, runs)
    report_budget(args.budget_seconds, cpu_per_tick_s)
    report_transport(min(args.seconds, 600.0))
    if args.whole:
        report_whole_process(args.seconds)
        with tempfile.TemporaryDirectory() as folder:  # a CI job's case: the drive kept
            for suffix in args.whole_log:
                report_whole_process(args.seconds, Path(folder) / f"run{suffix}")
    if args.profile:
        profile(min(args.seconds, 120.0), args.top)


if __name__ == "__main__":
    main()
