"""``odocan analyze`` in bounded memory: the report of a log read chunk by chunk
(``host.judge.stream_analysis.analyze_file``) is the whole log's (``analyze(read_log)``), every
key and every float bit for bit, at chunk sizes 1, 7, 64 and the whole log: on the awkward
synthesized log (a reboot, a counter restart, a gap across a COUNTER wrap, refused, repeated
and swapped frames), on a lockstep rig run with bus faults, an MCU stall and a reboot, and on a
lossy run (a babbler overflows the firmware's mailbox: encoder frames it lost that the log
holds, a loss allowance). A babble run on a slow bus (frames let out in a burst: queued
pairing) is refused for streaming and analysed whole. ``--stream auto`` streams by the log's
size."""

from __future__ import annotations

import json
import subprocess
import sys
from functools import cache
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log, to_message
from odocan.host.judge.analysis import analyze
from odocan.host.judge.stream import StreamEncoders
from odocan.host.judge.stream_analysis import (
    FrameCount,
    NotStreamable,
    analyze_file,
    stream_above_bytes,
    streams,
)
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.test_stream import awkward_lines
from tests.test_stream_facts import rig_frames

CHUNKS = [1, 7, 64, 1 << 20]
SPOILED_STATUS = 216  # awkward_lines' line of an ODOM_STATUS frame (0x380)
ROBOT = {"awkward": "pmir", "rig": "pmir", "lossy": "kobuki", "babble": "pmir"}


@cache
def run_lines(which: str) -> tuple[str, ...]:
    """``odocan run --log``'s lines of a lossy run (kobuki, babble=16000 on the instant bus, 3 s:
    the firmware's mailbox overflows; only the lines of the DBC's IDs, so that chunks of one
    frame stay quick; the firmware's reports of what it lost are all there) or of the babble
    run of tests/test_babble_firmware.py (125 kbit/s: frames wait and come in a burst)."""
    from tempfile import TemporaryDirectory

    argv = (["--robot", "kobuki", "--duration", "3", "--faults", "babble=16000"]
            if which == "lossy" else
            ["-b", "125000", "--seed", "3", "--duration", "4.5", "--faults",
             "babble=3000:0x050:2:0.5,seed=3"])
    with TemporaryDirectory() as tmp:
        log = Path(tmp) / "run.log"
        subprocess.run([sys.executable, "-m", "odocan", "run", *argv, "--log", str(log)],
                       capture_output=True, text=True, timeout=600, check=True)
        lines = log.read_text().splitlines(keepends=True)
    if which == "babble":
        return tuple(lines)
    ids = {f"{m.frame_id:03X}" for m in database().messages}
    return tuple(line for line in lines if line.split()[2].split("#")[0] in ids)


def log_of(tmp_path: Path, which: str) -> Path:
    path = tmp_path / f"{which}.log"
    if which == "awkward":  # its bad CRC on a status frame, no pose logged before the frame
        # it names: no pose names a frame ahead (such logs are read whole: test_ahead_silence)
        path.write_text("".join(awkward_lines(spoiled=SPOILED_STATUS, reordered=())))
        return path
    if which in ("lossy", "babble"):
        path.write_text("".join(run_lines(which)))
        return path
    frames = rig_frames()
    with can.Logger(str(path)) as logger:
        for i in range(len(frames)):
            logger.on_message_received(to_message(frames, i))
    return path


