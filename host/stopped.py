"""A command stopped by a signal before it finished what it was asked.

``odocan run --duration 3600`` killed by a CI job's timeout at 787 s used to print PASS and exit
0: CI read a pass for a drive that never finished. A command with a duration (or a log to play)
that a signal stops early still reports what ran -- the summary, the report, the log, all
finished -- but says it stopped (``STOPPED by SIGTERM at 787 s of 3600 s: partial drive PASS``)
and exits as the shell says a signal ends a process: 128 + N (130 for SIGINT, 143 for SIGTERM),
never 0. A command that runs until stopped (no duration asked) ends normally on a signal.

It lives at host/ level, below every room, so judge/ and report/ use it too.
"""

from __future__ import annotations

import signal
import time
from dataclasses import dataclass
from typing import Any

EXIT_SIGNAL_BASE = 128  # the shell's convention: ended by signal N exits 128 + N


@dataclass(frozen=True)
class Stopped:
    """Stopped by ``signum`` after ``done`` of the ``asked`` (both in ``unit``: ``s`` of the
    command's own time -- simulated for run, the log's for replay, the wall's for monitor --
    or ``frames``)."""

    signum: int
    done: float
    asked: float
    unit: str = "s"

    @property
    def signal_name(self) -> str:
        """``SIGTERM``, ``SIGINT``, ..."""
        return signal_name(self.signum)

    @property
    def exit_code(self) -> int:
        """128 + the signal's number."""
        return EXIT_SIGNAL_BASE + self.signum

    def text(self) -> str:
        """``STOPPED by SIGTERM at 787 s of 3600 s``."""
        return stopped_text(self.as_dict())

    def as_dict(self) -> dict[str, Any]:
        """The report's ``stopped``: signal, done, asked, unit."""
        return {"signal": self.signal_name, "done": self.done, "asked": self.asked,
                "unit": self.unit}


def signal_name(signum: int) -> str:
    """The signal's name (``SIG...``), or its number for one Python does not name."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def stopped_text(stopped: dict[str, Any]) -> str:
    """A report's ``stopped`` in words: ``STOPPED by SIGTERM at 787 s of 3600 s``."""
    unit = stopped["unit"]
    return (f"STOPPED by {stopped['signal']} at {stopped['done']:g} {unit} "
            f"of {stopped['asked']:g} {unit}")


def mark_stopped(report: dict[str, Any]) -> bool:
    """A report a signal stopped early: its ``passed`` is false, as the fleet's is (what was
    asked did not run: a CI step reading ``.passed`` must never take a killed drive for a pass),
    and the verdict of the part that ran moves to ``stopped.partial_passed``; returns
    ``passed``. Marking twice keeps the first partial verdict."""
    stopped = report.get("stopped")
    if stopped and "partial_passed" not in stopped:
        stopped["partial_passed"] = bool(report["passed"])
        report["passed"] = False
    return bool(report["passed"])


def partial_verdict(report: dict[str, Any]) -> bool:
    """The verdict of what was judged: ``stopped.partial_passed`` when a signal stopped it,
    else ``passed``."""
    stopped = report.get("stopped") or {}
    return bool(stopped.get("partial_passed", report.get("passed")))


def stop_code(stopped: dict[str, Any]) -> int:
    """The exit code of a report's ``stopped``: 128 + its signal's number."""
    name = str(stopped["signal"])
    number = int(name.split()[-1]) if name.startswith("signal ") else signal.Signals[name]
    return EXIT_SIGNAL_BASE + number


def signum_of(exc: BaseException | None, default: int = signal.SIGINT) -> int:
    """The signal a ``KeyboardInterrupt`` stands for (``Terminated``: SIGTERM)."""
    from odocan.sim.exceptions import Terminated

    return int(signal.SIGTERM) if isinstance(exc, Terminated) else int(default)


def early_stop(signum: int | None, started_s: float, duration_s: float | None) -> Stopped | None:
    """A ``--duration`` command (monitor, bridge) that signal ``signum`` ended before its time,
    ``started_s`` on ``time.monotonic``; None when it ran its time, or ran without one (a signal
    is then its normal end)."""
    if signum is None or duration_s is None:
        return None
    elapsed_s = time.monotonic() - started_s
    if elapsed_s >= duration_s:
        return None
    return Stopped(signum, round(elapsed_s, 1), duration_s)


def interruption(signum: int | None, where: str) -> KeyboardInterrupt:
    """What a signal heard as a request (``sim.realtime.stop_on_signals``) raises once the log
    it deferred to is finished: ``Terminated`` for SIGTERM, else ``KeyboardInterrupt``; ``where``
    ends the CLI's one line (``interrupted (SIGTERM): odocan run stopped before it finished
    (where)``), in brackets, and its exit code is 143 (130)."""
    from odocan.sim.exceptions import Terminated

    return Terminated(where) if signum == signal.SIGTERM else KeyboardInterrupt(where)
