"""The ``odocan`` command line: one ``main()``, one module per subcommand (cantools' layout).

Every error a person can cause becomes one line ``error: ...`` on stderr and exit code 2 (a
traceback only with ``--debug``). Exit 1 means "ran, but the check failed" (e.g. out of tolerance).

Start-up is part of every command's speed: this module imports neither python-can nor rich (the
command that uses them does), ``--version`` builds no subcommand at all, a named command
builds only its own parser, and a bare ``--help`` reads each command's one-line help from its
module's source without importing it.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import importlib.util
import os
import signal
import sys
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from typing import NoReturn

from odocan import __version__
from odocan.host.cli.dbcfirst import follow_named_dbc
from odocan.host.outputs import outputs_on_stdout
from odocan.sim import interrupts
from odocan.sim.exceptions import OdocanError, Terminated

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
    "key",
)
VERSION = __version__  # one definition, in odocan/__init__.py (pyproject.toml reads it too)
EXIT_OK, EXIT_USAGE = 0, 2
EXIT_SIGNAL_BASE = 128  # the shell's convention: killed by signal N exits 128 + N


class UsageError(OdocanError):
    """A bad command line (unknown option, bad value)."""


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's help shows its default (``none`` when unset), unless the text already
    says it; flags, required options and positionals are left as written."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if (
            "default" in text
            or not action.option_strings
            or action.required
            or action.default is False
            or action.default is argparse.SUPPRESS
        ):
            return text
        if action.default is None or action.default == "" or action.default == []:
            return f"{text} (default: none)"
        return super()._get_help_string(action)


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are exceptions (turned into one line by ``main``), and
    whose help shows every default."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def error(self, message: str) -> NoReturn:
        raise UsageError(message)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole command line, every subcommand registered; with ``only`` (a name in
    ``SUBCOMMANDS``) just that one, so a command imports nothing of the others (start-up); with
    ``only=""`` none (``--version``)."""
    parser = _Parser(
        prog="odocan",
        description="Fixed-point odometry firmware over CAN: "
        "run the rig, analyze logs, replay drives, monitor a live bus.",
    )
    parser.add_argument("--version", action="version", version=f"odocan {VERSION}")
    parser.add_argument(
        "--debug", action="store_true", help="show tracebacks on errors (anywhere on the line)"
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    subparsers.required = True
    for name in SUBCOMMANDS if only is None else tuple(n for n in SUBCOMMANDS if n == only):
        try:
            module = importlib.import_module(f"odocan.host.cli.subparsers.{name}")
        except ImportError as exc:  # e.g. an optional dependency missing: say so when it is used
            _add_unavailable(subparsers, name, exc)
            continue
        module.add_subparser(subparsers)
    return parser


def summary_parser() -> argparse.ArgumentParser | None:
    """The parser bare ``odocan --help`` prints, built without importing any subcommand: each
    command's one-line help is read from the ``help=`` literal of its module's ``add_parser``
    call (0.4-0.7 s of imports saved). None when one cannot be read so: then build them all."""
    parser = build_parser(only="")
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name in SUBCOMMANDS:
        text = _help_literal(name)
        if text is None:
            return None
        subparsers.add_parser(name, help=text)
    return parser


def _help_literal(name: str) -> str | None:
    """The string literal given as ``help=`` to ``add_parser(name, ...)`` in
    ``subparsers/<name>.py``, read from its source; None if there is no such literal."""
    spec = importlib.util.find_spec(f"odocan.host.cli.subparsers.{name}")
    if spec is None or spec.origin is None:
        return None
    with open(spec.origin, encoding="utf-8") as source:
        tree = ast.parse(source.read())
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "add_parser"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and node.args[0].value == name
        ):
            for keyword in node.keywords:
                if keyword.arg == "help" and isinstance(keyword.value, ast.Constant):
                    return str(keyword.value.value)
    return None


