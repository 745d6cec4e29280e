"""A command asked for a ``--duration`` that Ctrl-C or SIGTERM ends early never exits 0.

Found from outside: ``odocan monitor --duration 600 --json`` and ``odocan bridge --duration 600``
killed by a CI job's timeout exited 0, as if they had watched (bridged) for the time asked. Now
they still print what they heard (the JSON, the bridge's summary), say they were STOPPED and at
what time of the asked duration, and exit 128 + the signal's number. Without ``--duration`` a
signal is their normal end and exit 0 stays (tests/test_signals.py).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.test_signals import _catches_sigterm

ROOT = Path(__file__).resolve().parents[1]
START_TIMEOUT_S = 120.0  # a loaded machine: imports and the embedded broker take their time
EXIT_TIMEOUT_S = 60.0


def _start(*argv: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "odocan", *argv], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _stop(proc: subprocess.Popen[str], signum: int) -> tuple[int, str, str]:
    proc.send_signal(signum)
    try:
        out, err = proc.communicate(timeout=EXIT_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"no exit {EXIT_TIMEOUT_S} s after the signal: {err}")
    return proc.returncode, out, err


def _wait_until(proc: subprocess.Popen[str], ready: Path) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while not ready.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"never ready: {proc.communicate()}")
        time.sleep(0.05)


def _wait_for_its_handler(proc: subprocess.Popen[str]) -> None:
    """Until odocan handles SIGTERM (``main`` installed its handler; before, the signal kills
    the interpreter: -15). Before, a fixed 4 s: a loaded machine can take longer to import."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while not _catches_sigterm(proc.pid):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"SIGTERM never handled: {proc.communicate()}")
        time.sleep(0.05)


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_monitor_stopped_before_its_duration_says_so_and_exits_128_plus_n(
    tmp_path: Path, signum: signal.Signals, code: int
) -> None:
    log = tmp_path / "heard.log"  # made once the monitor's receive loop is about to run
    proc = _start("monitor", "-i", "virtual", "-c", f"stopped-{os.getpid()}", "--json",
                  "--duration", "600", "--log", str(log))
    _wait_until(proc, log)
    time.sleep(0.5)
    got, out, err = _stop(proc, signum)
    assert got == code, err
    stopped = json.loads(out)["stopped"]
    assert (stopped["signal"], stopped["asked"], stopped["unit"]) == (signum.name, 600, "s")
    assert 0 < stopped["done"] < 600
    assert err == f"monitor: STOPPED by {signum.name} at {stopped['done']:g} s of 600 s\n"


def test_a_bridge_stopped_before_its_duration_exits_143(tmp_path: Path) -> None:
    proc = _start("bridge", "-i", "virtual", "-c", f"stopped-bridge-{os.getpid()}",
                  "--duration", "600")
    assert proc.stderr is not None
    deadline = time.monotonic() + START_TIMEOUT_S
    line = proc.stderr.readline()  # "bridge robot001: mqtt://... (embedded)": broker up
    while line and not line.startswith("bridge robot001: mqtt") and time.monotonic() < deadline:
        line = proc.stderr.readline()
    assert line.startswith("bridge robot001: mqtt"), line
    time.sleep(2.0)  # its signal handlers are installed right after that line
    code, _, err = _stop(proc, signal.SIGTERM)
    assert code == 143, err
    assert "Traceback" not in err
    last = err.splitlines()[-1]
    assert last.startswith("bridge robot001: STOPPED by SIGTERM at "), err
    assert last.endswith(" s of 600 s"), err


@pytest.mark.parametrize("node", ["sim", "firmware"])
def test_a_real_time_node_stopped_before_its_duration_exits_143(node: str) -> None:
    proc = _start(node, "-i", "virtual", "-c", f"stopped-{node}-{os.getpid()}",
                  "--duration", "600")
    _wait_for_its_handler(proc)  # from then on 143 (its loop under way, or before it by main)
    code, _, err = _stop(proc, signal.SIGTERM)
    assert code == 143, err
    assert "Traceback" not in err
    last = err.splitlines()[-1]
    stopped = last.startswith(f"odocan {node}: STOPPED by SIGTERM at ") and last.endswith(
        " s of 600 s")
    assert stopped or last == f"interrupted (SIGTERM): odocan {node} stopped before it finished"
