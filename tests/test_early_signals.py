"""SIGTERM during ``odocan run``'s start-up: exit 143 and one line, a log finished or none at all.

An outside tester found two gaps of ``odocan run --duration 3600 --log X`` signalled within its
first half second, before the first frame: a 0-byte log (python-can's writer interrupted after
it opened the file: an unreadable ``.blf``; an ``.asc`` without its footer when the signal
landed in the rig's construction), and once a SIGTERM ignored: the run went on to its end, exit 0.
That one was reproduced with a handler that printed where it ran: the ``Terminated`` it raised
landed in numpy.random's import (a Cython module's initialisation, while the rig built its
scenario), which swallowed it. Here the same moments are made exactly, in-process, by raising
the signal from inside the step concerned (and swallowing it there, as numpy did); then in a
subprocess at several early moments. The contract is the one of a later signal (test_signals.py,
docs/rig.md): 143, never 0; every log python-can can read back, finished; a log opened before
the signal holds no frame, a signal heard before it is opened writes none.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.cli.app import main
from odocan.sim.rig import LockstepRig
from tests.test_signals import _terminate

ROOT = Path(__file__).resolve().parents[1]
OLD_LOG = "an older log, kept\n"
DURATION = "30"  # simulated s: a signal that went unheard costs a whole run of it


def _sigterm_inside(call: Callable[..., Any], *, swallowed: bool = False) -> Callable[..., Any]:
    """``call`` with a SIGTERM raised in the middle of it (after it returned, before its value
    is handed back); ``swallowed``: the exception it raises, if any, lost there (as numpy's
    Cython import lost it)."""

    def signalled(*args: Any, **kwargs: Any) -> Any:
        value = call(*args, **kwargs)
        try:
            signal.raise_signal(signal.SIGTERM)
        except KeyboardInterrupt:
            if not swallowed:
                raise
        return value

    return signalled


def _finished_empty(log: Path) -> None:
    """``log`` is a finished log of its format, with no frame."""
    assert list(can.LogReader(log)) == []
    if log.suffix == ".asc":
        assert log.read_text().rstrip().endswith("End TriggerBlock")
    if log.suffix == ".blf":
        reader = can.BLFReader(log)
        assert (reader.object_count, reader.file_size) == (0, log.stat().st_size)


def _run(log: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    code = main(["run", "--duration", DURATION, "--log", str(log)])
    return code, capsys.readouterr().err.splitlines()


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_sigterm_while_the_log_writer_opens(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    suffix: str,
) -> None:
    """The signal lands in python-can's ``Logger`` once it opened the file: before, the writer
    was lost there and the file left unfinished (a 0-byte ``.blf``)."""
    log = tmp_path / f"drive{suffix}"
    monkeypatch.setattr(can, "Logger", _sigterm_inside(can.Logger))
    code, err = _run(log, capsys)
    assert code == 143
    _finished_empty(log)
    assert err == [f"interrupted (SIGTERM): odocan run stopped before it finished (before its "
                   f"first tick; --log {log}: finished, no frame)"]


@pytest.mark.parametrize("swallowed", [False, True], ids=["raised", "swallowed"])
def test_sigterm_while_the_rig_is_built(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    swallowed: bool,
) -> None:
    """The signal lands in the rig's construction, the log already open: before, raised, it
    left an ``.asc`` without its footer; swallowed (numpy.random's import), the run went on to
    its end and exited 0."""
    log = tmp_path / "drive.asc"
    monkeypatch.setattr(LockstepRig, "__init__",
                        _sigterm_inside(LockstepRig.__init__, swallowed=swallowed))
    code, err = _run(log, capsys)
    assert code == 143
    _finished_empty(log)
    assert err == [f"interrupted (SIGTERM): odocan run stopped before it finished (before its "
                   f"first tick; --log {log}: finished, no frame)"]


def test_a_swallowed_sigterm_before_the_log_stops_the_run_unwritten(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """Swallowed earlier (the firmware chosen, before the log opens): still heard, the run
    stops before its first tick and the log is not written (the file there stays as it was)."""
    from odocan.host.cli.subparsers import run
    from odocan.sim.cboard import board_maker

    log = tmp_path / "drive.blf"
    log.write_text(OLD_LOG)
    monkeypatch.setattr(run, "board_maker", _sigterm_inside(board_maker, swallowed=True))
    code, err = _run(log, capsys)
    assert code == 143
    assert log.read_text() == OLD_LOG
    assert err == [f"interrupted (SIGTERM): odocan run stopped before it finished (before its "
                   f"first tick; --log {log}: not written)"]


def test_sigterm_while_the_log_is_finished(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """The other end: a signal as the rig closes (its log being finished) after its last tick.
    Before, raised there, it left the log without its footer; now the log is finished, with
    every frame, then the signal is heard as one during the analysis: 143 and one line."""
    log = tmp_path / "drive.asc"
    monkeypatch.setattr(LockstepRig, "close", _signal_first(LockstepRig.close))
    code = main(["run", "--duration", "1", "--log", str(log)])
    err = capsys.readouterr().err.splitlines()
    assert code == 143
    assert log.read_text().rstrip().endswith("End TriggerBlock")
    assert len([m for m in can.LogReader(log) if m.arbitration_id == 0x100]) == 100
    assert err == ["interrupted (SIGTERM): odocan run stopped before it finished (after its last "
                   "tick, before the analysis)"]


def _signal_first(call: Callable[..., Any]) -> Callable[..., Any]:
    """``call`` with a SIGTERM raised just before it."""

    def signalled(*args: Any, **kwargs: Any) -> Any:
        signal.raise_signal(signal.SIGTERM)
        return call(*args, **kwargs)

    return signalled


def _start(log: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "odocan", "run", "--duration", "3600", "--log", str(log)],
        cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


@pytest.mark.parametrize("after_s", [None, 0.0, 0.003, 0.02, 0.1],
                         ids=["at-launch", "at-open", "3ms", "20ms", "100ms"])
def test_sigterm_at_early_moments_of_a_real_run(tmp_path: Path, after_s: float | None) -> None:
    """A real process signalled at launch, or ``after_s`` after the log writer truncated the
    file: whatever the moment, never exit 0, never a traceback, and the log as it was (the
    signal came before it was opened) or finished with every frame readable."""
    log = tmp_path / "drive.asc"
    log.write_text(OLD_LOG)
    proc = _start(log)
    deadline = time.monotonic() + 120
    if after_s is not None:
        while log.stat().st_size == len(OLD_LOG) and time.monotonic() < deadline:
            if proc.poll() is not None:
                pytest.fail(f"odocan ended early ({proc.returncode}): {proc.communicate()}")
            time.sleep(0.0002)
        time.sleep(after_s)
    code, out, err = _terminate(proc)
    assert "Traceback" not in err
    if code == -signal.SIGTERM:  # before the interpreter ran odocan's main
        assert log.read_text() == OLD_LOG
        return
    assert code == 143, (out, err)
    if log.read_text() == OLD_LOG:
        return
    frames = list(can.LogReader(log))  # every frame written is readable
    assert log.read_text().rstrip().endswith("End TriggerBlock")
    if frames:
        assert "STOPPED by SIGTERM at " in out, out
    else:
        assert "before its first tick" in err, err
