"""Streaming a log chunk by chunk gives the whole log's truth samples (``StreamTruth``) and the
report's facts (``StreamFacts``: frames per message, covered seconds, the integrator, the
power-up rule's inputs), at every chunk size down to one frame: on the awkward synthesized log
of ``tests/test_stream.py`` (a reboot, a counter restart, a gap across a COUNTER wrap, refused
frames, poses logged before their encoder frame) and on a lockstep rig run whose bus drops,
repeats and corrupts frames and whose firmware reboots."""

from __future__ import annotations

import itertools
from functools import cache
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.io.logs import FrameArrays, FrameCollector, iter_log, read_log, to_message
from odocan.host.judge.blockdot import DOT_BLOCK, block_dot
from odocan.host.judge.compare import _outside_band, check_twist
from odocan.host.judge.powerup import saw_only_the_log, starts_at_power_up
from odocan.host.judge.reboots import split_lives
from odocan.host.judge.reportfacts import covered_s, frame_counts
from odocan.host.judge.samples import (
    Poses,
    encoder_frames,
    onboard_samples,
    pick_integrator,
    truth_samples,
)
from odocan.host.judge.stalls import after_stalls
from odocan.host.judge.stream import StreamE2E, StreamEncoders, StreamPoses
from odocan.host.judge.stream_facts import StreamFacts
from odocan.host.judge.stream_fit import BlockDot, SegmentSums
from odocan.host.judge.stream_lives import StreamLives
from odocan.host.judge.stream_stalls import StreamStalls
from odocan.host.judge.stream_truth import StreamTruth
from odocan.host.judge.stream_twist import StreamTwist
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.board import FirmwareBoard
from odocan.sim.contract import database
from odocan.sim.faults import FaultSpec
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.sweeps import sample
from tests.test_stream import awkward_lines

CHUNKS = [1, 2, 7, 64, 1 << 20]
# tests.sweeps: each log frame by frame and whole, each chunk size once, a third of the rest
CHUNKED = sample(itertools.product(["awkward", "rig"], CHUNKS), 3,
                 [("awkward", 1), ("rig", 1), ("awkward", 1 << 20), ("rig", 1 << 20),
                  ("awkward", 7), ("rig", 2), ("awkward", 64)])
POSE_COLUMNS = ("enc", "x_m", "y_m", "heading_rad", "heading_raw")


@cache
def rig_frames() -> FrameArrays:
    """3 s of the rig's circle, its MCU stalled for 0.3 s at 1 s, its firmware rebooted at 2 s,
    the sim's frames dropped (3 %), repeated (2 %) and bit-flipped (1 %) on the bus."""
    collector = FrameCollector()
    faults = FaultSpec(drop=0.03, dup=0.02, flip=0.01, flip_bits=2, seed=7)
    scenario = get_scenario("circle", load("pmir"), duration_s=60.0)
    with FaultRig(sim_faults=faults, scenario=scenario) as rig:
        def record(tick: int, frames: list[can.Message]) -> None:
            for msg in frames:
                collector.on_message_received(msg)

        def reboot(k: int) -> None:
            if k == 200:
                rig.board = FirmwareBoard(rig.fw_bus, rig.params, rig.clock)

        rig.observers.append(record)
        rig.before_board.append(reboot)
        rig.halted = lambda k: 100 <= k < 130
        rig.run(3.0)
    return collector.arrays()


def log_of(tmp_path: Path, which: str) -> Path:
    path = tmp_path / f"{which}.log"
    if which == "awkward":
        path.write_text("".join(awkward_lines()))
        return path
    with can.Logger(str(path)) as logger:
        frames = rig_frames()
        for i in range(len(frames)):
            logger.on_message_received(to_message(frames, i))
    return path


