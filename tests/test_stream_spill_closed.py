"""The streamed judge closes its spill files when the log is refused mid-read (issue #11).

Before: ``analyze --stream always`` on a log whose bad line comes after the first chunk
raised out of the read loop with the spill's column files still open (a ``ResourceWarning``
per file, the temporary directory removed under them). The spill is recorded here and each of
its files must be closed once the CLI said its one line and exit 2.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.judge import stream_analysis
from odocan.host.judge.stream_spill import FrameSpill


def _log_with_bad_line(tmp_path: Path) -> Path:
    """A 2 s kobuki drive, a frame far past its first chunk given a time no clock has."""
    good = tmp_path / "good.log"
    assert main(["run", "--robot", "kobuki", "--duration", "2", "--log", str(good)]) == 0
    lines = good.read_text().splitlines(keepends=True)
    at = len(lines) * 3 // 4
    lines[at] = "(1e300)" + lines[at][lines[at].index(")") + 1:]
    bad = tmp_path / "bad.log"
    bad.write_text("".join(lines))
    return bad


def test_a_log_refused_mid_stream_leaves_no_spill_file_open(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    spills: list[FrameSpill] = []

    class Recorded(FrameSpill):
        def __init__(self, directory: Path) -> None:
            super().__init__(directory)
            spills.append(self)

    bad = _log_with_bad_line(tmp_path)
    capsys.readouterr()
    monkeypatch.setattr(stream_analysis, "FrameSpill", Recorded)
    code = main(["analyze", str(bad), "--stream", "always", "--chunk-frames", "256"])
    err = capsys.readouterr().err
    assert code == 2
    assert "bad timestamp" in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert len(spills) == 1
    assert all(f.closed for f in spills[0]._files.values())
