"""Lockstep rig throughput: the real-time factor beside the bare python-can cost of its frames.

One robot (pmir, random smooth drive for the whole run, exact integrator) runs in the lockstep rig
for ``--seconds`` of simulated time (default: one hour), every frame through three python-can
``virtual`` bus handles. The frames it put on the bus (recorded by a list-appending listener on the
host handle, a fraction of a microsecond per frame) are then replayed through three fresh virtual
handles with no simulation at all: per tick, the sim handle drains and sends its frames, the
firmware handle drains and sends its own, the host handle drains: the same sends and receives, in
the same order, as the rig. The messages are built before the replay is timed, so the replay is
python-can's transport alone.

Targets (issue #3): real-time factor >= 360x, rig / bare python-can <= 2x. Prints figures and
asserts nothing; ``--profile`` adds the top of a cProfile of a shorter rig run.
Run: ``.venv/bin/python bench/rig.py [--seconds S] [--profile]``.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

import can

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.firmware import frames as fr
from odocan.sim.board import TICK_S
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from odocan.sim.scenarios import RandomScenario

SIM_IDS = frozenset({fr.WHEEL_ENCODERS_ID, fr.MOTOR_CMD_ID, fr.SIM_TRUTH_ID})
RTF_TARGET = 360.0
RATIO_TARGET = 2.0


class _Recorder(can.Listener):
    """Keeps every frame the host handle received."""

    def __init__(self) -> None:
        self.messages: list[can.Message] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.messages.append(msg)


def make_rig(seconds: float, listeners: list[can.Listener], channel: str) -> LockstepRig:
    """The benchmarked rig: pmir, a random drive lasting the whole run."""
    rig = LockstepRig(
        RigConfig(robot=load("pmir"), scenario="random", seed=7, channel=channel), listeners
    )
    rig.driver.scenario = RandomScenario(7, duration_s=seconds)
    return rig


def time_rig(seconds: float) -> tuple[float, list[can.Message], int]:
    """Wall time (s) of the rig over ``seconds`` simulated, the frames it sent, its tick count."""
    recorder = _Recorder()
    with make_rig(seconds, [recorder], "bench-rig") as rig:
        start = time.perf_counter()
        rig.run(seconds)
        elapsed = time.perf_counter() - start
        ticks = rig.ticks
    return elapsed, recorder.messages, ticks


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


def time_replay(plan: list[tuple[list[can.Message], ...]]) -> float:
    """Wall time (s) of the same sends and receives through three bare virtual handles."""
    buses = [
        can.Bus(interface="virtual", channel="bench-replay", preserve_timestamps=True)
        for _ in range(3)
    ]
    sim, board, host = buses
    start = time.perf_counter()
    for sim_frames, board_frames in plan:
        _drain(sim)
        for msg in sim_frames:
            sim.send(msg)
        _drain(board)
        for msg in board_frames:
            board.send(msg)
        _drain(host)
    elapsed = time.perf_counter() - start
    for bus in buses:
        bus.shutdown()
    return elapsed


def profile(seconds: float, top: int) -> None:
    """Print the top of a cProfile of the rig (by own time)."""
    with make_rig(seconds, [], "bench-profile") as rig:
        profiler = cProfile.Profile()
        profiler.runcall(rig.run, seconds)
    print(f"\nprofile of {seconds:g} simulated seconds (top {top} by own time):")
    pstats.Stats(profiler).sort_stats("tottime").print_stats(top)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3600.0, help="simulated time (s)")
    parser.add_argument("--profile", action="store_true", help="also print a cProfile top")
    parser.add_argument("--top", type=int, default=25, help="profile rows to print")
    args = parser.parse_args()
    rig_s, messages, ticks = time_rig(args.seconds)
    replay_s = time_replay(schedule(messages, ticks))
    rtf = args.seconds / rig_s
    ratio = rig_s / replay_s
    print(f"lockstep rig, pmir, random drive, {args.seconds:g} s simulated ({ticks} ticks)")
    print(f"  frames on the bus       {len(messages):>10}  ({len(messages) / ticks:.2f} per tick)")
    print(f"  rig wall time           {rig_s:>10.2f} s  ({rig_s / ticks * 1e6:.1f} us per tick)")
    print(
        f"  real-time factor        {rtf:>10.0f} x  (target >= {RTF_TARGET:.0f}x: "
        f"{'met' if rtf >= RTF_TARGET else 'NOT met'})"
    )
    print(
        f"  bare python-can replay  {replay_s:>10.2f} s  "
        f"({replay_s / ticks * 1e6:.1f} us per tick, same sends and receives)"
    )
    print(
        f"  rig / bare python-can   {ratio:>10.2f} x  (target <= {RATIO_TARGET:.0f}x: "
        f"{'met' if ratio <= RATIO_TARGET else 'NOT met'})"
    )
    print(f"  our code per tick       {(rig_s - replay_s) / ticks * 1e6:>10.1f} us")
    if args.profile:
        profile(min(args.seconds, 120.0), args.top)


if __name__ == "__main__":
    main()
