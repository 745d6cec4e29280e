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


# --- monitor --log and replay --log: the same start-up and end windows -------------------------


def _monitor(log: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    channel = f"early-monitor-{os.getpid()}-{time.monotonic_ns()}"
    code = main(["monitor", "-i", "virtual", "-c", channel, "--json", "--duration", "60",
                 "--log", str(log)])
    return code, capsys.readouterr().err.splitlines()


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_monitor_sigterm_while_its_log_writer_opens(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    suffix: str,
) -> None:
    """Before, raised in python-can's ``Logger`` the monitor's writer was lost: an ``.asc``
    without its footer. Now the watch ends at once, its log finished with no frame."""
    log = tmp_path / f"heard{suffix}"
    monkeypatch.setattr(can, "Logger", _sigterm_inside(can.Logger))
    code, err = _monitor(log, capsys)
    assert code == 143
    _finished_empty(log)
    assert len(err) == 1, err
    assert err[0].startswith("monitor: STOPPED by SIGTERM at "), err


def test_monitor_swallowed_sigterm_is_heard(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """Swallowed by a library at start-up (as numpy.random's import swallowed run's): before,
    the watch ran its whole 60 s and exited 0; now it ends before it opens its log."""
    from odocan.host.cli.subparsers import monitor
    from odocan.host.judge.monitor import BusMonitor

    log = tmp_path / "heard.asc"
    log.write_text(OLD_LOG)
    monkeypatch.setattr(monitor, "BusMonitor", _sigterm_inside(BusMonitor, swallowed=True))
    code, err = _monitor(log, capsys)
    assert code == 143
    assert log.read_text() == OLD_LOG
    assert err == [f"interrupted (SIGTERM): odocan monitor stopped before it finished (before "
                   f"its watch; --log {log}: not written)"]


def test_monitor_sigterm_while_its_log_is_finished(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """A signal as the watch's log is finished (its --duration over): before, raised there, the
    ``.asc`` lost its footer; now the log is finished, then the signal heard: 143, one line."""
    from odocan.host.report.tui_app import FrameLog

    log = tmp_path / "heard.asc"
    monkeypatch.setattr(FrameLog, "close", _signal_first(FrameLog.close))
    code = main(["monitor", "-i", "virtual", "-c", f"early-end-{os.getpid()}", "--json",
                 "--duration", "0.3", "--log", str(log)])
    err = capsys.readouterr().err.splitlines()
    assert code == 143
    _finished_empty(log)
    assert err == ["interrupted (SIGTERM): odocan monitor stopped before it finished (after its "
                   "watch, before its verdict)"]


@pytest.fixture(scope="module")
def drive_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2 s drive of ``odocan run``, to replay."""
    log = tmp_path_factory.mktemp("drive") / "drive.log"
    assert main(["run", "--duration", "2", "--log", str(log)]) == 0
    return log


def _replay(drive: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    capsys.readouterr()
    code = main(["replay", str(drive), "--log", str(out)])
    return code, capsys.readouterr().err.splitlines()


@pytest.mark.parametrize("swallowed", [False, True], ids=["raised", "swallowed"])
@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_replay_sigterm_while_it_is_built(
    drive_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str], suffix: str, swallowed: bool,
) -> None:
    """The signal lands in the replay's construction, ``--log OUT`` open: before, raised, a
    0-byte log (a ``.blf`` unreadable); swallowed, nothing replayed and exit 2 blaming the DBC."""
    from odocan.host.judge.replay import LockstepReplay

    out = tmp_path / f"replayed{suffix}"
    monkeypatch.setattr(LockstepReplay, "__init__",
                        _sigterm_inside(LockstepReplay.__init__, swallowed=swallowed))
    code, err = _replay(drive_log, out, capsys)
    assert code == 143
    _finished_empty(out)
    assert err == [f"interrupted (SIGTERM): odocan replay stopped before it finished (before its "
                   f"first tick; --log {out}: finished, no frame)"]


def test_replay_swallowed_sigterm_before_its_log_writes_none(
    drive_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Swallowed while the input log is read: heard, the replay stops before its log opens."""
    from odocan.host.cli.subparsers import replay
    from odocan.host.io.logs import read_log

    out = tmp_path / "replayed.blf"
    out.write_text(OLD_LOG)
    monkeypatch.setattr(replay, "read_log", _sigterm_inside(read_log, swallowed=True))
    code, err = _replay(drive_log, out, capsys)
    assert code == 143
    assert out.read_text() == OLD_LOG
    assert err == [f"interrupted (SIGTERM): odocan replay stopped before it finished (before its "
                   f"first tick; --log {out}: not written)"]


def test_replay_sigterm_while_its_log_is_finished(
    drive_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Before, raised in the replay's close the ``.asc`` lost its footer; now it is finished
    with every frame, then the signal is heard as one in the analysis: 143, one line."""
    from odocan.host.judge.replay import LockstepReplay

    out = tmp_path / "replayed.asc"
    monkeypatch.setattr(LockstepReplay, "close", _signal_first(LockstepReplay.close))
    code, err = _replay(drive_log, out, capsys)
    assert code == 143
    assert out.read_text().rstrip().endswith("End TriggerBlock")
    assert len([m for m in can.LogReader(out) if m.arbitration_id == 0x100]) == len(
        [m for m in can.LogReader(drive_log) if m.arbitration_id == 0x100])
    assert err == ["interrupted (SIGTERM): odocan replay stopped before it finished (after its "
                   "last tick, before the analysis)"]


def test_ctrl_c_while_the_command_line_loads_is_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """Ctrl-C ~50 ms after ``python -m odocan`` lands in the import of the command line, before
    ``app.main`` handles anything: before, a traceback and exit -2; now one line and 130."""
    import builtins

    from odocan.host import cli

    real_import = builtins.__import__

    def interrupted(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "odocan.host.cli.app":
            raise KeyboardInterrupt
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", interrupted)
    assert cli.main(["analyze", "x.log"]) == 130
    assert capsys.readouterr().err == ("interrupted (SIGINT): odocan stopped before it finished "
                                       "(while starting)\n")
