"""``odocan analyze --stream`` judges a power-up primed late as the whole log does, in bounded
memory (issue #11; ``host.judge.stream_primed``).

A firmware whose first count page says it primed on the log's frame k >= 1 (its FIFO drained at
tick 0) and a recorder stamping ODOM_STATUS 0-50 ms late (k only too large): the whole log's
judge judges the life from each frame 0 .. min(k, n) (``host.judge.primedrange``). Before, the
stream refused every such life (``NotStreamable``) and the CLI read the log whole: an hour's
drive that primed late in its first second took the whole judge's memory (2.7 MB per MB of
log; ``bench/stream_powerup.py``). Now the stream holds the life's first frames up to its first
count page and pose, and streams the life again from each candidate: the report is the whole
log's, byte for byte, at every chunk size (the prefix spread over many chunks, or in one); the
correct firmware PASSes, one 10 mm or 1 m off FAILs (the drives and their independent evidence:
``tests/test_powerup_primed_range.py``). A prefix past its bound is still refused, and the
stderr line says why and the whole judge's memory.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge import stream_primed
from odocan.host.judge.analysis import analyze
from odocan.host.judge.primedon import PRIMED_KIND
from odocan.host.judge.stream_analysis import NotStreamable, analyze_file
from odocan.host.judge.stream_choice import refused_rss_mb
from tests.test_first_second_reboot import _written
from tests.test_powerup_primed_range import _frames
from tests.test_stall_beyond_window import PMIR

CHUNKS = (97, 1 << 18)  # the prefix over many chunks; in one


def _log(tmp_path: Path, drive: str, bias_lsb: int, late_s: float) -> Path:
    return _written(_frames(drive, bias_lsb, late_s), tmp_path / f"{drive}_{bias_lsb}.log")


@pytest.mark.parametrize("chunk_frames", CHUNKS)
@pytest.mark.parametrize("bias_lsb", [0, 100, 10_000])
@pytest.mark.parametrize("late_s", [0.0, 0.015, 0.05])
@pytest.mark.parametrize("drive", ["still", "moving"])
def test_the_streamed_report_is_the_whole_logs(tmp_path: Path, drive: str, late_s: float,
                                               bias_lsb: int, chunk_frames: int) -> None:
    """Before: ``NotStreamable`` (the whole log read instead) in every case."""
    path = _log(tmp_path, drive, bias_lsb, late_s)
    want = analyze(read_log(path), PMIR, "exact").report
    got = analyze_file(path, PMIR, "exact", chunk_frames=chunk_frames)
    assert json.dumps(got) == json.dumps(json.loads(json.dumps(want)))
    primed = [e for e in want["events"] if e["kind"] == PRIMED_KIND]
    assert len(primed) == 1  # judged from the candidates
    assert want["passed"] is (bias_lsb == 0)
    if drive == "moving" and bias_lsb == 0:
        assert primed[0]["encoder_frame"] == 1  # where the firmware primed (the evidence's)


def test_always_streams_it_quietly(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: 'not streamable (the firmware's first count page says it primed after ...)'."""
    path = _log(tmp_path, "moving", 0, 0.02)
    code = main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always", "--report", str(tmp_path / "r.json")])
    assert code == 0
    assert "not streamable" not in capsys.readouterr().err


def test_a_prefix_past_its_bound_is_refused_and_said(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Its first pose beyond the frames held (the bound made 50 frames here): judged whole,
    the line saying why and the whole judge's memory; the verdict the whole log's."""
    monkeypatch.setattr(stream_primed, "MAX_PREFIX_FRAMES", 50)
    path = _log(tmp_path, "moving", 10_000, 0.02)
    with pytest.raises(NotStreamable, match="first pose or count page came after"):
        analyze_file(path, PMIR, "exact", chunk_frames=32)
    code = main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always", "--chunk-frames", "32"])
    err = capsys.readouterr().err
    assert code == 1  # 1 m off: FAIL, the whole log's verdict
    rss_mb = refused_rss_mb(path)
    assert rss_mb is not None
    assert ("not streamable (the firmware's first count page says it primed after the log's "
            "first encoder frame, and its first pose or count page came after the first 50 "
            "frames") in err  # (the reason names the bound it was built with)
    assert err.rstrip().endswith(f"judged whole, in up to about {rss_mb:.0f} MB of memory (the "
                                 "stream aims under 300 MB)"), err
