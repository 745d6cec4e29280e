"""A pose after a silence is no pose named ahead (issue #11: a drive the stream judged before is
streamed still; ``host.judge.aheadnamed.silent``).

``aheadnamed`` took every pose whose ENC_COUNTER resolved (-8..+7 from the latest encoder frame
heard) to a later frame. The first pose after a stall names a frame of its backlog, a lap or
more back (pmir square seed 1, ``stall=2:0.25``: the pose at 2.251 s named the frame of 2.00 s,
resolved to 2.26 s): ``stallfirst`` judges it, as on main, and the stream refused the correct
drive for it (``NotStreamable``). Across a silence of the encoder frames a COUNTER lap long the
log cannot tell which frame of the COUNTER a pose names: such poses are left to the rules main
judges them by (tests/test_recorder_gap16.py, test_silence_gap.py: a correct kobuki FAILed).
A pose that does name a frame ahead still makes the stream give way to the whole log's judge:
the library reads the log whole as the CLI does (``analyze_file``'s ``whole_on_ahead``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.judge.stream_refusal import NamesAhead
from odocan.sim.robot import load
from tests.judges_cli import raise_first_x, reported_analyses
from tests.test_stream import awkward_lines

PMIR = load("pmir")
STALL_END_S = 2.25  # the drive's stall: 2 s, 0.25 s long


@pytest.fixture(scope="module")
def stalled(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A correct pmir square drive with one stall (its run asserted a PASS)."""
    log = tmp_path_factory.mktemp("stall") / "drive.log"
    assert main(["run", "--robot", "pmir", "--scenario", "square", "--seed", "1",
                 "--duration", "6", "--faults", "stall=2:0.25", "--log", str(log)]) == 0
    return log


def test_the_stalled_drive_streams_as_the_whole_log(stalled: Path) -> None:
    """Streamed without giving way (``NamesAhead`` not raised), the report the whole log's, no
    pose counted named ahead; the first pose after the stall judged by ``stallfirst``."""
    whole = analyze(read_log(stalled), PMIR).report
    streamed = analyze_file(stalled, PMIR, chunk_frames=97, whole_on_ahead=False)
    assert json.dumps(streamed) == json.dumps(whole)
    assert whole["passed"]
    assert "names_ahead_judged" not in whole["samples"]
    assert whole["samples"]["stall_first_judged"] >= 1


def test_the_first_pose_after_the_stall_10_mm_off_fails(stalled: Path, tmp_path: Path) -> None:
    """That first pose raised 10 mm: FAIL whole and streamed, by the position."""
    tampered = tmp_path / "tampered.log"
    raise_first_x(stalled, tampered, 100, STALL_END_S - 0.01, STALL_END_S + 0.05)
    for stream, code, report in reported_analyses(tampered, tmp_path):
        first = report["stall_first_pose"]
        assert code == 1, (stream, first)
        assert first["max_position_beyond_m"] > 5e-3, (stream, first)


def test_a_pose_named_ahead_gives_the_whole_logs_report(tmp_path: Path) -> None:
    """The awkward log (a pose naming the frame whose CRC the log spoilt, poses logged before
    the frame they name): the stream gives way, ``NamesAhead``; by default the library gives
    the whole log's report, as the CLI does."""
    path = tmp_path / "awkward.log"
    path.write_text("".join(awkward_lines()))
    with pytest.raises(NamesAhead):
        analyze_file(path, PMIR, "rk2", chunk_frames=64, whole_on_ahead=False)
    whole = analyze(read_log(path), PMIR, "rk2").report
    assert whole["samples"]["names_ahead_judged"] >= 1
    assert json.dumps(analyze_file(path, PMIR, "rk2", chunk_frames=64)) == json.dumps(whole)


def test_a_log_read_whole_after_the_stream_warns_once(tmp_path: Path) -> None:
    """The awkward log cut mid-line (what a killed recorder leaves): the stream's read and the
    whole log's read after it skip the same partial line; the caller is told once."""
    path = tmp_path / "cut.log"
    lines = awkward_lines()
    path.write_text("".join(lines[:-1]) + lines[-1][:11])
    warned: list[str] = []
    report = analyze_file(path, PMIR, "rk2", chunk_frames=64, warn=warned.append)
    assert report["samples"]["names_ahead_judged"] >= 1  # (read whole: a pose named ahead)
    assert len(warned) == 1, warned
