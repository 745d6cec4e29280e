"""A Ctrl-C or SIGTERM that lands in importlib's module-lock callback as ``odocan`` imports its
modules: one line and 130/143, never a traceback.

CPython calls ``_get_module_lock.<locals>.cb`` (a weakref callback) when a module's import lock
goes; an exception raised there is printed ("Exception ignored in: <function
_get_module_lock.<locals>.cb ...>" and its traceback) and dropped. Once odocan's handler
(``sim.interrupts.latch_and_raise``) was installed, its frame was in that traceback: the early
signal sweeps (test_early_sigint.py, test_early_signals.py) would have failed a run that stopped
right (the latch stopped it: 130/143 and its line), and a user read a traceback on Ctrl-C. The
handler now only latches there. The moment is made exactly: a ``sitecustomize`` profiles calls
until the handler is installed, then makes the signal pending (``Py_AddPendingCall`` of
``PyErr_SetInterruptEx``) at the next callback's entry, where the interpreter hears it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from odocan.sim import interrupts
from odocan.sim.exceptions import Terminated

ROOT = Path(__file__).resolve().parents[1]
OLD_LOG = "an older log, kept\n"
IN_CALLBACK = """
import ctypes, os, signal, sys
_signum = int(os.environ["ODOCAN_TEST_SIGNAL"])
_pend = ctypes.pythonapi.Py_AddPendingCall
_pend.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
_interrupt = ctypes.cast(ctypes.pythonapi.PyErr_SetInterruptEx, ctypes.c_void_p)

def _profile(frame, event, arg):
    code = frame.f_code
    if (event, code.co_filename, code.co_name) != ("call", "<frozen importlib._bootstrap>", "cb"):
        return
    handler = signal.getsignal(_signum)
    if callable(handler) and handler is not signal.default_int_handler:  # odocan's
        sys.setprofile(None)
        _pend(_interrupt, _signum)

sys.setprofile(_profile)
"""


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)],
                         ids=["SIGINT", "SIGTERM"])
def test_a_signal_in_importlibs_callback_is_one_line(
    tmp_path: Path, signum: signal.Signals, code: int,
) -> None:
    """Before: "Exception ignored in: <function _get_module_lock.<locals>.cb", a traceback
    through ``latch_and_raise``, then the line (the exit code was right)."""
    (tmp_path / "sitecustomize.py").write_text(IN_CALLBACK)
    log = tmp_path / "drive.asc"
    log.write_text(OLD_LOG)
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}",
           "ODOCAN_TEST_SIGNAL": str(int(signum))}
    done = subprocess.run(
        [sys.executable, "-m", "odocan", "run", "--duration", "3600", "--log", str(log)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    lines = done.stderr.splitlines()
    assert (done.returncode, len(lines)) == (code, 1), done.stderr
    assert lines[0].startswith(f"interrupted ({signum.name}): odocan run stopped before it "
                               "finished ("), lines
    assert lines[0].endswith(f"--log {log}: not written)"), lines
    assert log.read_text() == OLD_LOG


def test_elsewhere_the_handler_still_raises() -> None:
    """Only that callback: in any other frame the signal's exception is raised (and latched)."""
    try:
        with pytest.raises(Terminated):
            interrupts.latch_and_raise(signal.SIGTERM, sys._getframe())
        with pytest.raises(KeyboardInterrupt):
            interrupts.latch_and_raise(signal.SIGINT, None)
        assert interrupts.latched() == signal.SIGTERM
    finally:
        interrupts.clear()
