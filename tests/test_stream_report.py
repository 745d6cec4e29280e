"""``odocan analyze`` in bounded memory: the report of a log read chunk by chunk
(``host.judge.stream_analysis.analyze_file``) is the whole log's (``analyze(read_log)``), every
key and every float bit for bit, at chunk sizes 1, 7, 64 and the whole log: on the awkward
synthesized log (a reboot, a counter restart, a gap across a COUNTER wrap, refused, repeated
and swapped frames) and on a lockstep rig run with bus faults, an MCU stall and a reboot."""

from __future__ import annotations

import json
from pathlib import Path

import can
import pytest

from odocan.host.io.logs import read_log, to_message
from odocan.host.judge.analysis import analyze
from odocan.host.judge.stream_analysis import analyze_file
from odocan.sim.robot import load
from tests.test_stream import awkward_lines
from tests.test_stream_facts import rig_frames

CHUNKS = [1, 7, 64, 1 << 20]


def log_of(tmp_path: Path, which: str) -> Path:
    path = tmp_path / f"{which}.log"
    if which == "awkward":
        path.write_text("".join(awkward_lines()))
        return path
    frames = rig_frames()
    with can.Logger(str(path)) as logger:
        for i in range(len(frames)):
            logger.on_message_received(to_message(frames, i))
    return path


@pytest.mark.parametrize("chunk_frames", CHUNKS)
@pytest.mark.parametrize("which", ["awkward", "rig"])
def test_the_streamed_report_is_the_whole_logs(
    tmp_path: Path, which: str, chunk_frames: int
) -> None:
    path = log_of(tmp_path, which)
    profile = load("pmir")
    want = analyze(read_log(path), profile, "rk2" if which == "awkward" else None).report
    got = analyze_file(path, profile, "rk2" if which == "awkward" else None,
                       chunk_frames=chunk_frames)
    assert json.dumps(got) == json.dumps(want)
    assert len(want["reboots"]) == 1  # what the logs hold
    if which == "rig":
        assert want["samples"]["truth_compared"] > 0
        assert [e["kind"] for e in want["events"]].count("firmware_stall") >= 1
