"""The C port's odometry steps/s natively beside the Python firmware's, on the same counter stream,
then the lockstep rig's real-time factor with either firmware on the board.

Builds ``firmware/c/bench_odometry`` (``-O2``, no sanitizers) into a temporary directory, feeds
both firmwares the same u32-LCG counter stream (pmir and kobuki, every integrator), checks that
their final states are identical, and prints steps/s. Then runs ``LockstepRig`` (random scenario,
exact integrator, no listener) for ``--rig-seconds`` simulated seconds with ``--firmware python``
and ``--firmware c`` (``sim.cboard``, the ``-O2`` shared library through ctypes) and prints the
real-time factor (simulated s / wall s) of the whole rig and the board's own share (its receive
ISR and tick, timed around ``run_tick``), and whether both runs heard the same frames. Prints
figures; asserts nothing. Run: ``.venv/bin/python bench/c_port.py [--py-steps N]
[--rig-seconds S]``.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from odocan.firmware.config import Integrator, derive_constants  # noqa: E402
from odocan.firmware.errors import ErrorMask  # noqa: E402
from odocan.firmware.odometry import Odometry  # noqa: E402
from odocan.sim.rig import LockstepRig, RigConfig, firmware_params  # noqa: E402
from odocan.sim.robot import load  # noqa: E402


def lcg_counts(steps: int, counter_bits: int) -> list[tuple[int, int]]:
    """The counter pairs bench_odometry.c draws: u32 LCG 1664525, 1013904223, seed 1."""
    state = 1
    mask = (1 << counter_bits) - 1
    left = right = 0
    counts = [(0, 0)]
    for _ in range(steps):
        state = (state * 1664525 + 1013904223) & 0xFFFF_FFFF
        d_left = (state >> 16) % 601 - 300
        state = (state * 1664525 + 1013904223) & 0xFFFF_FFFF
        d_right = d_left + (state >> 16) % 81 - 40
        left, right = (left + d_left) & mask, (right + d_right) & mask
        counts.append((left, right))
    return counts


def python_run(robot: str, integrator: str, steps: int) -> tuple[list[int], float]:
    """The Python firmware's final state after ``steps`` steps, and the seconds they took."""
    params = firmware_params(load(robot), integrator)
    errors = ErrorMask()
    odo = Odometry(derive_constants(params, errors), errors)
    counts = lcg_counts(steps, params.counter_bits)
    step = odo.step_counts
    start = time.perf_counter()
    for left, right in counts:
        step(left, right)
    elapsed = time.perf_counter() - start
    state = [odo.x_q40_m, odo.y_q40_m, odo.heading_bam64, odo.heading_turns, odo.distance_q40_m]
    return [*state, errors.bits], elapsed


def c_run(binary: Path, robot: str, integrator: str, steps: int) -> tuple[list[int], float]:
    """bench_odometry's final state after ``steps`` steps, and the process's wall seconds."""
    params = firmware_params(load(robot), integrator)
    argv = [str(binary), str(steps), str(params.integrator), str(params.counts_per_rev)]
    argv += [str(params.wheel_radius_left_nm), str(params.wheel_radius_right_nm)]
    argv += [str(params.wheelbase_nm), str(params.counter_bits)]
    start = time.perf_counter()
    out = subprocess.run(argv, check=True, capture_output=True, text=True).stdout
    return [int(v) for v in out.split()], time.perf_counter() - start


class _Frames:
    """A listener keeping every frame the host hears (id, data), to compare the two firmwares."""

    def __init__(self) -> None:
        self.frames: list[tuple[int, bytes]] = []

    def on_message_received(self, msg: object) -> None:
        self.frames.append((msg.arbitration_id, bytes(msg.data)))  # type: ignore[attr-defined]

    def stop(self) -> None:
        """Nothing to release."""


