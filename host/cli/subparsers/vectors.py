"""``odocan vectors``: golden vectors (CSV and JSON) for checking a C port bit for bit."""

from __future__ import annotations

import argparse
from pathlib import Path

from odocan.host.judge import vectors
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.rig import INTEGRATORS
from odocan.sim.robot import load
from odocan.sim.scenarios import SCENARIOS


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan vectors``."""
    parser = subparsers.add_parser(
        "vectors",
        help="export golden vectors for a C port",
        description="Export encoder-count inputs and the firmware's exact integer outputs (JSON "
        "and one CSV per case), or --check a directory against the current firmware.",
    )
    parser.add_argument("--integrator", choices=INTEGRATORS, default="exact")
    parser.add_argument("--robot", default="pmir", help="profile name or TOML path")
    parser.add_argument("--scenario", choices=SCENARIOS, default="random")
    parser.add_argument("--duration", type=float, default=10.0, help="scenario seconds")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument(
        "--check", action="store_true", help="verify the vectors in --out instead of writing them"
    )
    parser.set_defaults(func=_do_vectors)


def _do_vectors(args: argparse.Namespace) -> int:
    if args.check:
        vector_set = vectors.read_json(args.out / "vectors.json")
        mismatched = vectors.verify(vector_set) + vectors.verify_csv(vector_set, args.out)
        if mismatched:
            print(f"mismatch in: {', '.join(mismatched)}")
            return 1
        print(f"{args.out}: every case (JSON and CSV) reproduced bit for bit")
        return 0
    if args.duration <= 0:
        raise ConfigurationError(f"--duration must be positive, got {args.duration}")
    robot = load(args.robot)
    cases = [vectors.scenario_case(robot, args.scenario, args.duration, args.seed)]
    cases += vectors.edge_cases(robot.counter_bits)
    paths = vectors.write(vectors.build(robot, args.integrator, cases), args.out)
    print(f"wrote {len(paths)} files to {args.out} ({args.integrator}, {robot.name})")
    return 0
