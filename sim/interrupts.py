"""Stop signals remembered after their exception was raised (standard library only).

The CLI's SIGTERM handler raises ``Terminated`` wherever the main thread is; third-party code
can lose that exception. One that lands in a C extension's module initialisation (numpy.random's
``_generator``, imported while ``odocan run`` builds its rig) is swallowed there:
``odocan run --duration 3600 --log X`` then went on to its end and exited 0, the SIGTERM
unheard. So the handler also ``latch``es its signal here, and ``sim.realtime.stop_on_signals``
starts with a stop requested when one is latched: the run that follows stops at its first safe
point, even when the exception that should have stopped it never arrived.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
from collections.abc import Callable, Iterator, Mapping
from typing import Any

from odocan.sim.exceptions import Terminated

_latched: list[int] = []  # the signal numbers latched since the last ``clear``, first first


def latch_and_raise(signum: int, frame: object) -> None:
    """The CLI's handler for SIGINT and SIGTERM: ``latch`` the signal, then raise where the
    main thread is (``Terminated`` for SIGTERM, ``KeyboardInterrupt`` for SIGINT), unless
    ``frame`` is importlib's module-lock callback (``_dropped_there``)."""
    latch(signum)
    if _dropped_there(frame):
        return
    raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt


# importlib's weakref callback of a module lock: CPython prints an exception raised in it
# ("Exception ignored in: <function _get_module_lock.<locals>.cb ...>" and a traceback through
# this handler) and drops it, so a Ctrl-C or SIGTERM landing there as odocan imported its modules
# said a traceback before its one line (made exactly in tests/test_early_interrupt_cb.py)
_MODULE_LOCK_CALLBACK = ("<frozen importlib._bootstrap>", "_get_module_lock.<locals>.cb")


def _dropped_there(frame: object) -> bool:
    """``frame`` is where an exception is dropped, not raised (``_MODULE_LOCK_CALLBACK``): the
    latch alone stops the command there (its first safe point), as it did once the exception
    was dropped; nothing printed."""
    code = getattr(frame, "f_code", None)
    return (getattr(code, "co_filename", None), getattr(code, "co_qualname", None)) \
        == _MODULE_LOCK_CALLBACK


def latch(signum: int) -> None:
    """Remember that ``signum`` asked the command to stop (safe in a signal handler)."""
    _latched.append(signum)


def latched() -> int | None:
    """The first signal latched since the last ``clear``, or None."""
    return _latched[0] if _latched else None


def clear() -> None:
    """Forget every latched signal (a command's end: the next one starts unasked)."""
    _latched.clear()


@contextlib.contextmanager
def handlers_installed(handlers: Mapping[signal.Signals, Callable[..., Any]]) -> Iterator[None]:
    """``handlers`` (Python-level) while inside, the previous ones back after; in a thread other
    than the main one (where ``signal.signal`` refuses) none, the block run as it is."""
    previous: dict[signal.Signals, Any] = {}
    try:
        for sig, handler in handlers.items():
            previous[sig] = signal.signal(sig, handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        for sig, before in previous.items():
            signal.signal(sig, before)


@contextlib.contextmanager
def loop_handlers_installed(
    loop: asyncio.AbstractEventLoop, callback: Callable[[int], None]
) -> Iterator[None]:
    """SIGINT and SIGTERM call ``callback(signum)`` from ``loop`` while inside (the signal no
    longer raises in whichever task is running), the Python-level handlers from before back
    after: asyncio's own removal leaves Python's default for SIGINT and SIG_DFL for SIGTERM,
    not the CLI's ``latch_and_raise``. Main thread only: elsewhere none is installed."""
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    handled: list[signal.Signals] = []
    try:
        for sig in previous:
            try:
                loop.add_signal_handler(sig, callback, int(sig))
            except (RuntimeError, ValueError, NotImplementedError):  # not the main thread
                break
            handled.append(sig)
        yield
    finally:
        for sig in handled:
            loop.remove_signal_handler(sig)
            if previous[sig] is not None:
                signal.signal(sig, previous[sig])
