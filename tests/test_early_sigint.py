"""Ctrl-C (SIGINT) during ``odocan``'s start-up and teardown: one line and exit 130, nothing lost.

Measured from outside (``python -m odocan run --duration 3600 --log x.log``, SIGINT 0-2000 ms
after launch): some runs ended -2 although the line said 130 was meant, some with a traceback.
SIGINT was not latched as SIGTERM is (test_early_signals.py): a ``KeyboardInterrupt`` that
numpy.random's Cython import swallows went unheard, and because it went through a
``PyRun_String`` the interpreter then ended the process by SIGINT whatever the code. These tests
make each moment exactly; the last sweeps real moments (no timing asserted).
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.cli.app import main

ROOT = Path(__file__).resolve().parents[1]
# the interpreter's options fixed: with warning options (PYTHONWARNINGS, dev mode) CPython
# imports ``warnings`` as it starts, and a Ctrl-C there is printed ("'import warnings' failed")
# and dropped, the run going on to its end: the test would wait out its timeout
ENV = {**{k: v for k, v in os.environ.items() if k not in ("PYTHONWARNINGS", "PYTHONDEVMODE")},
       "PYTHONPATH": str(ROOT)}
OLD_LOG = "an older log, kept\n"


def _driver(mode: str, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "tests.sigint_driver", mode, *argv], cwd=ROOT,
                          env=ENV, capture_output=True, text=True, timeout=300)


def _finished_empty(log: Path) -> None:
    assert list(can.LogReader(log)) == []
    assert log.read_text().rstrip().endswith("End TriggerBlock")


def test_a_swallowed_ctrl_c_before_the_log_stops_the_run_unwritten(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
) -> None:
    """Swallowed by a library as the firmware is chosen, before the log opens (SIGTERM's case
    in test_early_signals.py): before, the run went on to its end and replaced the log, exit 0;
    now it stops before its first tick and the file there stays as it was."""
    from odocan.host.cli.subparsers import run
    from odocan.sim.cboard import board_maker as chosen

    log = tmp_path / "drive.asc"
    log.write_text(OLD_LOG)

    def signalled(*args: Any, **kwargs: Any) -> Any:
        maker = chosen(*args, **kwargs)
        with contextlib.suppress(KeyboardInterrupt):  # swallowed, as numpy's import did
            signal.raise_signal(signal.SIGINT)
        return maker

    monkeypatch.setattr(run, "board_maker", signalled)
    code = main(["run", "--duration", "30", "--log", str(log)])
    assert code == 130
    assert log.read_text() == OLD_LOG
    assert capsys.readouterr().err.splitlines() == [
        f"interrupted (SIGINT): odocan run stopped before it finished (before its first tick; "
        f"--log {log}: not written)"]


@pytest.mark.parametrize("log_option", ["--log {}", "--log={}"])
def test_a_ctrl_c_before_the_log_opens_says_it_is_not_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    log_option: str,
) -> None:
    """A real Ctrl-C (no words of its own) as the robot is loaded, or as the command line is
    parsed: the line said only "stopped before it finished", not that ``--log pre.log`` was
    not written (docs/rig.md says it is); the file there stays as it was."""
    from odocan.host.cli import app
    from odocan.sim import robot

    log = tmp_path / "pre.log"
    log.write_text(OLD_LOG)
    argv = ["run", "--duration", "30", *log_option.format(log).split()]

    def interrupted(*args: Any, **kwargs: Any) -> Any:
        raise KeyboardInterrupt

    said = (f"interrupted (SIGINT): odocan run stopped before it finished (--log {log}: not "
            "written)")
    for where, name in ((robot, "load"), (app, "build_parser")):  # app: as it is parsed
        with monkeypatch.context() as patched:
            patched.setattr(where, name, interrupted)
            assert main(argv) == 130
        assert capsys.readouterr().err.splitlines() == [said], name
        assert log.read_text() == OLD_LOG


@pytest.mark.parametrize("mode", ["pyrun", "lost"])
def test_a_ctrl_c_before_the_log_opens_exits_130_unwritten(tmp_path: Path, mode: str) -> None:
    """The real process, an hour's run asked. ``pyrun``: the Ctrl-C raised inside a
    ``PyRun_String`` (a Cython module's initialisation): before, the line said the run
    stopped, then the interpreter ended the process by SIGINT (-2: what the measured runs
    showed). ``lost``: its exception dropped as the command's code is imported (CPython reports
    and drops one landing in importlib's module-lock callback): before, the run went on to its
    end, exit 0, the log replaced (met under load at 100 ms); it is latched from ``main``'s
    first line now. Both: 130, one line, the log as it was."""
    log = tmp_path / "drive.asc"
    log.write_text(OLD_LOG)
    done = _driver(mode, "run", "--duration", "3600", "--log", str(log))
    assert (done.returncode, done.stderr.splitlines()) == (130, [
        f"interrupted (SIGINT): odocan run stopped before it finished (--log {log}: not "
        "written)"])
    assert log.read_text() == OLD_LOG


def test_a_ctrl_c_after_the_verdict_changes_nothing(tmp_path: Path) -> None:
    """Ctrl-C once ``main`` returned (the interpreter's teardown): before, a traceback and -2
    after a PASS; now the command's own exit code, nothing more on stderr."""
    done = _driver("teardown", "run", "--duration", "1", "--log", str(tmp_path / "d.log"))
    assert (done.returncode, done.stderr) == (0, "")
    assert "PASS" in done.stdout


@pytest.mark.parametrize("mode", ["import", "entry", "environ"])
def test_a_ctrl_c_as_the_package_loads_is_one_line(mode: str) -> None:
    """Ctrl-C as ``odocan/__main__.py`` imports the command line, as it enters ``main``, or at
    ``main``'s first line: before, a traceback (CI's full run met the last at 20 ms)."""
    done = _driver(mode, "run", "--duration", "1")
    assert (done.returncode, done.stderr) == (
        130, "interrupted (SIGINT): odocan stopped before it finished (while starting)\n")


def _the_interpreters(err: str) -> bool:
    """True when ``err`` is what the interpreter says for a Ctrl-C before odocan's first line:
    nothing (killed by SIGINT), a fatal error of its initialisation (``init_import_site`` as
    site runs, ``init_sys_streams`` as io loads: met under load at 10 ms), or runpy's traceback
    through frozen frames, after "Could not import runpy module" when the Ctrl-C lands as
    ``-m`` imports runpy itself (CPython's ``pymain_run_module``, exit 1: CI met it at 20 ms).
    The innermost frame may be ``odocan/__init__.py``'s or ``odocan/__main__.py``'s at line 0:
    the Ctrl-C heard by the module's first instruction (3.11's ``RESUME`` checks signals),
    before its first line runs (``_ON_ENTRY``)."""
    if err == "" or "Fatal Python error: init_" in err:
        return True
    err = err.removeprefix("Could not import runpy module\n")
    frames = [line.strip() for line in err.splitlines() if line.lstrip().startswith("File ")]
    if frames and _ON_ENTRY.fullmatch(frames[-1]):
        frames.pop()
    return (err.startswith("Traceback") and err.rstrip().endswith("KeyboardInterrupt")
            and all(line.startswith('File "<frozen ') for line in frames))


# odocan's package or ``__main__`` module entered, none of its lines run yet (line 0)
_ON_ENTRY = re.compile(r'File ".*/odocan/__(init|main)__\.py", line 0, in <module>')


def _without_ignored_interrupts(err: str) -> str:
    """``err`` less the interpreter's "Exception ignored in: <function ...>" blocks whose frames
    are all frozen: a Ctrl-C landing in a callback of importlib's (its module locks' weakref
    callback), which CPython reports and drops whoever handles SIGINT (the full run of the
    twenty-ninth pass met one at 10 ms under load: its one line and exit 130 were right)."""
    kept: list[str] = []
    lines = err.splitlines(keepends=True)
    i = 0
    while i < len(lines):
        if lines[i].startswith("Exception ignored in: <function "):
            j = i + 1
            if j < len(lines) and lines[j].startswith("Traceback"):
                j += 1
            while j < len(lines) and lines[j].startswith('  File "<frozen '):
                j += 1
            if j < len(lines) and lines[j].startswith("KeyboardInterrupt"):
                i = j + 1
                continue
        kept.append(lines[i])
        i += 1
    return "".join(kept)


def test_runpys_own_import_interrupted_is_the_interpreters() -> None:
    """CI's message (a Ctrl-C as ``-m`` imports runpy) is the interpreter's; a traceback
    through odocan's files after the same first line is not."""
    said = ("Could not import runpy module\n"
            "Traceback (most recent call last):\n"
            '  File "<frozen importlib._bootstrap>", line 1176, in _find_and_load\n'
            '  File "<frozen runpy>", line 26, in <module>\n'
            "KeyboardInterrupt\n")
    assert _the_interpreters(said)
    ours = said.replace('"<frozen runpy>"', '"/x/odocan/__main__.py"')
    assert not _the_interpreters(ours)


# A sitecustomize that makes a Ctrl-C pending (``Py_AddPendingCall`` of ``PyErr_SetInterruptEx``)
# as ``exec`` starts the module ODOCAN_TEST_ENTERED ends with: the interpreter runs the call at
# its next check and hears the signal at the next, the module's first instruction
ENTERED_HOOK = """
import ctypes, os, sys
_target = os.environ["ODOCAN_TEST_ENTERED"]
_pend = ctypes.pythonapi.Py_AddPendingCall
_pend.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
_interrupt = ctypes.cast(ctypes.pythonapi.PyErr_SetInterruptEx, ctypes.c_void_p)

def _hook(event, args):
    if event == "exec" and getattr(args[0], "co_filename", "").endswith(_target):
        _pend(_interrupt, 2)  # SIGINT, the int PyErr_SetInterruptEx takes

sys.addaudithook(_hook)
"""


@pytest.mark.parametrize("module", ["__init__.py", "__main__.py"])
def test_a_ctrl_c_as_odocan_is_entered_is_the_interpreters(tmp_path: Path, module: str) -> None:
    """A Ctrl-C heard as ``python -m`` enters ``odocan/__init__.py`` or ``odocan/__main__.py``,
    before their first line (no handler of odocan's can exist yet): CPython's traceback through
    runpy's frozen frames to that module at line 0, killed by SIGINT (3.11's
    ``_Py_UnhandledKeyboardInterrupt``), nothing written. Before, the sweep below refused it
    (a frame outside the frozen modules) and a correct run failed."""
    (tmp_path / "sitecustomize.py").write_text(ENTERED_HOOK)
    log = tmp_path / "drive.asc"
    log.write_text(OLD_LOG)
    done = subprocess.run(
        [sys.executable, "-m", "odocan", "run", "--duration", "3600", "--log", str(log)],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
        env={**ENV, "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}",
             "ODOCAN_TEST_ENTERED": f"{os.sep}odocan{os.sep}{module}"})
    assert done.returncode == -signal.SIGINT, done.stderr
    assert f'odocan{os.sep}{module}", line 0, in <module>' in done.stderr, done.stderr
    assert _the_interpreters(done.stderr), done.stderr
    assert log.read_text() == OLD_LOG


def test_odocans_own_lines_are_not_the_interpreters() -> None:
    """Line 0 of odocan's entry modules only, and only as the innermost frame."""
    said = ("Traceback (most recent call last):\n"
            '  File "<frozen runpy>", line 198, in _run_module_as_main\n'
            '  File "<frozen runpy>", line 88, in _run_code\n'
            '  File "/x/odocan/__main__.py", line 0, in <module>\n'
            "KeyboardInterrupt\n")
    assert _the_interpreters(said)
    assert not _the_interpreters(said.replace("line 0,", "line 12,"))
    assert not _the_interpreters(said.replace("__main__.py", "host/cli/app.py"))
    deeper = said.replace("KeyboardInterrupt\n",
                          '  File "/x/odocan/host/__init__.py", line 7, in <module>\n'
                          "KeyboardInterrupt\n")
    assert not _the_interpreters(deeper)


def test_an_ignored_interrupt_in_importlib_is_not_odocans() -> None:
    """The filter drops only a frozen-frames block ending in KeyboardInterrupt."""
    block = ("Exception ignored in: <function _get_module_lock.<locals>.cb at 0x7f>\n"
             "Traceback (most recent call last):\n"
             '  File "<frozen importlib._bootstrap>", line 442, in cb\n'
             "KeyboardInterrupt: \n")
    line = "interrupted (SIGINT): odocan run stopped before it finished\n"
    assert _without_ignored_interrupts(block + line) == line
    ours = block.replace('"<frozen importlib._bootstrap>"', '"/x/odocan/host/cli/app.py"')
    assert _without_ignored_interrupts(ours + line) == ours + line


@pytest.mark.parametrize("after_ms", [0, 5, 10, 20, 50, 100, 300, 600, 900, 1200])
def test_ctrl_c_at_early_moments_of_a_real_run(tmp_path: Path, after_ms: int) -> None:
    """SIGINT ``after_ms`` after launch. The interpreter's own start-up is out of odocan's
    reach: before it installs its handler the process dies by SIGINT (-2, the shell's 130, no
    line, nothing written); a ``KeyboardInterrupt`` in ``site`` (the editable install's
    ``.pth``) or as ``io`` loads is Python's ``Fatal Python error: init_import_site`` (or
    ``init_sys_streams``), exit 1, before any odocan code, with nothing written; one in
    ``runpy`` as it compiles ``odocan/__main__.py`` (CI's clean clone has no cached bytecode) is
    a traceback through frozen frames only, exit 1, before any odocan code, with nothing
    written. From odocan's first line on: 130 and one line (or the STOPPED verdict), the log as
    it was or finished and readable; never the whole run, exit 0, as when a Ctrl-C's exception
    was dropped as odocan loaded (now latched from ``main``'s first line)."""
    log = tmp_path / "drive.asc"
    log.write_text(OLD_LOG)
    proc = subprocess.Popen(
        [sys.executable, "-m", "odocan", "run", "--duration", "3600", "--log", str(log)],
        cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(after_ms / 1000)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    err = _without_ignored_interrupts(err)
    if proc.returncode == -signal.SIGINT or _the_interpreters(err):
        assert _the_interpreters(err), err
        assert proc.returncode in (-signal.SIGINT, 1), proc.returncode
        assert log.read_text() == OLD_LOG
        return
    assert "Traceback" not in err, err
    assert proc.returncode == 130, (out, err)
    if log.read_text() == OLD_LOG:
        assert len(err.splitlines()) == 1, err
        return
    assert log.read_text().rstrip().endswith("End TriggerBlock")
    if list(can.LogReader(log)):
        assert "STOPPED by SIGINT at " in out, out
    else:
        assert "before its first tick" in err, err
