"""Golden vectors for a C port: encoder-count inputs and the firmware's exact integer outputs.

A vector set is one robot configuration (the integer parameters the firmware receives and the Q
constants it derives from them) and several named cases, each a sequence of raw counter pairs with
the odometry state after every pair. A C implementation of the same firmware reproduces every
integer bit for bit. Written as JSON (everything in one file) and as one CSV per case.
"""

from __future__ import annotations

import csv
import json
import random
import re
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from odocan.firmware.config import RobotParams, derive_constants, validate
from odocan.firmware.errors import ErrorMask
from odocan.firmware.odometry import Odometry
from odocan.host.outputs import replaced_together
from odocan.host.protocol.busfacts import ENC_CYCLE_S, ENC_PERIODS_PER_S
from odocan.sim.exceptions import ConfigurationError, OdocanError
from odocan.sim.rig import firmware_params
from odocan.sim.robot import RobotProfile
from odocan.sim.scenarios import get_scenario
from odocan.sim.vehicle import Vehicle

STATE_COLUMNS = ("x_q40_m", "y_q40_m", "heading_bam64", "heading_turns", "distance_q40_m")
CSV_COLUMNS = ("step", "left_count", "right_count", *STATE_COLUMNS)
FORMAT_VERSION = 1


class VectorFormatError(OdocanError):
    """A vector file that cannot be read back."""


@dataclass(frozen=True)
class Case:
    """One named sequence of raw counter pairs (the first pair only primes the odometry)."""

    name: str
    description: str
    counts: list[tuple[int, int]]


def scenario_case(robot: RobotProfile, scenario: str, duration_s: float, seed: int) -> Case:
    """The counters of a simulated drive, sampled every WHEEL_ENCODERS cycle (the DBC's: 10 ms)
    as the motor controller would."""
    vehicle = Vehicle(robot, seed=seed)
    drive = get_scenario(scenario, robot, seed)
    counts = []
    for k in range(round(duration_s * ENC_PERIODS_PER_S) + 1):
        t_s = k * ENC_CYCLE_S
        if k % 2 == 0:
            vehicle.command(*drive.command_at(t_s), t_s)
        vehicle.advance_to(t_s)
        counts.append(vehicle.encoder_counts())
    return Case(f"{scenario}_{seed}", f"scenario {scenario!r}, seed {seed}, {duration_s} s", counts)


def edge_cases(counter_bits: int) -> list[Case]:
    """Hand-made sequences that exercise wraps, special cases and the chord factor's branches."""
    top = 1 << counter_bits
    wrap = [((top - 30 + 7 * k) % top, (top - 20 + 9 * k) % top) for k in range(12)]
    spin = [(-5 * k % top, 5 * k % top) for k in range(50)]
    straight = [(11 * k, 11 * k) for k in range(50)]
    big = [(0, 0), (400, 900), (200, 1500), (-300 % top, 1000), (0, 0)]
    return [
        Case("counter_wrap", f"both counters wrap at 2^{counter_bits}", wrap),
        Case("spin_in_place", "equal and opposite wheel steps", spin),
        Case("straight", "equal wheel steps", straight),
        Case("big_steps", "large per-step deltas (long chord-factor series)", big),
    ]


def random_case(counter_bits: int, steps: int, seed: int) -> Case:
    """``steps`` random counter-delta pairs after a random start: a long set for a C port.

    Mostly driving (deltas up to 300 counts, the two wheels within 40 of each other), with fast
    arbitrary curvature, exact straights and spins, standstill, and a few extreme deltas up to
    half the counter range; the counters wrap at ``2^counter_bits`` many times.
    """
    rng = random.Random(seed)
    top = 1 << counter_bits
    extreme = (top >> 1) - 1
    left, right = rng.randrange(top), rng.randrange(top)
    counts = [(left, right)]
    for _ in range(steps):
        kind = rng.randrange(100)
        if kind < 80:  # driving: both wheels alike
            d_left = rng.randint(-300, 300)
            d_right = d_left + rng.randint(-40, 40)
        elif kind < 88:  # fast, any curvature
            d_left, d_right = rng.randint(-3000, 3000), rng.randint(-3000, 3000)
        elif kind < 92:  # straight
            d_left = d_right = rng.randint(-500, 500)
        elif kind < 96:  # spin in place
            d_left = rng.randint(-500, 500)
            d_right = -d_left
        elif kind < 99:  # standstill or a single count
            d_left, d_right = rng.randint(-1, 1), rng.randint(-1, 1)
        else:  # extreme: up to half the counter range
            d_left, d_right = rng.randint(-extreme, extreme), rng.randint(-extreme, extreme)
        left, right = (left + d_left) % top, (right + d_right) % top
        counts.append((left, right))
    return Case(
        f"random_steps_{seed}",
        f"{steps} random counter steps, seed {seed} (wraps, straights, spins, extremes)",
        counts,
    )


def run_case(params: RobotParams, case: Case) -> list[dict[str, int]]:
    """The firmware's state after each counter pair of ``case``."""
    errors = ErrorMask()
    odo = Odometry(derive_constants(params, errors), errors)
    rows = []
    for step, (left, right) in enumerate(case.counts):
        odo.step_counts(left, right)
        rows.append(
            {
                "step": step,
                "left_count": left,
                "right_count": right,
                **{name: getattr(odo, name) for name in STATE_COLUMNS},
            }
        )
    return rows