@pytest.mark.parametrize("chunk_frames", CHUNKS)
@pytest.mark.parametrize("which", ["awkward", "rig", "lossy"])
def test_the_streamed_report_is_the_whole_logs(
    tmp_path: Path, which: str, chunk_frames: int
) -> None:
    path = log_of(tmp_path, which)
    profile = load(ROBOT[which])
    want = analyze(read_log(path), profile, "rk2" if which == "awkward" else None).report
    got = analyze_file(path, profile, "rk2" if which == "awkward" else None,
                       chunk_frames=chunk_frames, whole_on_ahead=False)  # truly streamed
    assert json.dumps(got) == json.dumps(want)
    kinds = [e["kind"] for e in want["events"]]
    if which != "lossy":
        assert len(want["reboots"]) == 1  # what the logs hold
    if which == "rig":
        assert want["samples"]["truth_compared"] > 0
        assert kinds.count("firmware_stall") >= 1
        assert kinds.count("encoder_frames_lost_on_board") >= 1  # frames lost in the stall
    if which == "lossy":  # the allowance counts: beyond it the errors are smaller
        assert kinds.count("encoder_frames_lost_on_board") >= 3
        vs_ref = want["onboard_vs_reference"]
        assert vs_ref["loss_allowance_m"] > 0
        assert (vs_ref["max_position_error_beyond_allowance_m"]
                < vs_ref["max_position_error_m"])


@pytest.mark.parametrize("chunk_frames", [7, 1 << 20])
def test_the_streamed_report_counts_the_logs_frames_when_asked(
    tmp_path: Path, chunk_frames: int
) -> None:
    """One function, the count optional (``odocan analyze`` of many logs shows it): every frame
    the log holds, whatever the chunk size, and the same report as without it."""
    path = log_of(tmp_path, "awkward")
    profile = load("pmir")
    count = FrameCount()
    got = analyze_file(path, profile, "rk2", chunk_frames=chunk_frames, count=count)
    assert count.frames == len(read_log(path)) > 0
    assert json.dumps(got) == json.dumps(analyze_file(path, profile, "rk2"))


def test_a_babble_run_is_refused_for_streaming_and_analysed_whole(tmp_path: Path) -> None:
    """Pose frames let out in a burst after a busy bus are paired by when their firmware made
    them (``queued_names``: a median over the whole life): the stream refuses the log, and
    the command, told to stream, writes the whole log's report."""
    path = log_of(tmp_path, "babble")
    profile = load("pmir")
    with pytest.raises(NotStreamable, match="burst"):
        analyze_file(path, profile, chunk_frames=64)
    want = analyze(read_log(path), profile).report
    report = tmp_path / "babble.json"
    code = main(["analyze", str(path), "--report", str(report), "--stream", "always"])
    got = json.loads(report.read_text())
    del got["inputs"]
    assert got == json.loads(json.dumps(want))
    assert code == 0
    assert want["passed"] is True


def test_auto_streams_a_log_by_its_size(tmp_path: Path) -> None:
    """``--stream auto``: a log bigger than the size where the whole path would pass the max
    RSS target streams, a smaller one does not; ``always`` and ``never`` force either."""
    for suffix in (".log", ".asc", ".blf"):
        limit = int(stream_above_bytes(suffix))
        assert 1e6 < limit < 1e9  # a few MB at least (.blf compresses), never the 1 GB log
        small, big = tmp_path / f"small{suffix}", tmp_path / f"big{suffix}"
        with small.open("wb") as f:
            f.truncate(limit)  # sparse: the size is what counts
        with big.open("wb") as f:
            f.truncate(limit + 1)
        assert not streams(small, "auto")
        assert streams(big, "auto")
        assert streams(small, "always")
        assert not streams(big, "never")
    assert not streams(tmp_path / "missing.log", "auto")  # the whole path names the error


