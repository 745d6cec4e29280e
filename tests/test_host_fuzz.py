"""Fuzz the host: 100 000 random frames (any ID and DLC, error and remote frames, CRC-valid frames
of every DBC message) through the log writer and parser, the bulk E2E check and decoder, the
analysis, the streaming E2E monitor and the monitor's state model: no uncaught exception."""

from __future__ import annotations

import json
import random
from pathlib import Path

import can
import pytest

from odocan.host.io.logs import FrameCollector, read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.sim.contract import database
from odocan.sim.exceptions import OdocanError
from odocan.sim.robot import load
from tests.fault_rig import random_message

FRAMES = 100_000


@pytest.fixture(scope="module")
def messages() -> list[can.Message]:
    rng = random.Random(2026)
    return [random_message(rng, k * 1e-4) for k in range(FRAMES)]


def test_bulk_path_takes_any_frames(messages: list[can.Message], tmp_path: Path) -> None:
    collector = FrameCollector()
    for msg in messages:
        collector.on_message_received(msg)
    frames = collector.arrays()
    assert len(frames) == FRAMES
    counts, accepted = check_frames(frames)
    unknown = counts["unknown"]
    assert unknown["error_frames"] > 5_000
    assert unknown["remote_frames"] > 5_000
    assert 0 < int(accepted.sum()) < FRAMES  # some sealed frames pass, garbage does not
    decoder = BulkDecoder(database())
    for message in database().messages:
        decoded = decoder.decode(frames, message.name)
        assert all(len(v) == len(decoded["index"]) for v in decoded.values())
    error = None
    try:
        result = analyze(frames, load("pmir"), "exact")
    except OdocanError as exc:  # the frames do not make a drive: a one-line error, not a crash
        error = str(exc)
    else:
        json.dumps(result.report, allow_nan=False)
    assert error is None or "\n" not in error

    path = tmp_path / "fuzz.log"
    with can.Logger(path) as logger:
        for msg in messages:
            logger.on_message_received(msg)
    assert len(read_log(path)) == FRAMES


def test_streaming_path_takes_any_frames(messages: list[can.Message]) -> None:
    e2e = E2EMonitor()
    monitor = BusMonitor(load("pmir"))
    verdicts: set[str] = set()
    for k, msg in enumerate(messages):
        verdicts.add(e2e.check(msg.arbitration_id, bytes(msg.data), extended=msg.is_extended_id))
        monitor.feed(msg, now_s=k * 1e-4)
    assert {"ok", "crc_error", "unknown_id", "wrong_dlc"} <= verdicts
    monitor.release_held()  # the watch's end (the CLI's): frames a hold kept are judged now
    snapshot = monitor.snapshot()
    assert snapshot["frames_total"] == len(messages)  # every frame counted, none lost to a crash
    known = sum(m["count"] for m in snapshot["messages"].values())
    assert 0 < known < len(messages)
    json.dumps(snapshot, allow_nan=False, default=str)