def _add_unavailable(
    subparsers: argparse._SubParsersAction[_Parser], name: str, exc: ImportError
) -> None:
    """Register ``name`` as a subcommand that explains why it cannot run (cantools does the same
    for its plugins), instead of dropping it from the command line without a word."""
    reason = f"odocan {name} is unavailable: {exc}"
    parser = subparsers.add_parser(name, help=f"(unavailable: {exc})", add_help=False)
    parser.add_argument("rest", nargs=argparse.REMAINDER)

    def unavailable(args: argparse.Namespace) -> int:
        raise UsageError(reason)

    parser.set_defaults(func=unavailable)


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` (default: sys.argv[1:]) and run the subcommand; returns the exit code.

    ``--debug`` is taken anywhere before a ``--``. SIGTERM is handled as SIGINT (Ctrl-C) while
    the command runs: a command that stops on it with its verdict (run, replay, monitor, fleet,
    bridge ...) exits as it says; one interrupted before its verdict (analyze, or any command
    still starting) says so on stderr and exits 130 (SIGINT) or 143 (SIGTERM), never 0 -- a CI
    job killed by its timeout must not read as a pass. A closed stdout (``odocan run | head -1``)
    ends the command quietly with 141, as SIGPIPE ends a writer: under ``set -o pipefail`` a
    FAIL piped to ``head`` must not read as a pass either.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    argv, debug = split_debug(argv)
    args: argparse.Namespace | None = None
    try:
        with sigterm_as_interrupt():
            follow_named_dbc(argv, named_command(argv))  # before any judge reads a DBC
            parser = summary_parser() if argv in (["-h"], ["--help"]) else None
            args = (parser or build_parser(named_command(argv))).parse_args(argv)
            args.debug = debug  # split off above; bridge/fleet show library logs with it
            _quiet_broken_pipe_in_rich()
            with outputs_on_stdout(args):  # --report -: the report alone on stdout
                return int(args.func(args))
    except KeyboardInterrupt as exc:
        return _interrupted(exc, named_command(argv), unopened_log(argv, args))
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_SIGNAL_BASE + int(signal.SIGPIPE)
    except Exception as exc:
        if not is_usage_error(exc):
            raise
        if debug:  # the traceback too, but the same exit code: --debug must not turn 2 into 1
            traceback.print_exc()
        code = int(getattr(exc, "exit_code", EXIT_USAGE))  # 1: an experiment that failed
        print(f"{'error' if code == EXIT_USAGE else 'FAIL'}: {_one_line(exc)}", file=sys.stderr)
        return code


def _interrupted(exc: KeyboardInterrupt, command: str | None, unopened: str | None) -> int:
    """One line on stderr for a command stopped by a signal before its verdict; 128 + N.
    ``unopened``: ``run``'s ``--log`` when the signal came before it was opened (the words
    say that the file, if one is there, stays as it was)."""
    signum = signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT
    what = f"odocan {command}" if command else "odocan"
    words = str(exc) or ("" if unopened is None else f"--log {unopened}: not written")
    detail = f" ({words})" if words else ""  # e.g. run: before its first tick, its --log
    print(f"interrupted ({signum.name}): {what} stopped before it finished{detail}",
          file=sys.stderr)
    return EXIT_SIGNAL_BASE + int(signum)


def unopened_log(argv: list[str], args: argparse.Namespace | None) -> str | None:
    """``run``'s ``--log`` when the run had not reached the opening of it (``args.log_opened``,
    set by ``run`` as its rig's signals become requests: from there every interruption says
    what became of the log); from ``argv`` when the signal came as it was parsed; else None."""
    if named_command(argv) != "run" or getattr(args, "log_opened", False):
        return None
    if args is not None:
        return None if args.log is None else str(args.log)
    for k, word in enumerate(argv):
        if word.startswith("--log="):
            return word.partition("=")[2]
        if word == "--log" and k + 1 < len(argv):
            return argv[k + 1]
    return None


def is_usage_error(exc: BaseException) -> bool:
    """Whether ``exc`` is one a person causes (odocan's errors, python-can's, I/O): one line,
    exit 2. python-can is looked up only if a command imported it: else none of its errors can
    have been raised, and importing it here would cost every command its start-up."""
    if isinstance(exc, OdocanError | OSError):
        return True
    can = sys.modules.get("can")
    return can is not None and isinstance(exc, can.CanError)


def named_command(argv: list[str]) -> str | None:
    """The subcommand ``argv`` names (its first word, when options such as ``--help`` come
    nowhere before it); ``""`` for a bare ``--version`` (no subcommand needed); or None: then
    the whole parser is built (help, errors list them all)."""
    if argv and argv[0] in SUBCOMMANDS:
        return argv[0]
    if argv == ["--version"]:
        return ""
    return None


def split_debug(argv: list[str]) -> tuple[list[str], bool]:
    """``argv`` without its ``--debug`` flags (those before a ``--``), and whether one was there."""
    end = argv.index("--") if "--" in argv else len(argv)
    kept = [a for a in argv[:end] if a != "--debug"] + argv[end:]
    return kept, len(kept) != len(argv)


_LATCHED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While inside, SIGTERM raises ``KeyboardInterrupt`` as Ctrl-C does, so every command that
    stops cleanly on Ctrl-C (summary, report, logs closed) does so on SIGTERM too; and both are
    ``latch``ed first (``sim.interrupts``): a Ctrl-C in the first second of ``odocan run``,
    whose ``KeyboardInterrupt`` numpy.random's Cython import swallowed, once let the run go
    on to its end (exit 0, or -2 from the interpreter's exit). A signal latched before (the
    command line's early handler, ``odocan.host.cli``) stops the command here: its exception
    may have been lost as odocan loaded. Main thread only (elsewhere a no-op); commands that
    install their own handlers override it."""
    try:
        with interrupts.handlers_installed(
                dict.fromkeys(_LATCHED_SIGNALS, interrupts.latch_and_raise)):
            if (signum := interrupts.latched()) is not None:
                interrupts.latch_and_raise(signum, None)
            yield
    finally:
        interrupts.clear()


def _quiet_broken_pipe_in_rich() -> None:
    """Make rich's hook for a reader of stdout that went away raise ``BrokenPipeError`` (rich
    would exit 1; ``main`` ends quietly, exit 141). Installed once the command line is parsed, so
    ``--version``, ``--help`` and usage errors never import rich."""
    from rich.console import Console

    Console.on_broken_pipe = _on_broken_pipe  # type: ignore[method-assign]


def _on_broken_pipe(self: object) -> None:
    """rich's ``Console.on_broken_pipe``: raise, for ``main`` to end quietly."""
    raise BrokenPipeError


def _silence_stdout() -> None:
    """Point stdout at /dev/null so the interpreter's final flush cannot fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout without a file descriptor (captured in tests)
        pass


def _one_line(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    return " ".join(text.split())


if __name__ == "__main__":
    sys.exit(main())
