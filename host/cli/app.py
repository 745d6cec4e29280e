"""The ``odocan`` command line: one ``main()``, one module per subcommand (cantools' layout).

Every error a person can cause becomes one line ``error: ...`` on stderr and exit code 2 (a
traceback only with ``--debug``). Exit 1 means "ran, but the check failed" (e.g. out of tolerance).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import NoReturn

import can

from odocan.sim.exceptions import OdocanError

# Each module has add_subparser(subparsers) that sets func=_do_<cmd>(args) -> int.
SUBCOMMANDS = (
    "run",
    "analyze",
    "replay",
    "monitor",
    "sim",
    "firmware",
    "vectors",
    "bridge",
    "fleet",
    "experiment",
    "umbmark",
    "calibrate",
    "busload",
)
VERSION = "0.1.0"
EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2


class UsageError(OdocanError):
    """A bad command line (unknown option, bad value)."""


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are exceptions (turned into one line by ``main``)."""

    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    """The whole command line, every subcommand registered."""
    parser = _Parser(
        prog="odocan",
        description="Fixed-point odometry firmware over CAN: "
        "run the rig, analyze logs, replay drives, monitor a live bus.",
    )
    parser.add_argument("--version", action="version", version=f"odocan {VERSION}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    subparsers.required = True
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"odocan.host.cli.subparsers.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"odocan.host.cli.subparsers.{name}":
                raise
            continue
        module.add_subparser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` (default: sys.argv[1:]) and run the subcommand; returns the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv
    try:
        args = build_parser().parse_args(argv)
        return int(args.func(args))
    except KeyboardInterrupt:
        return EXIT_OK
    except (OdocanError, can.CanError, OSError) as exc:
        if debug:
            raise
        print(f"error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE


def _one_line(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    return " ".join(text.split())


if __name__ == "__main__":
    sys.exit(main())