def rig_run(
    robot: str, firmware: str, seconds: float
) -> tuple[float, float, list[tuple[int, bytes]]]:
    """Wall seconds of the whole rig, of the board (ISRs, tick, bus I/O) and of the ECU's tick
    (its transmits into python-can included) over ``seconds`` simulated seconds, and the frames
    the host heard."""
    frames = _Frames()
    config = RigConfig(robot=load(robot), scenario="random", duration_s=seconds, firmware=firmware)
    rig = LockstepRig(config, [frames])  # type: ignore[list-item]
    board_s = ecu_s = 0.0
    run_tick, ecu_tick = rig.board.run_tick, rig.board.ecu.tick

    def timed_run_tick() -> None:
        nonlocal board_s
        start = time.perf_counter()
        run_tick()
        board_s += time.perf_counter() - start

    def timed_ecu_tick() -> None:
        nonlocal ecu_s
        start = time.perf_counter()
        ecu_tick()
        ecu_s += time.perf_counter() - start

    rig.board.run_tick = timed_run_tick  # type: ignore[method-assign]
    rig.board.ecu.tick = timed_ecu_tick  # type: ignore[method-assign]
    try:
        start = time.perf_counter()
        rig.run(seconds)
        total_s = time.perf_counter() - start
    finally:
        rig.close()
    return total_s, board_s, ecu_s, frames.frames


def rig_table(seconds: float) -> None:
    """The rig's real-time factor with each firmware."""
    print(f"\nlockstep rig, random scenario, exact integrator, {seconds:g} simulated s per run")
    print(
        f"{'robot':<7} {'firmware':<8} {'rig x real time':>16} {'board x real time':>18}"
        f" {'board us/tick':>14} {'ecu.tick us':>12}  same frames"
    )
    for robot in ("pmir", "kobuki"):
        heard: dict[str, list[tuple[int, bytes]]] = {}
        for firmware in ("python", "c"):
            total_s, board_s, ecu_s, heard[firmware] = rig_run(robot, firmware, seconds)
            ticks = round(seconds * 100)
            same = (
                "" if firmware == "python" else ("yes" if heard["c"] == heard["python"] else "NO")
            )
            print(
                f"{robot:<7} {firmware:<8} {seconds / total_s:>16,.1f} {seconds / board_s:>18,.1f}"
                f" {board_s / ticks * 1e6:>14,.1f} {ecu_s / ticks * 1e6:>12,.1f}  {same}"
            )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--py-steps", type=int, default=100_000, help="Python steps per run")
    parser.add_argument("--c-steps", type=int, default=10_000_000, help="C steps per run")
    parser.add_argument(
        "--rig-seconds", type=float, default=120.0, help="simulated s per rig run (0: no rig)"
    )
    args = parser.parse_args()
    if shutil.which("make") is None or shutil.which("gcc") is None:
        print("bench/c_port.py: needs make and gcc")
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        binary = Path(tmp) / "bench_odometry"
        subprocess.run(
            ["make", "-s", "-C", str(ROOT / "firmware" / "c"), f"BUILD={tmp}", str(binary)],
            check=True,
        )
        print(
            f"odometry steps/s: Python {args.py_steps} steps, C {args.c_steps} steps (native -O2)"
        )
        print(
            f"{'robot':<7} {'integrator':<10} {'Python':>12} {'C':>14} {'C/Python':>9}  same state"
        )
        for robot in ("pmir", "kobuki"):
            for integrator in (i.name.lower() for i in Integrator):
                py_state, py_s = python_run(robot, integrator, args.py_steps)
                c_state, _ = c_run(binary, robot, integrator, args.py_steps)
                _, c_s = c_run(binary, robot, integrator, args.c_steps)
                py_rate, c_rate = args.py_steps / py_s, args.c_steps / c_s
                print(
                    f"{robot:<7} {integrator:<10} {py_rate:>12,.0f} {c_rate:>14,.0f}"
                    f" {c_rate / py_rate:>8.0f}x  {'yes' if py_state == c_state else 'NO'}"
                )
    if args.rig_seconds > 0:
        rig_table(args.rig_seconds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
