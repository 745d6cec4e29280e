"""``python -m tests.sigint_driver MODE ARGS...``: ``odocan`` as ``python -m odocan`` runs it
(Py_RunMain's ``-m`` path, where the interpreter decides the exit status), with a Ctrl-C made
at one exact moment (test_early_sigint.py):

- ``pyrun``: raised as the firmware is chosen (before the log opens) inside a ``PyRun_String``,
  as it is when it lands in a Cython module's initialisation (numpy.random's runs one);
- ``teardown``: raised once ``main`` has returned its exit code, before the interpreter exits;
- ``import``: raised as ``odocan/__main__.py`` imports the command line;
- ``entry``: raised as ``main`` is entered (the signal checked on its first instruction);
- ``environ``: raised by ``main``'s first line (where CI's full run met one at 20 ms);
- ``lost``: raised, and its exception dropped, as ``main`` imports the command's code (as
  CPython drops one landing in importlib's module-lock callback: met under load at 100 ms).
"""

from __future__ import annotations

import builtins
import contextlib
import ctypes
import os
import runpy
import signal
import sys
from typing import Any

PY_FILE_INPUT = 257  # Python.h's Py_file_input


def _raised_in_pyrun() -> None:
    run = ctypes.pythonapi.PyRun_String
    run.restype = ctypes.py_object
    run.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.py_object, ctypes.py_object]
    run(b"import signal\nsignal.raise_signal(signal.SIGINT)\n", PY_FILE_INPUT, {}, {})


def _pyrun(argv: list[str]) -> None:
    from odocan.host.cli import main
    from odocan.host.cli.subparsers import run
    from odocan.sim.cboard import board_maker as chosen

    def signalled(*args: Any, **kwargs: Any) -> Any:
        maker = chosen(*args, **kwargs)
        _raised_in_pyrun()
        return maker

    setattr(run, "board_maker", signalled)  # noqa: B010 (not exported: mypy)
    sys.argv[1:] = argv
    sys.exit(main())


def _teardown(argv: list[str]) -> None:
    from odocan.host.cli import main

    sys.argv[1:] = argv
    code = main()
    signal.raise_signal(signal.SIGINT)
    sys.exit(code)


def _import(argv: list[str]) -> None:
    real = builtins.__import__

    def interrupted(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "odocan.host.cli":
            raise KeyboardInterrupt
        return real(name, *args, **kwargs)

    builtins.__import__ = interrupted
    sys.argv[1:] = argv
    runpy.run_module("odocan", run_name="__main__", alter_sys=True)


def _interrupted(*args: Any, **kwargs: Any) -> Any:
    raise KeyboardInterrupt


def _entry(argv: list[str]) -> None:
    from odocan.host import cli

    setattr(cli, "main", _interrupted)  # noqa: B010 (what __main__.py imports: mypy)
    sys.argv[1:] = argv
    runpy.run_module("odocan", run_name="__main__", alter_sys=True)


def _environ(argv: list[str]) -> None:
    import odocan.host.cli  # noqa: F401 (loaded first: its own imports may set a default too)

    setattr(os.environ, "setdefault", _interrupted)  # noqa: B010 (a method: mypy)
    sys.argv[1:] = argv
    runpy.run_module("odocan", run_name="__main__", alter_sys=True)


def _lost(argv: list[str]) -> None:
    real = builtins.__import__

    def dropped(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "odocan.host.cli.app":
            with contextlib.suppress(KeyboardInterrupt):  # as "Exception ignored in: <function
                signal.raise_signal(signal.SIGINT)  # _get_module_lock...>" dropped it
        return real(name, *args, **kwargs)

    builtins.__import__ = dropped
    sys.argv[1:] = argv
    runpy.run_module("odocan", run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    {"pyrun": _pyrun, "teardown": _teardown, "import": _import, "entry": _entry,
     "environ": _environ, "lost": _lost}[sys.argv[1]](sys.argv[2:])