def test_odocan_analyze_streams_the_report_it_wrote_from_the_whole_log(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The command: the streamed report (``--chunk-frames 7``) is the one the whole-log path
    writes (``-b`` reads the whole log and adds only its bus section), the same verdict and
    exit code; a failed verdict too (a wrong --integrator)."""
    path = log_of(tmp_path, "rig")
    for extra in ([], ["--integrator", "euler"]):
        streamed, whole = tmp_path / "streamed.json", tmp_path / "whole.json"
        code_s = main(["analyze", str(path), "--report", str(streamed), "--chunk-frames", "7",
                       "--stream", "always", *extra])
        out_s = capsys.readouterr().out
        code_w = main(["analyze", str(path), "--report", str(whole), "-b", "500000", *extra])
        out_w = capsys.readouterr().out
        got, want = json.loads(streamed.read_text()), json.loads(whole.read_text())
        del want["bus"]
        assert got == want
        assert list(got) == list(want)
        assert code_s == code_w == (0 if not extra else 1)
        verdict = "FAIL" if extra else "PASS"
        assert verdict in out_s
        assert verdict in out_w


def test_an_empty_chunk_numbers_no_encoder_frame() -> None:
    """A chunk without an accepted encoder frame gives no sequence number (it gave one)."""
    db = database()
    numbering = StreamEncoders(BulkDecoder(db))
    frames = rig_frames()
    ids = {db.get_message_by_name("WHEEL_ENCODERS").frame_id}
    other = frames.select(np.flatnonzero(~np.isin(frames.can_id, list(ids)))[:5])
    encoders = numbering.feed(other, np.ones(len(other), dtype=bool))
    assert len(encoders.seq) == len(encoders.index) == 0


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_asc_and_blf_logs_stream_the_same_report(tmp_path: Path, suffix: str) -> None:
    """The other log formats stream through python-can's readers: the same report."""
    frames = rig_frames()
    path = tmp_path / f"rig{suffix}"
    with can.Logger(str(path)) as logger:
        for i in range(len(frames)):
            logger.on_message_received(to_message(frames, i))
    profile = load("pmir")
    want = analyze(read_log(path), profile).report
    assert json.dumps(analyze_file(path, profile, chunk_frames=64)) == json.dumps(want)


def test_a_batch_worker_streams_the_same_report(tmp_path: Path) -> None:
    """``odocan analyze LOG…``'s worker (``batch.analyze_one``) streams too: the report and
    the frame count of the whole-log path; a log the analysis refuses still gets its one-line
    reason."""
    from odocan.host.cli.batch import Job, analyze_one
    from odocan.host.judge.analysis import Tolerance

    path = log_of(tmp_path, "rig")
    tolerance = Tolerance()
    result = analyze_one(str(path), Job("pmir", None, tolerance.position_m,
                                        tolerance.heading_rad, stream="always"))
    whole = read_log(path)
    want = analyze(whole, load("pmir")).report
    assert result.report is not None
    got = dict(result.report)
    del got["inputs"]
    assert json.dumps(got) == json.dumps(json.loads(json.dumps(want)))
    assert result.frames == len(whole)
    empty = tmp_path / "foreign.log"
    empty.write_text("(1.000000) vcan0 123#0102\n" * 3)
    refused = analyze_one(str(empty), Job("pmir", None, tolerance.position_m,
                                          tolerance.heading_rad, stream="always"))
    assert refused.error is not None
    assert "WHEEL_ENCODERS" in refused.error


def test_a_log_whose_times_go_back_is_analysed_whole(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Encoder frames whose times go back: the stall detection of a stream could differ from
    the whole log's, so the streamed analysis refuses (``NotStreamable``) and the command
    analyses the whole log: the whole log's report."""
    frames = rig_frames()
    wheel = np.flatnonzero(frames.can_id == database().get_message_by_name(
        "WHEEL_ENCODERS").frame_id)
    stamps = frames.timestamp_s.copy()
    stamps[wheel[40]] = stamps[wheel[39]] - 0.001  # recorded out of time order
    path = tmp_path / "back.log"
    with can.Logger(str(path)) as logger:
        for i in range(len(frames)):
            message = to_message(frames, i)
            message.timestamp = float(stamps[i])
            logger.on_message_received(message)
    with pytest.raises(NotStreamable):
        analyze_file(path, load("pmir"))
    report = tmp_path / "report.json"
    code = main(["analyze", str(path), "--report", str(report), "--stream", "always"])
    capsys.readouterr()
    want = analyze(read_log(path), load("pmir")).report
    got = json.loads(report.read_text())
    del got["inputs"]
    assert got == json.loads(json.dumps(want))
    assert code == (0 if want["passed"] else 1)
