"""Streaming a log chunk by chunk gives what the whole log gives: frames (``iter_log``), E2E
(``StreamE2E``) and the encoder sequence (``StreamEncoders``), at every chunk size down to one
frame, so at every awkward cut: between an encoder frame and the pose that echoes it, across a
COUNTER wrap, inside a gap, at a firmware reboot, at a counter restart, next to a frame the E2E
check refuses."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.firmware.ecu import MAX_WHEEL_SPEED_MM_S
from odocan.host.io.logs import (
    FrameArrays,
    LogFormatError,
    concat_frames,
    iter_log,
    read_log,
    to_message,
)
from odocan.host.judge.reference import Geometry, integrate
from odocan.host.judge.reference_path import firmware_steps
from odocan.host.judge.samples import encoder_frames, onboard_samples
from odocan.host.judge.stream import StreamE2E, StreamEncoders, StreamPoses, StreamReference
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.synth_log import synthesize, synthesize_stalled, wandering_drive

CHUNKS = [1, 2, 7, 64, 1 << 20]


@cache
def awkward_lines(spoiled: int = 205, reordered: tuple[int, ...] = (150, 152, 161),
                  ) -> tuple[str, ...]:
    """A drive with a firmware reboot (frame 300), a counter restart (frame 500), a gap of 20
    encoder frames (620..639: the COUNTER wraps inside it), a repeated frame, a frame with a bad
    CRC (line ``spoiled``: 205 an encoder frame, whose pose then names a frame the host refused,
    216 an ODOM_STATUS frame), two frames swapped, and poses logged before the encoder frame
    they name (the groups ``reordered``)."""
    profile = load("pmir")
    d_left, d_right = wandering_drive(profile, 800, 0.004, seed=3)
    synth = synthesize(profile, "rk2", d_left, d_right, reboot_at=300,
                       counter_jumps={500: 20_000})
    for k in reordered:  # the poses (and status) logged before the frame they name
        synth.groups[k] = synth.groups[k][1:] + synth.groups[k][:1]
    lines = list(synth.lines(0, 620)) + list(synth.lines(640))
    lines.insert(101, lines[100])  # repeated
    bad = lines[spoiled]
    at = bad.index("#") + 1  # the CRC byte's two hex digits
    lines[spoiled] = bad[:at] + ("00" if bad[at : at + 2] != "00" else "11") + bad[at + 2 :]
    lines[410], lines[411] = lines[411], lines[410]  # out of order
    return tuple(lines)


def write(tmp_path: Path, suffix: str) -> Path:
    log = tmp_path / "awkward.log"
    log.write_text("".join(awkward_lines()))
    if suffix == ".log":
        return log
    frames = read_log(log)
    other = tmp_path / f"awkward{suffix}"
    with can.Logger(str(other)) as logger:
        for i in range(len(frames)):
            logger.on_message_received(to_message(frames, i))
    return other


def assert_same_frames(got: FrameArrays, want: FrameArrays) -> None:
    assert len(got) == len(want)
    for name in ("timestamp_s", "can_id", "dlc", "data", "flags"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
@pytest.mark.parametrize("chunk_frames", [1, 7, 1000])
def test_iter_log_gives_the_frames_of_read_log(
    tmp_path: Path, suffix: str, chunk_frames: int
) -> None:
    path = write(tmp_path, suffix)
    chunks = list(iter_log(path, chunk_frames=chunk_frames))
    assert all(len(c) == chunk_frames for c in chunks[:-1])
    assert 1 <= len(chunks[-1]) <= chunk_frames
    assert_same_frames(concat_frames(chunks), read_log(path))


def test_iter_log_keeps_read_logs_rules(tmp_path: Path) -> None:
    """The partial last line skipped with the same warning; a bad line named by its line in
    the file, raised when its chunk is reached; an empty log and a missing one refused."""
    lines = awkward_lines()
    cut = tmp_path / "cut.log"
    cut.write_text("".join(lines[:50]) + lines[50][:11])
    warned: list[str] = []
    streamed = concat_frames(list(iter_log(cut, chunk_frames=3, warn=warned.append)))
    whole_warned: list[str] = []
    assert_same_frames(streamed, read_log(cut, warn=whole_warned.append))
    assert warned == whole_warned
    assert len(warned) == 1
    bad = tmp_path / "bad.log"
    bad.write_text("".join(lines[:300]) + "(9.0) vcan0 123#00112\n" + "".join(lines[300:]))
    with pytest.raises(LogFormatError) as whole:
        read_log(bad)
    with pytest.raises(LogFormatError) as streamed_error:
        list(iter_log(bad, chunk_frames=5))
    assert str(streamed_error.value) == str(whole.value)
    assert ":301:" in str(whole.value)
    empty = tmp_path / "empty.log"
    empty.write_text("")
    with pytest.raises(LogFormatError, match="empty log"):
        list(iter_log(empty))
    with pytest.raises(LogFormatError, match="no such log file"):
        list(iter_log(tmp_path / "missing.log"))


@pytest.mark.parametrize("chunk_frames", CHUNKS)
def test_streamed_e2e_and_encoder_sequence_are_the_whole_logs(
    tmp_path: Path, chunk_frames: int
) -> None:
    path = write(tmp_path, ".log")
    db = database()
    whole = read_log(path)
    want_counts, want_accepted = check_frames(whole, db)
    want_enc = encoder_frames(whole, want_accepted, BulkDecoder(db))
    e2e, numbering = StreamE2E(db), StreamEncoders(BulkDecoder(db))
    accepted, parts = [], []
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        accepted.append(e2e.feed(chunk))
        parts.append(numbering.feed(chunk, accepted[-1]))
    np.testing.assert_array_equal(np.concatenate(accepted), want_accepted)
    assert e2e.counts == want_counts
    # the log has what the test says it has: refusals of every kind, a wrap inside the gap
    enc = want_counts["WHEEL_ENCODERS"]
    assert enc["repeated"] + enc["crc_errors"] + enc["wrong_sequence"] > 0
    assert want_counts["WHEEL_ENCODERS"]["lost"] > 0
    for name in ("index", "counter", "seq", "left", "right", "timestamp_s"):
        got = np.concatenate([getattr(p, name) for p in parts])
        np.testing.assert_array_equal(got, getattr(want_enc, name), err_msg=name)
    assert np.any(np.diff(want_enc.seq) >= 16)  # the gap took more than one COUNTER turn


def held_log(tmp_path: Path) -> Path:
    """A firmware that stalls (frame 300, 40 frames), holds its pose on one frame while its E2E
    window is shut (frame 700, 30 frames: its poses keep naming frame 699) and takes late
    frames: pose frames repeating the ENC_COUNTER of the one before them."""
    profile = load("kobuki")
    d_left, d_right = wandering_drive(profile, 1200, 0.004, seed=3)
    synth = synthesize_stalled(profile, "exact", d_left, d_right, stalls={300: 40},
                               holds={700: 30}, late={150, 151, 900})
    return synth.write(tmp_path / "held.log")


@pytest.mark.parametrize("log", ["awkward", "held"])
@pytest.mark.parametrize("chunk_frames", CHUNKS)
def test_streamed_onboard_samples_are_the_whole_logs(
    tmp_path: Path, chunk_frames: int, log: str
) -> None:
    """Pose frames paired with the encoder frame they name across every cut: the same samples,
    in the same order, the same unmatched count, as the whole log's alignment (held poses
    carried across cuts)."""
    path = write(tmp_path, ".log") if log == "awkward" else held_log(tmp_path)
    db = database()
    whole = read_log(path)
    _, accepted_all = check_frames(whole, db)
    enc = encoder_frames(whole, accepted_all, BulkDecoder(db))
    want, want_unmatched, want_sent = onboard_samples(whole, accepted_all, BulkDecoder(db), enc)
    e2e, numbering = StreamE2E(db), StreamEncoders(BulkDecoder(db))
    poses = StreamPoses(BulkDecoder(db))
    parts, sent = [], []
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        accepted = e2e.feed(chunk)
        samples, sent_s = poses.feed(chunk, accepted, numbering.feed(chunk, accepted))
        parts.append(samples)
        sent.append(sent_s)
    samples, sent_s = poses.finish()
    parts.append(samples)
    sent.append(sent_s)
    for name in ("enc", "x_m", "y_m", "heading_rad", "heading_raw"):
        got = np.concatenate([p[name] for p in parts])
        np.testing.assert_array_equal(got, getattr(want, name), err_msg=name)
    np.testing.assert_array_equal(np.concatenate(sent), want_sent)
    assert poses.unmatched == want_unmatched
    if log == "awkward":
        assert want_unmatched > 0  # the gap and the refused frames leave poses without a frame


@pytest.mark.parametrize("chunk_frames", CHUNKS)
@pytest.mark.parametrize("integrator", ["euler", "exact"])
def test_streamed_reference_is_the_whole_logs(
    tmp_path: Path, chunk_frames: int, integrator: str
) -> None:
    """The steps as the firmware takes them (refusals and the counter restart's re-prime across
    cuts) and their integration: every increment bit for bit the whole log's."""
    path = write(tmp_path, ".log")
    db = database()
    whole = read_log(path)
    _, accepted_all = check_frames(whole, db)
    enc = encoder_frames(whole, accepted_all, BulkDecoder(db))
    geometry = Geometry.of(load("pmir"))
    steps = firmware_steps(enc, 0, geometry, 16, MAX_WHEEL_SPEED_MM_S)
    rel = integrate(steps.d_left, steps.d_right, geometry, integrator)
    e2e, numbering = StreamE2E(db), StreamEncoders(BulkDecoder(db))
    reference = StreamReference(geometry, integrator, 16, MAX_WHEEL_SPEED_MM_S)
    parts = []
    for chunk in iter_log(path, chunk_frames=chunk_frames):
        accepted = e2e.feed(chunk)
        parts.append(reference.feed(numbering.feed(chunk, accepted)))
    for name in ("x_m", "y_m", "heading_rad", "distance_m"):
        want = np.concatenate(([0.0], getattr(rel, name)))
        np.testing.assert_array_equal(np.concatenate([p[name] for p in parts]), want,
                                      err_msg=name)
    assert steps.refused > 0  # the counter restart's frames
    assert reference.refused == steps.refused
    assert reference.reprimed == steps.reprimed
