"""A command stopped by Ctrl-C or SIGTERM before its verdict never exits 0.

Found from outside: ``odocan analyze big.log`` killed with SIGTERM (what a CI job's timeout
sends) printed nothing and exited 0 -- read by CI as a pass although no log was judged. Commands
that stop on a signal WITH a verdict (run, replay, monitor, fleet) keep their own exit codes
(tests/test_signals.py); any other interruption says so on stderr and exits 128 + the signal's
number, the shell's convention.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

import odocan.host.io.logs as logs
from odocan.host.cli.app import main

LINE = "(0.000000) vcan0 100#8F00000000000000\n"


def _log(tmp_path: Path) -> Path:
    path = tmp_path / "drive.log"
    path.write_text(LINE * 4)
    return path


@pytest.mark.parametrize(
    ("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)]
)
def test_analyze_stopped_by_a_signal_mid_read_exits_128_plus_n(
    signum: signal.Signals, code: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    log = _log(tmp_path)

    def read_then_signal(*args: object, **kwargs: object) -> object:
        os.kill(os.getpid(), signum)  # main's handlers turn it into an exception here
        raise AssertionError("the signal did not interrupt the read")

    monkeypatch.setattr(logs, "read_log", read_then_signal)
    assert main(["analyze", str(log), "--stream", "never"]) == code
    out, err = capsys.readouterr()
    assert out == ""
    assert err == f"interrupted ({signum.name}): odocan analyze stopped before it finished\n"


def test_sigterm_handler_is_restored_after_main(tmp_path: Path) -> None:
    before = signal.getsignal(signal.SIGTERM)
    assert main(["busload"]) in (0, 1)
    assert signal.getsignal(signal.SIGTERM) is before
