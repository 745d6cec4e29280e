"""The encoder frames the firmware lost that the log holds, streamed (``StreamLosses``,
``SpanDrops``): the spans of ``losses.firmware_losses`` and the allowance of
``losses.loss_allowance`` at every encoder frame and every on-board sample, bit for bit, at
every chunk size, on the lossy run of tests/test_stream_report.py (a babbler overflows the
firmware's mailbox) and on the faulted rig run (frames lost in an MCU stall)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from odocan.host.io.logs import iter_log, read_log
from odocan.host.judge.losses import firmware_losses, loss_allowance
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import (
    WIRE_COUNTER_BITS,
    encoder_frames,
    onboard_samples,
    pick_integrator,
)
from odocan.host.judge.stalls import after_stalls
from odocan.host.judge.stream import StreamE2E, StreamEncoders
from odocan.host.judge.stream_losses import SpanDrops, StreamLosses
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.test_stream_report import ROBOT, log_of

CHUNKS = [1, 7, 64, 1 << 20]


@pytest.mark.parametrize("chunk_frames", CHUNKS)
@pytest.mark.parametrize("which", ["lossy", "rig"])
def test_streamed_losses_and_allowance_are_the_whole_logs(
    tmp_path: Path, which: str, chunk_frames: int
) -> None:
    path = log_of(tmp_path, which)
    if which == "rig":  # its first life: the firmware reboots at 2 s
        lines = path.read_text().splitlines(keepends=True)
        path.write_text("".join(x for x in lines if float(x.split()[0].strip("()")) < 2.0))
    db, robot = database(), load(ROBOT[which])
    whole = read_log(path)
    decoder = BulkDecoder(db)
    _, accepted = check_frames(whole, db)
    enc = encoder_frames(whole, accepted, decoder)
    onboard, _, sent = onboard_samples(whole, accepted, decoder, enc)
    pose_y = decoder.select(whole, "ODOM_POSE_Y")
    pose_sent = whole.timestamp_s[pose_y[accepted[pose_y]]]
    onboard, _ = after_stalls(onboard, sent, enc, pose_sent)
    integrator, _ = pick_integrator(whole, accepted, decoder, None)
    want_spans = firmware_losses(whole, accepted, decoder, enc)
    every = np.arange(len(enc.seq), dtype=np.int64)

    e2e, numbering = StreamE2E(db), StreamEncoders(BulkDecoder(db))
    losses = StreamLosses(BulkDecoder(db))
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        ok = e2e.feed(chunk)
        losses.feed(chunk, ok, numbering.feed(chunk, ok))
    spans = losses.spans()
    assert spans == want_spans
    assert len(spans) >= (3 if which == "lossy" else 1)  # what the runs hold

    drops = SpanDrops(spans, Geometry.of(robot), min(robot.counter_bits, WIRE_COUNTER_BITS),
                      integrator)
    numbering = StreamEncoders(BulkDecoder(db))
    e2e = StreamE2E(db)
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        drops.feed(numbering.feed(chunk, e2e.feed(chunk)))
    drops.named(onboard.enc)
    for at in (onboard.enc, every):
        want = loss_allowance(enc, robot, integrator, want_spans, at, onboard.enc)
        np.testing.assert_array_equal(drops.allowance(at), want)
    assert np.max(drops.allowance(every)) > 0.0