def pose_columns(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {name: np.concatenate([p[name] for p in parts]) for name in POSE_COLUMNS}


@pytest.mark.parametrize(("which", "chunk_frames"), CHUNKED)
def test_streamed_truth_and_facts_are_the_whole_logs(
    tmp_path: Path, which: str, chunk_frames: int
) -> None:
    path = log_of(tmp_path, which)
    db = database()
    whole = read_log(path)
    decoder = BulkDecoder(db)
    _, accepted_all = check_frames(whole, db)
    enc = encoder_frames(whole, accepted_all, decoder)
    want_truth = truth_samples(whole, accepted_all, decoder, enc)
    onboard, _, _ = onboard_samples(whole, accepted_all, decoder, enc)

    e2e, numbering = StreamE2E(db), StreamEncoders(BulkDecoder(db))
    poses, truth = StreamPoses(BulkDecoder(db)), StreamTruth(BulkDecoder(db))
    facts = StreamFacts(BulkDecoder(db))
    truth_parts, first_sample = [], []
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        accepted = e2e.feed(chunk)
        encoders = numbering.feed(chunk, accepted)
        first_sample.append(poses.feed(chunk, accepted, encoders)[0])
        truth_parts.append(truth.feed(chunk, accepted, encoders)[0])
        facts.feed(chunk, accepted)
    truth_parts.append(truth.finish()[0])
    first_sample.append(poses.finish()[0])

    got = pose_columns(truth_parts)
    for name in POSE_COLUMNS:
        np.testing.assert_array_equal(got[name], getattr(want_truth, name), err_msg=name)
    assert facts.frame_counts == frame_counts(whole, decoder)
    assert facts.covered_s() == covered_s(whole, db)
    assert facts.integrator(None) == pick_integrator(whole, accepted_all, decoder, None)
    assert facts.saw_only_the_log() == saw_only_the_log(whole, accepted_all, decoder)
    first = pose_columns(first_sample)
    head = Poses(*(first[name][:1] for name in POSE_COLUMNS))
    want_power_up = starts_at_power_up(whole, accepted_all, decoder, onboard)
    assert facts.starts_at_power_up(head) == want_power_up
    if which == "rig":  # the run is what the docstring says: truth, refused frames, power-up
        assert len(want_truth.enc) > 20  # SIM_TRUTH at 10 Hz
        counts = e2e.counts["WHEEL_ENCODERS"]
        assert counts["lost"] + counts["repeated"] + counts["crc_errors"] > 0
        assert want_power_up
    else:
        assert len(want_truth.enc) == 0  # the synthesized log carries no SIM_TRUTH


@pytest.mark.parametrize(("which", "chunk_frames"), CHUNKED)
def test_streamed_twist_check_is_the_whole_logs(
    tmp_path: Path, which: str, chunk_frames: int
) -> None:
    """ODOM_TWIST judged against the reference's step speeds across every cut: the same number
    of judged frames and the same largest excesses (compared exactly) as the whole log's."""
    path = log_of(tmp_path, which)
    db, robot = database(), load("pmir")
    whole = read_log(path)
    decoder = BulkDecoder(db)
    _, accepted_all = check_frames(whole, db)
    enc = encoder_frames(whole, accepted_all, decoder)
    want = check_twist(whole, accepted_all, decoder, enc, robot)
    e2e, numbering = StreamE2E(db), StreamEncoders(BulkDecoder(db))
    twist = StreamTwist(BulkDecoder(db), robot)
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        accepted = e2e.feed(chunk)
        twist.feed(chunk, accepted, numbering.feed(chunk, accepted))
    assert twist.finish() == want
    if which == "rig":  # the synthesized log has no ODOM_TWIST
        assert want["samples"] > 20


def test_the_twist_band_of_the_last_segment_holds_its_last_step() -> None:
    """The whole log's band over steps (e[k], e[k + 1]] ends at the last named encoder frame
    even when the log's last twist frames name one frame again (the firmware heard no new
    encoder frame): the step into it is in the band (``reduceat`` once cut it off there)."""
    step = np.array([np.nan, 1.0, 1.0, 1.0, 5.0])  # per encoder frame: speed of the step into it
    gap = np.zeros(5)
    e = np.array([0, 1, 4, 4])  # the last two twist frames both name encoder frame 4
    out = _outside_band(np.array([0.0, 0.0, 5.0, 5.0]), e, step, gap)
    np.testing.assert_array_equal(out[2:], [0.0, 0.0])  # 5.0 lies in the band [1, 5]
    out = _outside_band(np.array([0.0, 0.0, 6.0, 6.0]), e, step, gap)
    slack = 1e-3 + 0.02 * 5.0
    np.testing.assert_allclose(out[2:], [1.0 - slack, 1.0 - slack])


@pytest.mark.parametrize(("which", "chunk_frames"), CHUNKED)
def test_streamed_lives_are_the_whole_logs(tmp_path: Path, which: str, chunk_frames: int) -> None:
    """The firmware reboot found, and each life started, where the whole log's split puts it."""
    path = log_of(tmp_path, which)
    db = database()
    whole = read_log(path)
    want = split_lives(whole, BulkDecoder(db))
    e2e, lives = StreamE2E(db), StreamLives(BulkDecoder(db))
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        lives.feed(chunk, e2e.feed(chunk))
    got = lives.finish()
    assert len(want) == 2  # both logs hold one reboot
    assert [(g.start, g.stop) for g in got] == [(int(w.index[0]), int(w.index[-1]) + 1)
                                                for w in want]
    assert [(g.boot, g.t_s, g.uptime_before_s) for g in got] == [
        (w.boot, w.t_s, w.uptime_before_s) for w in want]


@pytest.mark.parametrize(("which", "chunk_frames"), CHUNKED)
def test_streamed_stalls_are_the_whole_logs(tmp_path: Path, which: str, chunk_frames: int) -> None:
    """The samples sent after a stall left out and the reference's restarts placed where the
    whole log's ``after_stalls`` puts them, the kept samples in encoder order."""
    path = log_of(tmp_path, which)
    db = database()
    whole = read_log(path)
    decoder = BulkDecoder(db)
    _, accepted_all = check_frames(whole, db)
    enc = encoder_frames(whole, accepted_all, decoder)
    onboard, _, sent_all = onboard_samples(whole, accepted_all, decoder, enc)
    pose_y = decoder.select(whole, "ODOM_POSE_Y")
    pose_sent = whole.timestamp_s[pose_y[accepted_all[pose_y]]]
    want, want_breaks = after_stalls(onboard, sent_all, enc, pose_sent)
    e2e, numbering = StreamE2E(db), StreamEncoders(BulkDecoder(db))
    poses, stalls = StreamPoses(BulkDecoder(db)), StreamStalls(enc.cycle_s)
    parts = []
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        accepted = e2e.feed(chunk)
        encoders = numbering.feed(chunk, accepted)
        samples, sent = poses.feed(chunk, accepted, encoders)
        watermark = min(float(chunk.timestamp_s[-1]), poses.open_sent_s())
        pose_y = numbering.decoder.select(chunk, "ODOM_POSE_Y")
        pose_t = chunk.timestamp_s[pose_y[accepted[pose_y]]]
        parts.append(stalls.feed(samples, sent, encoders.timestamp_s, watermark, pose_t))
    samples, sent = poses.finish()
    parts.append(stalls.feed(samples, sent, np.zeros(0), np.inf))
    parts.append(stalls.finish())
    got = pose_columns(parts)
    for name in POSE_COLUMNS:
        np.testing.assert_array_equal(got[name], getattr(want, name), err_msg=name)
    np.testing.assert_array_equal(stalls.breaks, want_breaks)
    assert stalls.exact
    if which == "rig":  # the stall is in the log (and, over both lives, the reboot's silence)
        assert len(want_breaks) >= 1
        assert len(want.enc) < len(onboard.enc)


@pytest.mark.parametrize("chunk", [1, 7, 64, 1 << 20])
def test_the_start_fits_sums_streamed_are_the_whole_logs(chunk: int) -> None:
    """The rotation fit's segment means (``np.bincount``) and its dot products in fixed blocks
    (``block_dot``), summed chunk by chunk over more than one block with segments cut
    anywhere: equal bit for bit (values of mixed magnitudes, where the order of the additions
    shows)."""
    rng = np.random.default_rng(14)
    n = DOT_BLOCK + 4_321
    segment = np.cumsum(rng.random(n) < 0.001).astype(np.int64)
    a = rng.normal(size=n) * 10.0 ** rng.integers(-6, 6, size=n)
    b = rng.normal(size=n) * 10.0 ** rng.integers(-6, 6, size=n)
    sums, dot = SegmentSums(), BlockDot()
    for start in range(0, n, chunk):
        sums.feed(segment[start : start + chunk], a[start : start + chunk])
        dot.feed(a[start : start + chunk], b[start : start + chunk])
    want_means = np.bincount(segment, weights=a) / np.maximum(np.bincount(segment), 1)
    np.testing.assert_array_equal(sums.means(), want_means)
    assert dot.result() == block_dot(a, b)
    assert block_dot(a[:DOT_BLOCK], b[:DOT_BLOCK]) == float(np.dot(a[:DOT_BLOCK], b[:DOT_BLOCK]))
