"""Command-line options and checks that several ``odocan`` subcommands share.

Every number a person types is checked by argparse as it is parsed (``int_in``, ``float_in``:
a range, finite), so a bad value is one line ``error: argument --x: ...`` and exit 2 before
anything runs. ``--duration`` has one meaning per kind of command, said in its help:
simulated seconds in ``run``, wall-clock seconds in the real-time nodes, scenario seconds in
``vectors``.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

from odocan.host.outputs import check_writable
from odocan.sim import robot
from odocan.sim.exceptions import ConfigurationError

LOG_SUFFIXES = (".log", ".asc", ".blf")  # python-can writers by extension
SEED_LIMIT = 2**32  # numpy's SeedSequence takes 32-bit words; one word is enough for a CLI seed
WALL_DURATION_MAX_S = 7 * 86400.0  # a real-time node runs a week at most per invocation
SIM_DURATION_MAX_S = 86400.0  # one simulated day: ~25 min of wall time, ~1 GB of frames held
SIM_DURATION_MIN_S = 0.1  # five on-board poses: less cannot be checked against anything


def int_in(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer in ``[lo, hi]``."""

    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be in [{lo}, {hi}], got {value}")
        return value

    parse.__name__ = "integer"
    return parse


def float_in(lo: float, hi: float, *, lo_open: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite number in ``[lo, hi]`` (``(lo, hi]`` when ``lo_open``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        low_ok = value > lo if lo_open else value >= lo
        if not (math.isfinite(value) and low_ok and value <= hi):
            bracket = "(" if lo_open else "["
            raise argparse.ArgumentTypeError(f"must be in {bracket}{lo:g}, {hi:g}], got {text}")
        return value

    parse.__name__ = "number"
    return parse


def add_seed_argument(parser: argparse.ArgumentParser, what: str = "random seed") -> None:
    """``--seed N``, 0 <= N < 2^32 (default 0)."""
    parser.add_argument(
        "--seed",
        type=int_in(0, SEED_LIMIT - 1),
        default=0,
        metavar="N",
        help=f"{what}, 0 .. 2^32-1 (default: %(default)s)",
    )


def add_robot_argument(
    parser: argparse.ArgumentParser, *, role: str = "profile name", from_log: bool = False,
    live: bool = False,
) -> None:
    """``--robot NAME|PATH`` (default pmir; ``from_log``: None, the log's PROFILE page picks,
    ``host.cli.robotchoice``; ``live``: None, the firmware's first PROFILE page picks,
    ``host.judge.liverobot``)."""
    default = ("the shipped robot whose parameters the log's PROFILE page gives, when exactly "
               "one does (said on stderr); else pmir" if from_log else "pmir")
    if live:
        default = ("the shipped robot whose parameters the firmware's first PROFILE page gives, "
                   "when exactly one does (frames held till it comes, said on stderr); else pmir, "
                   "unless the page is not pmir's: then nothing is judged (UNJUDGED)")
    parser.add_argument(
        "--robot",
        default=None if from_log or live else "pmir",
        help=f"{role} ({', '.join(robot.list_profiles())}) or TOML path (default: {default})",
    )


def add_judge_arguments(parser: argparse.ArgumentParser) -> None:
    """What a judge of a recorded or live bus needs: ``--integrator`` of the float64 reference
    (default: the one ODOM_STATUS reports) and ``--dbc`` (``analyze`` and ``monitor``)."""
    from odocan.host.judge.reference import INTEGRATORS

    parser.add_argument(
        "--integrator",
        choices=INTEGRATORS,
        help="reference integrator (default: the one ODOM_STATUS reports)",
    )
    parser.add_argument(
        "--dbc", type=Path, metavar="PATH", help="DBC to decode with (default: odocan's own)"
    )


def add_firmware_arguments(parser: argparse.ArgumentParser) -> None:
    """The board's firmware: ``--robot``, ``--integrator`` and ``--firmware auto|python|c``
    (``odocan run`` and ``odocan firmware``; ``auto``: ``firmware_choice.resolve_firmware``)."""
    from odocan.host.cli.firmware_choice import AUTO_FIRMWARE, FIRMWARE_CHOICES
    from odocan.sim.rig import INTEGRATORS

    add_robot_argument(parser)
    parser.add_argument(
        "--integrator", choices=INTEGRATORS, default="exact",
        help="on-board integrator (default: exact)",
    )
    parser.add_argument(
        "--firmware", choices=FIRMWARE_CHOICES, default=AUTO_FIRMWARE,
        help="the firmware on the board: python (firmware/) or c (firmware/c, built with make "
        "on first use; bit-exact, about twice as fast); auto: c when it builds and loads, "
        "python otherwise (the output says which, and why) (default: auto)",
    )


def add_duration_argument(parser: argparse.ArgumentParser) -> None:
    """``--duration S`` for real-time nodes: wall-clock seconds (default: until Ctrl-C or
    SIGTERM)."""
    parser.add_argument(
        "--duration",
        type=float_in(0.0, WALL_DURATION_MAX_S, lo_open=True),
        metavar="SECONDS",
        help=f"wall-clock seconds to run, at most {WALL_DURATION_MAX_S:g} "
        "(default: until Ctrl-C or SIGTERM)",
    )


def check_duration(duration_s: float | None) -> None:
    """Refuse a duration that is not a positive, finite number of seconds."""
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise ConfigurationError(
            f"--duration must be a positive number of seconds, got {duration_s}"
        )


def check_log_path(path: Path | None, option: str = "--log") -> None:
    """A log to write: a known format by extension, at a path that can be written."""
    if path is None:
        return
    if path.suffix.lower() not in LOG_SUFFIXES:
        raise ConfigurationError(
            f"{option} {path}: unknown format {path.suffix or '(none)'!r} "
            f"(use {', '.join(LOG_SUFFIXES)})"
        )
    check_writable(path, option)
