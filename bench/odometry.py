"""Odometry throughput: firmware steps/s beside the float64 reference (scalar and vectorised).

Target (issue #2): >= 200 000 firmware steps/s on the 2-core development machine. Prints figures;
asserts nothing. Run: ``.venv/bin/python bench/odometry.py [--steps N]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from odocan.firmware.config import Integrator, RobotParams, derive_constants
from odocan.firmware.errors import ErrorMask
from odocan.firmware.odometry import Odometry
from odocan.host.judge.reference import Geometry, ReferenceOdometry, integrate
from tests.odo_helpers import smooth_random_counts

PMIR = RobotParams(500, 75_000_000, 75_000_000, 300_000_000, 16, 0)
GEOMETRY = Geometry(500, 0.075, 0.075, 0.3)


def _best_of(runs: int, job: object) -> float:
    assert callable(job)
    best = float("inf")
    for _ in range(runs):
        start = time.perf_counter()
        job()
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=200_000)
    args = parser.parse_args()
    left, right = smooth_random_counts(args.steps, 0.01, GEOMETRY.m_per_count_left, seed=1)
    counts = list(zip((left & 0xFFFF).tolist(), (right & 0xFFFF).tolist(), strict=True))
    dl, dr = left[1:] - left[:-1], right[1:] - right[:-1]
    print(f"odometry, {args.steps} steps of a random drive (pmir robot), best of 3")
    print(f"{'integrator':<10} {'firmware':>14} {'ref scalar':>14} {'ref numpy':>14}")
    for integrator in Integrator:
        name = integrator.name.lower()

        def firmware_run(integrator: Integrator = integrator) -> None:
            params = replace(PMIR, integrator=int(integrator))
            odo = Odometry(derive_constants(params, ErrorMask()), ErrorMask())
            step = odo.step_counts
            for cl, cr in counts:
                step(cl, cr)

        def scalar_run(name: str = name) -> None:
            ref = ReferenceOdometry(GEOMETRY, name, 16)
            step = ref.step_counts
            for cl, cr in counts:
                step(cl, cr)

        def numpy_run(name: str = name) -> None:
            integrate(dl, dr, GEOMETRY, name)

        rates = [args.steps / _best_of(3, job) for job in (firmware_run, scalar_run, numpy_run)]
        print(f"{name:<10} " + " ".join(f"{r:>10,.0f}/s " for r in rates))


if __name__ == "__main__":
    main()
