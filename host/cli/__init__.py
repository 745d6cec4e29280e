"""The command line: the parser, shared options, thin subcommands (argparse only).

``main`` imports ``app`` only when called, so that ``python -m odocan.host.cli.app`` runs the
module once, without runpy's "found in sys.modules" warning on stderr.
"""

from __future__ import annotations

import os
import signal
import sys

from odocan.sim import interrupts

__all__ = ["main"]

# numpy's OpenBLAS starts a thread per core when numpy loads; they spin-wait for work no odocan
# command gives them (no large matrix product anywhere: 0.08 s of CPU per process for nothing),
# and a dot product split across them sums in another order, so np.dot of more than ~10^4
# elements (the start fit's sums, ``blockdot.block_dot``) differs in its last bits from
# one machine's core count to another's. One thread: the same bits on every machine, and less
# CPU. A user's own setting is kept; set before numpy is imported (nothing here imports it).
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "1")

STARTING = "interrupted (SIGINT): odocan stopped before it finished (while starting)"
EXIT_SIGNAL_BASE = 128  # app's: killed by signal N exits 128 + N (app may be what did not load)
EXIT_SIGINT = EXIT_SIGNAL_BASE + int(signal.SIGINT)
PY_FILE_INPUT = 257  # Python.h's Py_file_input


def main(argv: list[str] | None = None) -> int:
    """The ``odocan`` command (``odocan.host.cli.app.main``). Called as the program (no
    ``argv``: the console script, ``python -m odocan``), nothing after the command's exit
    code changes it (``_ended``)."""
    try:  # a Ctrl-C at the first line is odocan's too: one line, no traceback (CI met one there)
        os.environ.setdefault(*BLAS_THREADS)
        if argv is None:  # the program: a Ctrl-C from here on is latched (app stops on it)
            signal.signal(signal.SIGINT, interrupts.latch_and_raise)
        from odocan.host.cli.app import main as app_main
    except KeyboardInterrupt:  # Ctrl-C while the command line loads: one line, no traceback
        code = _said(STARTING, EXIT_SIGINT)
    else:
        code = app_main(argv)
    if argv is None:
        _ended(code)
    return code


def _said(line: str, code: int) -> int:
    print(line, file=sys.stderr)
    return code


def _ended(code: int) -> None:
    """The command has its verdict and its exit code ``code``; the interpreter's teardown must
    change neither. A Ctrl-C there was a traceback: SIGINT is ignored from here on (SIGTERM
    back to its default: it still ends a teardown that hangs, silently). And a
    ``KeyboardInterrupt`` that went through a ``PyRun_String`` (a Cython module's
    initialisation runs one: numpy.random's) marks the interpreter, which then ends ``python -m
    odocan`` by SIGINT whatever the code: -2 after the line that said 130 (measured). For an
    exit a signal made (``code`` >= 128) the mark is cleared: CPython clears it as it starts
    evaluating any ``PyRun_String``, so an empty one does (a no-op where there is no such mark,
    or no ``ctypes.pythonapi``)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if code < EXIT_SIGNAL_BASE:
        return
    try:
        import ctypes

        run = ctypes.pythonapi.PyRun_String
    except (ImportError, AttributeError):  # not CPython: no such mark
        return
    run.restype = ctypes.py_object
    run.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.py_object, ctypes.py_object]
    run(b"", PY_FILE_INPUT, {}, {})
