"""The judge's own error on long drives (issue #11 item 1): figures, no assertion.

For each robot, a drive of about 112 km (2 m per 10 ms period, straight runs and arcs) is written
directly as a candump log with the firmware's exact outputs (``tests/synth_log.py``), then
analysed from power-up and from a cut 60 s in (mid-drive: the start fitted). The judge's own
error is its reference against the same float64 odometry started at the firmware's true
internal pose (Q40, BAM64) at the log's first sample: only the start can make them differ.
Also printed: the on-board vs reference error the verdict is made of, and the verdict.

2 m per 10 ms is faster than any ECU build allows, so the judge runs without the firmware's
plausibility bound (``analyze(max_wheel_speed_mm_s=None)``, as tests/test_analysis.py does);
with it, the judge would refuse every step, as the firmware built with that bound would.

Run: ``.venv/bin/python bench/judge_error.py [--steps N]``; ``bench/verdicts.py`` calls
``judge_error_rows``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.reference import Geometry, integrate
from odocan.sim.robot import load
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
            rows.append(JudgeErrorRow(
                robot_name, integrator, analysis.report["reference_start"],
                float(analysis.series["distance_m"][-1]) / 1e3, float(own) / POSITION_LSB_M,
                vs_ref / POSITION_LSB_M, analysis.passed, seconds))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=LONG_STEPS, help="encoder periods (2 m each)")
    args = parser.parse_args()
    print(f"{'robot':8} {'integrator':10} {'start':9} {'km':>7} {'judge own error':>16} "
          f"{'vs reference':>13}  verdict  seconds")
    for r in judge_error_rows(args.steps):
        print(f"{r.robot:8} {r.integrator:10} {r.start:9} {r.km:7.1f} "
              f"{r.own_error_lsb:12.4f} LSB {r.vs_reference_lsb:9.3f} LSB"
              f"  {'PASS' if r.passed else 'FAIL':7}  {r.seconds:.2f}")


if __name__ == "__main__":
    main()
