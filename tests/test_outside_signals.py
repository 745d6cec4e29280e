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


MARKS = "ODOCAN_TEST_BATCH_MARKS"
LONG_S = 5.0  # a long log's analysis, as the workers see it


def _slow_analyze_one(path: str, job: object) -> object:
    """``batch.analyze_one`` standing in for logs: marks its process id and the log, takes
    ``LONG_S`` (drive00 none: its result comes at once)."""
    import time

    from odocan.host.cli.batch import LogResult

    with open(os.environ[MARKS], "a") as marks:
        marks.write(f"{os.getpid()} {path}\n")
    if not path.endswith("drive00.log"):
        time.sleep(LONG_S)
    return LogResult(path, error="not analysed (test)")


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return True
    return state in ("Z", "X")  # dead (a zombie until reaped)


def test_ctrl_c_in_a_batch_stops_its_workers_at_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C or SIGTERM in ``analyze logs/`` went on to analyse every log still queued (the
    pool's exit waited for all of them: 5 s for 12 logs here, hours for an archive); a worker's
    log under way is ended too (a 1 GB log is half a minute)."""
    import time

    from odocan.host.cli import batch

    marks = tmp_path / "marks"
    monkeypatch.setenv(MARKS, str(marks))
    monkeypatch.setattr(batch, "analyze_one", _slow_analyze_one)  # forked workers see it

    def interrupt(result: object) -> None:
        raise KeyboardInterrupt

    job = batch.Job("pmir", None, 1e-4, 1e-4)
    paths = [tmp_path / f"drive{i:02}.log" for i in range(40)]
    with pytest.raises(KeyboardInterrupt):
        batch.analyze_logs(paths, job, jobs=2, on_done=interrupt)
    pids = {int(line.split()[0]) for line in marks.read_text().splitlines()}
    deadline = time.monotonic() + LONG_S / 2
    while not all(_gone(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(_gone(pid) for pid in pids), "a worker went on with its log"
    assert len(marks.read_text().splitlines()) < 10  # not every queued log
