"""Command-line options and checks that several ``odocan`` subcommands share."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from odocan.sim import robot
from odocan.sim.exceptions import ConfigurationError

LOG_SUFFIXES = (".log", ".asc", ".blf")  # python-can writers by extension


def add_robot_argument(parser: argparse.ArgumentParser, *, role: str = "profile name") -> None:
    """``--robot NAME|PATH`` (default pmir)."""
    parser.add_argument(
        "--robot",
        default="pmir",
        help=f"{role} ({', '.join(robot.list_profiles())}) or TOML path (default: pmir)",
    )


def add_duration_argument(parser: argparse.ArgumentParser) -> None:
    """``--duration S`` for real-time nodes (default: until Ctrl-C or SIGTERM)."""
    parser.add_argument(
        "--duration",
        type=float,
        metavar="SECONDS",
        help="wall-clock seconds to run (default: until Ctrl-C or SIGTERM)",
    )


def check_duration(duration_s: float | None) -> None:
    """Refuse a duration that is not a positive, finite number of seconds."""
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise ConfigurationError(
            f"--duration must be a positive number of seconds, got {duration_s}"
        )


def check_log_path(path: Path | None, option: str = "--log") -> None:
    """A log to write: a known format by extension, in a directory that exists."""
    if path is None:
        return
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise ConfigurationError(
            f"{option} {path}: unknown format {path.suffix or '(none)'!r} "
            f"(use {', '.join(LOG_SUFFIXES)})"
        )
    if not path.parent.is_dir():
        raise ConfigurationError(f"{option} {path}: directory {path.parent} does not exist")
