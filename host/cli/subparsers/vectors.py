"""``odocan vectors``: golden vectors (CSV and JSON) for checking a C port bit for bit."""

from __future__ import annotations

import argparse
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

from odocan.host.cli.options import add_robot_argument, add_seed_argument, float_in, int_in
from odocan.host.judge import vectors
from odocan.host.outputs import OutputError
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.rig import INTEGRATORS, firmware_params
from odocan.sim.robot import load
from odocan.sim.scenarios import SCENARIOS

VECTORS_MAX_S = 3600.0  # scenario seconds: 360 000 rows, tens of MB of CSV
RANDOM_STEPS_MAX = 10_000_000  # a long random case for a C port: about 1 GB of CSV at the top


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan vectors``."""
    parser = subparsers.add_parser(
        "vectors",
        help="export golden vectors for a C port",
        description="Export encoder-count inputs and the firmware's exact integer outputs (JSON "
        "and one CSV per case), or --check a directory against the current firmware.",
    )
    parser.add_argument(
        "--integrator", choices=INTEGRATORS, default="exact", help="on-board integrator"
    )
    add_robot_argument(parser)
    parser.add_argument("--scenario", choices=SCENARIOS, default="random", help="driving scenario")
    parser.add_argument(
        "--duration",
        type=float_in(0.01, VECTORS_MAX_S),
        default=10.0,
        metavar="SECONDS",
        help=f"SCENARIO seconds of the scenario case, 0.01 .. {VECTORS_MAX_S:g} "
        "(default: %(default)s)",
    )
    add_seed_argument(parser)
    parser.add_argument(
        "--random-steps",
        type=int_in(0, RANDOM_STEPS_MAX),
        default=0,
        metavar="N",
        help="add a case of N random counter steps (a long set for a C port; default: none)",
    )
    parser.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="output directory (required)"
    )
    parser.add_argument(
        "--check", action="store_true", help="verify the vectors in --out instead of writing them"
    )
    parser.set_defaults(func=_do_vectors, defaults_of=parser.get_default)


_CASE_OPTIONS = ("scenario", "duration", "seed", "random_steps")


def check_options_apply(args: argparse.Namespace, vector_set: dict[str, Any]) -> None:
    """``--check`` re-runs the robot, integrator and cases the vector file holds: a --robot or
    --integrator other than the file's, or any case option, is refused, not silently ignored
    (``--check --robot kobuki`` of pmir's vectors said 'reproduced bit for bit')."""
    given = [name for name in _CASE_OPTIONS if getattr(args, name) != args.defaults_of(name)]
    if given:
        options = ", ".join(f"--{name.replace('_', '-')}" for name in given)
        raise ConfigurationError(f"--check: {options}: the cases are the vector file's")
    path, integrator = args.out / "vectors.json", vector_set["integrator"]
    if args.integrator not in (integrator, args.defaults_of("integrator")):
        raise ConfigurationError(
            f"--integrator {args.integrator}: {path} is for integrator {integrator}"
        )
    if args.robot != args.defaults_of("robot") and (
        asdict(firmware_params(load(args.robot), integrator)) != vector_set["params"]
    ):
        raise ConfigurationError(
            f"--robot {args.robot}: {path} is for robot {vector_set['robot']}, other parameters"
        )


def _do_vectors(args: argparse.Namespace) -> int:
    if args.check:
        vector_set = vectors.read_json(args.out / "vectors.json")
        check_options_apply(args, vector_set)
        mismatched = vectors.verify(vector_set) + vectors.verify_csv(vector_set, args.out)
        if mismatched:
            print(f"mismatch in: {', '.join(mismatched)}")
            return 1
        print(f"{args.out}: every case (JSON and CSV) reproduced bit for bit")
        return 0
    check_out_dir(args.out)
    robot = load(args.robot)
    cases = [vectors.scenario_case(robot, args.scenario, args.duration, args.seed)]
    cases += vectors.edge_cases(robot.counter_bits)
    if args.random_steps:
        cases.append(vectors.random_case(robot.counter_bits, args.random_steps, args.seed))
    try:
        paths = vectors.write(vectors.build(robot, args.integrator, cases), args.out)
    except OSError as exc:
        raise OutputError(f"--out {args.out}: {exc.strerror or exc}") from None
    print(f"wrote {len(paths)} files to {args.out} ({args.integrator}, {robot.name})")
    return 0


def check_out_dir(out: Path) -> None:
    """``--out``: a writable directory, or one that can be made in a writable parent."""
    target = out
    while not target.exists():
        if target.parent == target:
            break
        target = target.parent
    if not target.is_dir():
        raise ConfigurationError(f"--out {out}: {target} is not a directory")
    if not os.access(target, os.W_OK | os.X_OK):
        raise ConfigurationError(f"--out {out}: {target} is not writable")
