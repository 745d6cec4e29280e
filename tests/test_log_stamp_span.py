"""One frame's timestamp must never size memory nor flip a correct log's verdict (issue #11,
trial40): memory is bounded by the log's frames, not by the time its stamps span.

* A recorder paused and resumed (times monotonic, one long silence): ``gapfill.LateFrames``
  listed every 10 ms period of the silence (``fill``, ``known``): 1e6 s took ``analyze`` to
  835 MB resident, 1e8 s past 4 GB (MemoryError). The structures are sized by the frames now.
* One WHEEL_ENCODERS frame stamped far ahead of (or behind) both its neighbours, its
  neighbours in order (a glitched stamp, not a reorder: a recorder's stamping goes back by
  1 ms at most, a bus by a frame): 1e8 s took ``analyze`` to 5.5 GB, 1e6 s to 836 MB, and
  1000 s FAILed a correct drive (a 998.7 s "silence", a re-prime, the distance 1.6 mm off).
  Such a frame is set aside by the log's reader (``host.io.logs``, whole and streamed alike)
  with one warning naming the log, the frame and its stamp: the rest of the log is judged as
  recorded, the frame counted lost (its gap bounded as any gap of the log).

The drive is a correct 5 s kobuki square; its logs are written by python-can's writers.
"""

from __future__ import annotations

import tracemalloc
import warnings
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.gapfill import LateFrames
from tests.judges_cli import fails_by_position, live_judges, raise_x_10_mm

GLITCHED = 241  # the frame (0-based) whose stamp is replaced: a WHEEL_ENCODERS frame mid-log
MEMORY_BOUND_B = 200_000_000  # a generous bound: the clean drive peaks at a few tens of MB


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[can.Message]]:
    """A correct 5 s square drive's ``.log`` and frames, frame ``GLITCHED`` an encoder frame."""
    log = tmp_path_factory.mktemp("span") / "drive.log"
    assert main(["run", "--robot", "kobuki", "--scenario", "square", "--duration", "5",
                 "--log", str(log)]) == 0
    frames = list(can.LogReader(str(log)))
    assert frames[GLITCHED].arbitration_id == 0x100  # WHEEL_ENCODERS (the DBC's)
    assert len(frames) > 1500
    return log, frames


def _write(frames: list[can.Message], path: Path) -> Path:
    """``frames`` written by python-can's writer for ``path``'s suffix."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with can.Logger(str(path)) as out:
            for msg in frames:
                out.on_message_received(msg)
    return path


def _restamped(msg: can.Message, t_s: float) -> can.Message:
    return can.Message(timestamp=t_s, arbitration_id=msg.arbitration_id, data=msg.data,
                       is_extended_id=msg.is_extended_id, is_rx=msg.is_rx)


def _peak_analyze(path: Path, stream: str, capsys: pytest.CaptureFixture[str]
                  ) -> tuple[int, str, str, int]:
    """``analyze PATH --stream STREAM``: exit code, stdout, stderr and tracemalloc's peak."""
    tracemalloc.start()
    try:
        code = main(["analyze", str(path), "--stream", stream])
        peak_b = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    out, err = capsys.readouterr()
    return code, out, err, peak_b


def test_late_frames_are_sized_by_the_frames_not_the_gap() -> None:
    """A gap of 10^7 periods with two refused frames in it: ``fill`` and ``known`` answer from
    the two, not from a list of the gap's periods (80 MB of pointers)."""
    late = LateFrames()
    late.counts.update({1: (5, 6), 3: (7, 8)})
    tracemalloc.start()
    try:
        filled = late.fill(0, 10**7)
        known = late.known(0, 10**7)
        peak_b = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert filled is None
    assert known == [(1, (5, 6)), (3, (7, 8))]
    assert peak_b < 1_000_000, peak_b
    assert late.fill(0, 3) is None  # 2 is missing
    late.counts[2] = (1, 1)
    assert late.fill(0, 4) == [(5, 6), (1, 1), (7, 8)]
    assert late.known(0, 3) == [(1, (5, 6)), (2, (1, 1))]


