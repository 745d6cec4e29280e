"""The progress line: drawn in place on a terminal with a correct ETA, silent elsewhere."""

from __future__ import annotations

import io
import sys
import time

import pytest

from odocan.host.report import progress as progress_module
from odocan.host.report.progress import Progress, progress


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_line_shows_share_elapsed_and_eta() -> None:
    bar = Progress("simulating 100 s", 10_000, stream=_Terminal(), delay_s=0)
    start = bar.started
    # a quarter done after 30 s: 90 s to go
    assert bar.line(2_500, start + 30) == "simulating 100 s:  25.0%  0:30 elapsed, ETA 1:30"
    assert bar.line(0, start + 5).endswith("ETA --:--")
    assert bar.line(10_000, start + 3_700) == "simulating 100 s: 100.0%  1:01:40 elapsed, ETA 0:00"
    assert Progress("analysing", None, stream=_Terminal()).line(0, start + 61) == (
        "analysing: 1:01 elapsed"
    )


def test_drawn_in_place_on_a_terminal_and_erased(monkeypatch: pytest.MonkeyPatch) -> None:
    now = [1000.0]
    monkeypatch.setattr(f"{progress_module.__name__}.time.monotonic", lambda: now[0])
    stream = _Terminal()
    with progress("work", 4, stream=stream, delay_s=1.0) as bar:
        bar.update(1)  # before the delay: nothing
        assert stream.getvalue() == ""
        now[0] += 2.0
        bar.update(2)
        now[0] += 0.05
        bar.update(3)  # within the redraw interval: not drawn
    text = stream.getvalue()
    assert text == "\rwork:  50.0%  0:02 elapsed, ETA 0:02\x1b[K\r\x1b[K"


def test_silent_when_not_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    now = [0.0]
    monkeypatch.setattr(f"{progress_module.__name__}.time.monotonic", lambda: now[0])
    stream = io.StringIO()
    with progress("work", 4, stream=stream, delay_s=0) as bar:
        for done in range(5):
            now[0] += 10
            bar.update(done)
    assert stream.getvalue() == ""


def test_a_run_writes_nothing_extra_to_a_non_terminal_stderr(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from odocan.host.cli.app import main

    assert main(["run", "--duration", "2"]) == 0
    assert capsys.readouterr().err == ""


def test_an_experiment_counts_its_runs_with_an_eta(monkeypatch: pytest.MonkeyPatch) -> None:
    """``odocan umbmark`` (and experiment, calibrate) count squares done: the line has an ETA."""
    from odocan.host.cli.app import main

    stream = _Terminal()
    lines: list[str] = []
    real_line = Progress.line

    def spy(self: Progress, done: float, now: float) -> str:
        text = real_line(self, done, now)
        lines.append(text)
        return text

    ticks = iter(range(0, 10**9, 10))  # a clock that moves 10 s per reading: past every delay
    monkeypatch.setattr(sys, "stderr", stream)
    monkeypatch.setattr(time, "monotonic", lambda: float(next(ticks)))
    monkeypatch.setattr(Progress, "line", spy)
    assert main(["umbmark", "--runs", "1", "--side", "0.5", "--errors", ""]) in (0, 1)
    assert any(line.startswith("UMBmark: 2 x 1 squares:  50.0%") and "ETA" in line
               for line in lines), lines