def build(robot: RobotProfile, integrator: str, cases: Iterable[Case]) -> dict[str, Any]:
    """The whole vector set as a JSON-ready dict."""
    params = firmware_params(robot, integrator)
    constants = derive_constants(params, ErrorMask())
    return {
        "format_version": FORMAT_VERSION,
        "robot": robot.name,
        "integrator": integrator,
        "params": asdict(params),
        "constants": {**asdict(constants), "integrator": int(constants.integrator)},
        "cases": [
            {"name": c.name, "description": c.description, "rows": run_case(params, c)}
            for c in cases
        ],
    }


def write(vector_set: dict[str, Any], out_dir: Path, option: str = "--out") -> list[Path]:
    """``vectors.json`` and one ``<case>.csv`` per case into ``out_dir`` (made if missing), all
    or none (``replaced_together``: a full disk leaves no partial file and an older set as it
    was; ``OutputError`` naming ``option`` and the directory); returns the paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    cases = vector_set["cases"]
    paths = [out_dir / "vectors.json", *(out_dir / f"{case['name']}.csv" for case in cases)]
    with replaced_together(paths, option, out_dir) as temps:
        temps[0].write_text(json.dumps(vector_set, indent=1) + "\n", encoding="utf-8")
        for case, temp in zip(cases, temps[1:], strict=True):
            with temp.open("w", newline="", encoding="utf-8") as f:
                writer = csv.DictWriter(f, fieldnames=CSV_COLUMNS, lineterminator="\n")
                writer.writeheader()
                writer.writerows(case["rows"])
    return paths


def read_json(path: Path) -> dict[str, Any]:
    """A vector set written by ``write``."""
    try:
        data: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise VectorFormatError(f"{path}: {exc}") from exc
    if not isinstance(data, dict) or data.get("format_version") != FORMAT_VERSION:
        raise VectorFormatError(f"{path}: not an odocan vector file (format_version)")
    problem = _shape_problem(data)
    if problem:
        raise VectorFormatError(f"{path}: not an odocan vector file ({problem})")
    return data


_CASE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")  # a file name in --out, nothing more
_PARAM_NAMES = tuple(RobotParams.__dataclass_fields__)


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _shape_problem(data: dict[str, Any]) -> str:
    """What in a parsed vector file is not as ``build`` writes it ("" when all is): params of
    integers, cases named as plain file names, rows of integers in ``CSV_COLUMNS``."""
    params = data.get("params")
    if not isinstance(params, dict) or sorted(params) != sorted(_PARAM_NAMES) or not all(
        _is_int(v) for v in params.values()
    ):
        return f"params must be the integers {', '.join(_PARAM_NAMES)}"
    cases = data.get("cases")
    if not isinstance(cases, list):
        return "cases must be a list"
    for number, case in enumerate(cases):
        if not isinstance(case, dict) or not isinstance(case.get("name"), str) or \
                not _CASE_NAME.fullmatch(case["name"]):
            return f"case {number}: a plain name (letters, digits, _ . -) is needed"
        rows = case.get("rows")
        if not isinstance(rows, list) or not all(
            isinstance(r, dict) and tuple(r) == CSV_COLUMNS and all(_is_int(v) for v in r.values())
            for r in rows
        ):
            return f"case {case['name']}: rows must hold the integers {', '.join(CSV_COLUMNS)}"
    return ""


def read_csv(path: Path) -> list[dict[str, int]]:
    """The rows of one case CSV, as integers."""
    try:
        with path.open(newline="", encoding="utf-8") as f:
            return [{k: int(v) for k, v in row.items()} for row in csv.DictReader(f)]
    except (OSError, ValueError, TypeError) as exc:
        raise VectorFormatError(f"{path}: {exc}") from exc


def verify(vector_set: dict[str, Any]) -> list[str]:
    """Re-run the current firmware on every case; the names of the cases that differ."""
    params = _params(vector_set)
    mismatched = []
    for case in vector_set["cases"]:
        counts = [(r["left_count"], r["right_count"]) for r in case["rows"]]
        if run_case(params, Case(case["name"], "", counts)) != case["rows"]:
            mismatched.append(case["name"])
    return mismatched


def verify_csv(vector_set: dict[str, Any], out_dir: Path) -> list[str]:
    """Re-run the current firmware on the counts of every case's CSV in ``out_dir`` (what a C
    port most likely reads); the names of the CSV files that differ, are missing or unreadable.
    Each must also hold the same rows as the JSON (a CSV cannot silently drop or add steps)."""
    params = _params(vector_set)
    mismatched = []
    for case in vector_set["cases"]:
        path = out_dir / f"{case['name']}.csv"
        try:
            rows = read_csv(path)
        except VectorFormatError:
            mismatched.append(path.name)
            continue
        counts = [(r.get("left_count", 0), r.get("right_count", 0)) for r in rows]
        if rows != run_case(params, Case(case["name"], "", counts)) or rows != case["rows"]:
            mismatched.append(path.name)
    return mismatched


def _params(vector_set: dict[str, Any]) -> RobotParams:
    """The firmware configuration of a vector set (validated)."""
    try:
        params = RobotParams(**vector_set["params"])
    except (KeyError, TypeError) as exc:
        raise VectorFormatError(f"not an odocan vector set: bad params ({exc})") from None
    if validate(params) != 0:
        raise ConfigurationError("the vector file's parameters are invalid")
    return params