@pytest.mark.parametrize("pause_s", [3600.0, 1e5, 1e8])
@pytest.mark.parametrize("stream", ["never", "always"])
def test_a_paused_recorder_costs_no_memory_by_its_pause(
    drive: tuple[Path, list[can.Message]], pause_s: float, stream: str, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Every frame from ``GLITCHED`` on ``pause_s`` later (monotonic: a recorder paused then
    resumed): PASS as the drive, in about the drive's memory."""
    _, frames = drive
    clean = _write(frames, tmp_path / "clean.csv")
    paused = _write([m if k < GLITCHED else _restamped(m, m.timestamp + pause_s)
                     for k, m in enumerate(frames)], tmp_path / "paused.csv")
    code0, _, _, peak0_b = _peak_analyze(clean, stream, capsys)
    code, out, err, peak_b = _peak_analyze(paused, stream, capsys)
    assert (code0, code) == (0, 0), (out, err)
    assert "PASS" in out, out
    assert peak_b < peak0_b + 30_000_000, (peak0_b, peak_b)


def _glitched(frames: list[can.Message], path: Path, jump_s: float) -> Path:
    """``frames`` with frame ``GLITCHED``'s stamp ``jump_s`` after (before, negative) its
    own, written to ``path``."""
    bad = _restamped(frames[GLITCHED], frames[GLITCHED].timestamp + jump_s)
    return _write([*frames[:GLITCHED], bad, *frames[GLITCHED + 1:]], path)


def _judged(out: str) -> tuple[int, int]:
    """The report's poses judged and poses (``judged     N of M on-board poses ...``)."""
    line = next(line for line in out.splitlines() if line.strip().startswith("judged"))
    words = line.split()
    return int(words[1]), int(words[3])


def _set_aside_warned(err: str, path: Path, stamp_s: float) -> None:
    """One warning naming ``path``, frame ``GLITCHED + 1`` and its stamp; no other."""
    lines = [line for line in err.splitlines() if line.startswith(("warning", "error"))]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"warning: {path}: set aside 1 frame "), lines
    assert f"frame {GLITCHED + 1}" in lines[0], lines
    assert f"{stamp_s:.6f} s" in lines[0], lines


CASES = [(suffix, 1e8) for suffix in ("csv", "asc", "trc", "log")] + [
    ("csv", 1000.0), ("csv", 1e6), ("log", 1e6), ("csv", -1000.0)]


