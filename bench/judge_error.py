"""The judge's own error on long drives (issue #11 item 1): figures, no assertion.

For each robot, a drive of about 112 km (2 m per 10 ms period, straight runs and arcs) is written
directly as a candump log with the firmware's exact outputs (``tests/synth_log.py``), then
analysed from power-up and from a cut 60 s in (mid-drive: the start fitted). The judge's own
error is its reference against the same float64 odometry started at the firmware's true
internal pose (Q40, BAM64) at the log's first sample: only the start can make them differ.
Also printed: the on-board vs reference error the verdict is made of, and the verdict.

Run: ``.venv/bin/python bench/judge_error.py [--steps N]``.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.reference import Geometry, integrate
from odocan.sim.robot import load
from tests.synth_log import synthesize, wandering_drive


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=56_100, help="encoder periods (2 m each)")
    args = parser.parse_args()
    print(f"{'robot':8} {'integrator':10} {'start':9} {'km':>7} {'judge own error':>16} "
          f"{'vs reference':>13}  verdict  seconds")
    for robot_name, integrator in (("kobuki", "exact"), ("pmir", "rk2"), ("kobuki", "euler")):
        robot = load(robot_name)
        d_left, d_right = wandering_drive(robot, args.steps, 2.0, seed=11)
        synth = synthesize(robot, integrator, d_left, d_right)
        for cut in (0, 6000):
            with tempfile.TemporaryDirectory() as folder:
                start = time.perf_counter()
                analysis = analyze(read_log(synth.write(Path(folder) / "d.log", cut)), robot)
                seconds = time.perf_counter() - start
            x0, y0, h0 = synth.state[cut].pose
            exact = integrate(d_left[cut:], d_right[cut:], Geometry.of(robot), integrator,
                              x0_m=x0, y0_m=y0, heading0_rad=h0)
            ex = np.concatenate(([x0], exact.x_m))[::2]
            ey = np.concatenate(([y0], exact.y_m))[::2]
            own = np.max(np.hypot(analysis.series["reference_x_m"] - ex,
                                  analysis.series["reference_y_m"] - ey))
            vs_ref = analysis.report["onboard_vs_reference"]["max_position_error_m"]
            km = analysis.series["distance_m"][-1] / 1e3
            print(f"{robot_name:8} {integrator:10} {analysis.report['reference_start']:9} "
                  f"{km:7.1f} {own / POSITION_LSB_M:12.4f} LSB {vs_ref / POSITION_LSB_M:9.3f} LSB"
                  f"  {'PASS' if analysis.passed else 'FAIL':7}  {seconds:.2f}")


if __name__ == "__main__":
    main()
