"""``odocan firmware --nvm PATH`` on something that is not a regular file: one line, exit 2.

A named pipe used to block the firmware's start for ever (``read_bytes`` waits for a writer),
so a mistyped path hung the node instead of refusing it; a directory was refused only by the
read's errno. Both are refused before anything is read, naming the path.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.sim.board import FileNvm
from odocan.sim.exceptions import ConfigurationError
from tests.test_cli_run import assert_usage_error

KEY_HEX = "000102030405060708090a0b0c0d0e0f"


def _key(tmp_path: Path) -> Path:
    key = tmp_path / "k"
    key.write_text(KEY_HEX)
    key.chmod(0o600)
    return key


def _refused_within(path: Path, timeout_s: float = 10.0) -> str:
    """FileNvm(path)'s refusal, or a failure when it blocks (run in a thread: a FIFO would
    block the test itself)."""
    outcome: list[str] = []

    def load() -> None:
        try:
            FileNvm(path)
        except ConfigurationError as exc:
            outcome.append(str(exc))
        else:
            outcome.append("accepted")

    worker = threading.Thread(target=load, daemon=True)
    worker.start()
    worker.join(timeout_s)
    if worker.is_alive():  # unblock the reader so the thread ends
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        os.close(fd)
        worker.join(timeout_s)
        pytest.fail(f"FileNvm({path}) blocked for {timeout_s} s instead of refusing it")
    return outcome[0]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_named_pipe_is_refused_not_waited_on(tmp_path: Path) -> None:
    fifo = tmp_path / "nvm.fifo"
    os.mkfifo(fifo)
    message = _refused_within(fifo)
    assert message == f"NVM file {fifo}: not a regular file (a FIFO)"


def test_a_directory_is_refused_as_not_a_file(tmp_path: Path) -> None:
    assert _refused_within(tmp_path) == f"NVM file {tmp_path}: not a regular file (a directory)"


def test_cli_nvm_directory_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["firmware", "-i", "virtual", "-c", "nvm-not-a-file", "--duration", "0.1",
                 "--secoc-key", str(_key(tmp_path)), "--nvm", str(tmp_path)])
    assert_usage_error(capsys, code, "--nvm", str(tmp_path), "not a regular file")


def test_a_regular_file_and_a_missing_one_still_load(tmp_path: Path) -> None:
    missing = FileNvm(tmp_path / "fw.nvm")
    assert missing.read_epoch() == 0
    assert missing.write_epoch(7)
    assert FileNvm(tmp_path / "fw.nvm").read_epoch() == 7