@pytest.mark.parametrize(("suffix", "jump_s"), CASES)
@pytest.mark.parametrize("stream", ["never", "always"])
def test_one_glitched_stamp_is_set_aside(
    drive: tuple[Path, list[can.Message]], suffix: str, jump_s: float, stream: str,
    tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    """The drive with one encoder frame's stamp ``jump_s`` off its neighbours: PASS with the
    drive's verdict, its poses judged but the one naming that frame, one warning, the drive's
    memory."""
    _, frames = drive
    path = _glitched(frames, tmp_path / f"glitch.{suffix}", jump_s)
    stamp_s = [m.timestamp for m in can.LogReader(str(path))][GLITCHED]
    code0, out0, _, _ = _peak_analyze(_write(frames, tmp_path / f"clean.{suffix}"), stream,
                                      capsys)
    code, out, err, peak_b = _peak_analyze(path, stream, capsys)
    assert (code0, code) == (0, 0), (out, err)
    assert "PASS" in out, out
    (judged0, of0), (judged, of) = _judged(out0), _judged(out)
    assert of == of0, (out0, out)
    assert judged0 - 1 <= judged <= judged0, (out0, out)  # the pose naming it, at most, not
    _set_aside_warned(err, path, stamp_s)
    assert peak_b < MEMORY_BOUND_B, peak_b


def test_whole_and_streamed_agree_on_a_glitched_stamp(
    drive: tuple[Path, list[can.Message]], tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    """The two analyses print the same report of a glitched log (one frame set aside)."""
    _, frames = drive
    path = _glitched(frames, tmp_path / "glitch.csv", 1e6)
    reports = []
    for stream in ("never", "always"):
        code = main(["analyze", str(path), "--stream", stream])
        out, _ = capsys.readouterr()
        reports.append((code, out.replace(" (streamed)", "")))
    assert reports[0] == reports[1]


@pytest.mark.parametrize("jump_s", [1000.0, 1e6])
def test_a_10_mm_pose_still_fails_beside_a_glitched_stamp(
    drive: tuple[Path, list[can.Message]], jump_s: float, tmp_path: Path,
) -> None:
    """X raised 10 mm from 2 s on, one encoder frame's stamp glitched: FAIL by the position,
    whole and streamed."""
    log, _ = drive
    tampered = tmp_path / "tampered.log"
    assert raise_x_10_mm(log, tampered, 2.0) > 100
    frames = list(can.LogReader(str(tampered)))
    glitched = _glitched(frames, tmp_path / "glitched.log", jump_s)
    assert fails_by_position(glitched, tmp_path) == []


@pytest.mark.parametrize("jump_s", [1e8, -1000.0])
def test_the_live_judges_keep_their_memory_by_frames(
    drive: tuple[Path, list[can.Message]], jump_s: float, tmp_path: Path,
) -> None:
    """The monitor and the bridge fed the glitched log, then the paused one (1e8 s): their
    memory stays the frames' (``livefill`` answers from the frames held, as ``gapfill``)."""
    _, frames = drive
    paused = _write([m if k < GLITCHED else _restamped(m, m.timestamp + 1e8)
                     for k, m in enumerate(frames)], tmp_path / "paused.csv")
    for path in (_glitched(frames, tmp_path / "glitch.csv", jump_s), paused):
        tracemalloc.start()
        try:
            live_judges("kobuki", path)
            peak_b = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak_b < 50_000_000, (path, peak_b)


@pytest.mark.parametrize("jump_s", [1000.0, 1e8, -1000.0])
def test_the_live_judges_set_a_glitched_stamp_aside(
    drive: tuple[Path, list[can.Message]], jump_s: float, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The monitor and the bridge set the glitched frame aside as ``analyze`` does
    (``host.judge.livestampgate``): the drive's verdict (1000 s ahead said DISTANCE WRONG,
    1.621 mm beyond its tolerance, before), one ``stamp_glitch`` event whose detail is the
    reader's warning, the frame counted lost."""
    _, frames = drive
    clean = live_judges("kobuki", _write(frames, tmp_path / "clean.csv"))
    path = _glitched(frames, tmp_path / "glitch.csv", jump_s)
    glitched = live_judges("kobuki", path)
    assert main(["analyze", str(path)]) == 0
    warned = [line for line in capsys.readouterr().err.splitlines() if "set aside" in line]
    assert len(warned) == 1, warned
    monitor_events = glitched[0].health(now_s=frames[-1].timestamp)["events"]
    bridge_events = glitched[1].status()[1]["events"]
    for k, events in enumerate((monitor_events, bridge_events)):  # the monitor, the bridge
        assert clean[k].distance.verdict() == []
        assert glitched[k].distance.verdict() == [], glitched[k].distance.verdict()
        assert glitched[k].tracker.wrongs.count == 0
        told = [e for e in events if e["kind"] == "stamp_glitch"]
        assert len(told) == 1, events
        assert told[0]["count"] == 1, told
        assert warned[0].endswith(f"{path}: {told[0]['detail']}"), (warned, told)
        assert glitched[k].e2e.counts()["WHEEL_ENCODERS"]["lost"] == (
            clean[k].e2e.counts()["WHEEL_ENCODERS"]["lost"] + 1)
