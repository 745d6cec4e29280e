"""Every input of a run, recorded in its report: what ran, on what, with which errors and seeds.

A report that says PASS is evidence only if it says what passed: the robot profile (with a hash of
what the firmware was configured with), the integrator, the injected errors and bus faults, every
seed, the odocan version and the DBC (path and SHA-256).
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from odocan import __version__
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import RobotProfile, profile_sha256


def file_sha256(path: Path) -> str:
    """SHA-256 of a file's bytes (hex), read in blocks (a log of any size)."""
    with path.open("rb") as file:
        return hashlib.file_digest(file, "sha256").hexdigest()


def inputs(
    robot: RobotProfile,
    *,
    integrator: str | None,
    errors: str = "",
    faults: str = "",
    seeds: dict[str, int] | None = None,
    dbc_path: Path = DBC_PATH,
) -> dict[str, Any]:
    """The ``inputs`` section of a report (JSON-ready)."""
    return {
        "robot": {**robot.firmware_params(), "name": robot.name,
                  "sha256": profile_sha256(robot)},
        "integrator": integrator,
        "errors": errors,
        "faults": faults,
        "seeds": dict(seeds or {}),
        "odocan_version": __version__,
        "dbc": {"path": str(dbc_path), "sha256": file_sha256(dbc_path)},
    }
