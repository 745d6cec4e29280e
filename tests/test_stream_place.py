"""The reference placed in passes over the on-board samples given chunk by chunk
(``host.judge.stream_place``) is the whole log's ``reference_path`` placement bit for bit: the
start pose (heading overlap, rotation fit, start position) and the offsets of the segments
after gaps and stalls, at chunk sizes down to one sample, on the faulted rig run of
``tests/test_stream_facts.py`` (its first life: consistent samples, the rotation fit; the whole
log across the reboot: samples that disagree) and on the awkward synthesized log."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from odocan.firmware.ecu import MAX_WHEEL_SPEED_MM_S
from odocan.host.io.logs import FrameArrays, read_log
from odocan.host.judge.compare import error_summary, pose_errors
from odocan.host.judge.reference import Geometry, integrate
from odocan.host.judge.reference_path import (
    Reference,
    _Relative,
    _start_pose,
    firmware_steps,
    raw_segment_offsets,
)
from odocan.host.judge.samples import (
    Poses,
    encoder_frames,
    onboard_samples,
)
from odocan.host.judge.stalls import after_stalls, pose_sent_times
from odocan.host.judge.stream_life import placed_chunks
from odocan.host.judge.stream_place import (
    PlacedChunk,
    reference_errors,
    segment_offsets,
    start_pose,
)
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.test_stream import awkward_lines
from tests.test_stream_facts import rig_frames

CHUNKS = [1, 7, 64, 1 << 20]


def placement_inputs(
    frames: FrameArrays,
) -> tuple[Poses, _Relative, np.ndarray, np.ndarray, np.ndarray]:
    """What ``build_reference`` places (a start fitted from sample 0's encoder frame): the
    samples after stalls, their increments and segments; and every encoder frame's segment
    and increments (x, y); the stalls' breaks."""
    db, robot = database(), load("pmir")
    decoder = BulkDecoder(db)
    _, accepted = check_frames(frames, db)
    enc = encoder_frames(frames, accepted, decoder)
    onboard, _, sent = onboard_samples(frames, accepted, decoder, enc)
    pose_sent = pose_sent_times(frames, accepted, decoder)  # CRC-right refused ones too
    onboard, breaks = after_stalls(onboard, sent, enc, pose_sent)
    e0 = int(onboard.enc[0])
    geometry = Geometry.of(robot)
    bits = min(robot.counter_bits, 24)
    steps = firmware_steps(enc, e0, geometry, bits, MAX_WHEEL_SPEED_MM_S)
    rel = integrate(steps.d_left, steps.d_right, geometry, "exact")
    zero = np.zeros(1)
    rel_x, rel_y = np.concatenate((zero, rel.x_m)), np.concatenate((zero, rel.y_m))
    rel_h = np.concatenate((zero, rel.heading_rad))
    at = onboard.enc - e0
    starts = np.concatenate(([False], np.diff(enc.seq[e0:]) > 1))
    inside = breaks[(breaks > e0) & (breaks < len(enc.seq))] - e0
    starts[inside] = True
    segment = np.cumsum(starts)
    relative = _Relative(rel_x[at], rel_y[at], rel_h[at], segment[at])
    return onboard, relative, segment, np.stack((rel_x, rel_y, rel_h)), breaks


def chunks_of(onboard: Poses, rel: _Relative, size: int) -> Iterator[PlacedChunk]:
    for s in range(0, len(onboard.enc), size):
        cut = slice(s, s + size)
        yield PlacedChunk(onboard.x_m[cut], onboard.y_m[cut], onboard.heading_rad[cut],
                          onboard.heading_raw[cut], rel.x_m[cut], rel.y_m[cut],
                          rel.heading_rad[cut], rel.segment[cut])


def logs() -> dict[str, FrameArrays]:
    rig = rig_frames()
    first_life = rig.select(np.flatnonzero(rig.timestamp_s < rig.timestamp_s[0] + 1.9))
    return {"rig first life": first_life, "rig across the reboot": rig}


@pytest.mark.parametrize("chunk", CHUNKS)
@pytest.mark.parametrize("which", ["rig first life", "rig across the reboot", "awkward"])
def test_placement_in_passes_is_the_whole_logs(tmp_path: Path, which: str, chunk: int) -> None:
    if which == "awkward":
        path = tmp_path / "awkward.log"
        path.write_text("".join(awkward_lines()))
        frames = read_log(path)
    else:
        frames = logs()[which]
    onboard, rel, segment, rel_xy, _ = placement_inputs(frames)
    want = _start_pose(onboard, rel, power_up=False)
    got = start_pose(lambda: chunks_of(onboard, rel, chunk), power_up=False)
    assert got == want
    assert start_pose(lambda: chunks_of(onboard, rel, chunk), power_up=True) == (
        _start_pose(onboard, rel, power_up=True))
    x0, y0, h0, _ = want
    cos0, sin0 = np.cos(h0), np.sin(h0)
    x_m = x0 + cos0 * rel_xy[0] - sin0 * rel_xy[1]
    y_m = y0 + sin0 * rel_xy[0] + cos0 * rel_xy[1]
    at = onboard.enc - onboard.enc[0]
    raw_x = raw_segment_offsets(segment, at, onboard.x_m - x_m[at])
    raw_y = raw_segment_offsets(segment, at, onboard.y_m - y_m[at])
    off_x, off_y = segment_offsets(lambda: chunks_of(onboard, rel, chunk), (x0, y0, h0),
                                   int(segment[-1]) + 1)
    np.testing.assert_array_equal(off_x, raw_x)  # NaN where a segment has no sample
    np.testing.assert_array_equal(off_y, raw_y)
    filled = np.maximum.accumulate(np.where(np.isnan(raw_x), 0, np.arange(len(raw_x))))
    off_x, off_y = off_x[filled], off_y[filled]
    want_x, want_y = raw_x[filled][segment], raw_y[filled][segment]
    ref = Reference(int(onboard.enc[0]), x_m + want_x, y_m + want_y, h0 + rel_xy[2],
                    np.zeros(len(x_m))).at(onboard.enc)
    want_errors = error_summary(*pose_errors(onboard, ref))
    got_errors = reference_errors(lambda: chunks_of(onboard, rel, chunk), (x0, y0, h0),
                                  (off_x, off_y))
    assert got_errors == want_errors
    assert list(got_errors) == list(want_errors)  # the report's key order too
    if which == "rig first life":  # the fit's branch: consistent headings, a lever arm
        assert int(segment[-1]) >= 1  # the stall's restart


def frames_of(tmp_path: Path, which: str) -> FrameArrays:
    if which != "awkward":
        return logs()[which]
    path = tmp_path / "awkward.log"
    path.write_text("".join(awkward_lines()))
    return read_log(path)


@pytest.mark.parametrize("chunk", CHUNKS)
@pytest.mark.parametrize("which", ["rig first life", "rig across the reboot", "awkward"])
def test_placed_chunks_from_the_frames_are_the_whole_logs(
    tmp_path: Path, which: str, chunk: int
) -> None:
    """The frames chunk by chunk to the placement's input: the samples after stalls, the
    reference's increments at each and its segment, as the whole log's build_reference has
    them."""
    frames = frames_of(tmp_path, which)
    onboard, rel, _, _, breaks = placement_inputs(frames)
    pieces = (frames.select(np.arange(s, min(s + chunk, len(frames))))
              for s in range(0, len(frames), chunk))
    got = list(placed_chunks(pieces, database(), load("pmir"), "exact",
                             e0=int(onboard.enc[0]), breaks=breaks,
                             max_wheel_speed_mm_s=MAX_WHEEL_SPEED_MM_S))
    want = {"x_m": onboard.x_m, "y_m": onboard.y_m, "heading_rad": onboard.heading_rad,
            "heading_raw": onboard.heading_raw, "rel_x_m": rel.x_m, "rel_y_m": rel.y_m,
            "rel_heading_rad": rel.heading_rad, "segment": rel.segment}
    for name, values in want.items():
        np.testing.assert_array_equal(np.concatenate([getattr(p, name) for p in got]), values,
                                      err_msg=name)
