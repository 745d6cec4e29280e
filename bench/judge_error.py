"""The judge's own error on long drives (issue #11 item 1): figures, no assertion.

For each robot, a drive of about 112 km (2 m per 10 ms period, straight runs and arcs) is written
directly as a candump log with the firmware's exact outputs (``tests/synth_log.py``), then
analysed from power-up and from a cut 60 s in (mid-drive: the start fitted). The judge's own
error is its reference against the same float64 odometry started at the firmware's true
internal pose (Q40, BAM64) at the log's first sample: only the start can make them differ.
Also printed: the on-board vs reference error the verdict is made of, and the verdict.

The live judge (the monitor model, ``host.judge.monitor.BusMonitor``, which the bridge's judge
shares) is fed the same log frame by frame: its own error is its reference at its latest sample
(the start narrowed as the drive went, ``host.judge.livefit``) against the same float64
odometry; with its largest on-board vs reference error and its verdict at the end.

2 m per 10 ms is faster than any ECU build allows, so the judge runs without the firmware's
plausibility bound (``analyze(max_wheel_speed_mm_s=None)``, as tests/test_analysis.py does);
with it, the judge would refuse every step, as the firmware built with that bound would. The
live judge's step gate is widened alike (``_unbounded``).

Run: ``.venv/bin/python bench/judge_error.py [--steps N]``; ``bench/verdicts.py`` calls
``judge_error_rows``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.host.io.logs import parse_candump_line, read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry, integrate
from odocan.sim.robot import RobotProfile, load
from tests.synth_log import synthesize, wandering_drive

LONG_STEPS = 56_100  # 2 m per period: 112 km, over 100 km after the mid-drive cut
MID_DRIVE_CUT = 6_000  # an even encoder frame: the log's first on-board sample names it
CASES = (("kobuki", "exact"), ("pmir", "rk2"), ("kobuki", "euler"))


@dataclass(frozen=True)
class JudgeErrorRow:
    """One analysed long drive: the judge's own error and the verdict, in LSB of X/Y (0.1 mm)."""

    robot: str
    integrator: str
    start: str  # the report's reference_start: "power-up" or "fitted"
    km: float
    own_error_lsb: float
    vs_reference_lsb: float
    passed: bool
    seconds: float
    live_own_error_lsb: float
    live_vs_reference_lsb: float
    live_state: str
    live_us_per_frame: float  # the monitor model's CPU per frame (us)


def judge_error_rows(steps: int = LONG_STEPS) -> list[JudgeErrorRow]:
    """Every robot of ``CASES``, from power-up and from ``MID_DRIVE_CUT`` (mid-drive)."""
    rows = []
    for robot_name, integrator in CASES:
        robot = load(robot_name)
        d_left, d_right = wandering_drive(robot, steps, 2.0, seed=11)
        synth = synthesize(robot, integrator, d_left, d_right)
        for cut in (0, min(MID_DRIVE_CUT, steps // 4 * 2)):  # even: names a pose
            with tempfile.TemporaryDirectory() as folder:
                start = time.perf_counter()
                frames = read_log(synth.write(Path(folder) / "d.log", cut))
                analysis = analyze(frames, robot, max_wheel_speed_mm_s=None)
                seconds = time.perf_counter() - start
            x0, y0, h0 = synth.state[cut].pose
            exact = integrate(d_left[cut:], d_right[cut:], Geometry.of(robot), integrator,
                              x0_m=x0, y0_m=y0, heading0_rad=h0)
            ex = np.concatenate(([x0], exact.x_m))[::2]  # the pose is sent every other frame
            ey = np.concatenate(([y0], exact.y_m))[::2]
            own = np.max(np.hypot(analysis.series["reference_x_m"] - ex,
                                  analysis.series["reference_y_m"] - ey))
            vs_ref = analysis.report["onboard_vs_reference"]["max_position_error_m"]
            live = _live_error(robot, synth.lines(cut), exact)
            rows.append(JudgeErrorRow(
                robot_name, integrator, analysis.report["reference_start"],
                float(analysis.series["distance_m"][-1]) / 1e3, float(own) / POSITION_LSB_M,
                vs_ref / POSITION_LSB_M, analysis.passed, seconds, *live))
    return rows


def _unbounded(robot: RobotProfile) -> RobotProfile:
    """``robot`` as the live judge's step gate (``livepose.StepGate``) sees it without the
    firmware's speed bound (module docstring): 2 m per period is beyond any robot's."""
    return dataclasses.replace(robot, max_wheel_speed_m_s=1e9)


def _live_error(robot: RobotProfile, lines: list[str], exact: Any) -> tuple[float, float, str,
                                                                            float]:
    """The monitor model fed ``lines``: its reference's own error at its latest sample against
    ``exact`` (the float64 odometry from the true start, element k: after k steps), its largest
    on-board vs reference error (LSB), its verdict, and its CPU per frame (us)."""
    messages = [m for m in (parse_candump_line(line.encode()) for line in lines) if m]
    monitor = BusMonitor(_unbounded(robot))
    start = time.process_time()
    for msg in messages:
        monitor.feed(msg, now_s=msg.timestamp)
    cpu_s = time.process_time() - start
    ref = monitor.tracker.reference
    assert ref is not None and ref.seq >= 1
    own = math.hypot(ref.x_m - exact.x_m[ref.seq - 1], ref.y_m - exact.y_m[ref.seq - 1])
    return (own / POSITION_LSB_M, monitor.tracker.vs_reference.max_dpos_m / POSITION_LSB_M,
            monitor.health(messages[-1].timestamp)["state"], cpu_s / len(messages) * 1e6)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=LONG_STEPS, help="encoder periods (2 m each)")
    args = parser.parse_args()
    print(f"{'robot':8} {'integrator':10} {'start':9} {'km':>7} {'judge own error':>16} "
          f"{'vs reference':>13}  verdict  seconds | {'live own error':>15} "
          f"{'vs reference':>13}  live verdict  us/frame")
    for r in judge_error_rows(args.steps):
        print(f"{r.robot:8} {r.integrator:10} {r.start:9} {r.km:7.1f} "
              f"{r.own_error_lsb:12.4f} LSB {r.vs_reference_lsb:9.3f} LSB"
              f"  {'PASS' if r.passed else 'FAIL':7}  {r.seconds:7.2f} | "
              f"{r.live_own_error_lsb:11.4f} LSB {r.live_vs_reference_lsb:9.3f} LSB"
              f"  {r.live_state:12}  {r.live_us_per_frame:8.1f}")

if __name__ == "__main__":
    main()
