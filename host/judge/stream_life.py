"""A firmware life's frames to the placement's input, chunk by chunk (issue #14.1): the
on-board samples after stalls, each with the reference's increments from the start frame e0
to its encoder frame and the segment it lies in (``reference_path.build_reference``'s ``rel``
at ``at`` and ``segment``), as ``host.judge.stream_place.PlacedChunk`` -- what the placement's
passes read.

The stages run as in the first pass (E2E, encoder sequence, samples, stalls); the reference's
increments (``stream.StreamReference``, fed the encoder frames from e0) and the segments (a
gap of the sequence or a stall's break starts one) wait, one row per encoder frame, until the
sample of their encoder frame is given out: samples leave in encoder order, so the rows below
the last sample given out are dropped."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import cantools
import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import WIRE_COUNTER_BITS, Encoders
from odocan.host.judge.stream import StreamE2E, StreamEncoders, StreamPoses, StreamReference
from odocan.host.judge.stream_place import PlacedChunk
from odocan.host.judge.stream_stalls import StreamStalls
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import RobotProfile


@dataclass
class _Rows:
    """The reference's rows from e0 not yet matched to a sample: encoder frame number g,
    increments, segment."""

    columns: dict[str, np.ndarray] = field(default_factory=dict)
    last_seq: int | None = None  # of the last encoder frame from e0
    segment: int = 0  # the last row's

    def add(self, g: npt.NDArray[np.int64], seq: npt.NDArray[np.int64],
            increments: dict[str, np.ndarray], breaks: npt.NDArray[np.int64]) -> None:
        if len(g) == 0:
            return
        prior = np.concatenate(([self.last_seq if self.last_seq is not None else seq[0]],
                                seq))
        starts = np.diff(prior) > 1
        if self.last_seq is None:
            starts[0] = False  # the start frame opens segment 0
        starts |= np.isin(g, breaks)  # breaks after e0 only: e0 itself opens segment 0
        segment = self.segment + np.cumsum(starts)
        new = {"g": g, "segment": segment, **increments}
        self.columns = ({k: np.concatenate((self.columns[k], v)) for k, v in new.items()}
                        if self.columns else new)
        self.last_seq, self.segment = int(seq[-1]), int(segment[-1])

    def at(self, g: npt.NDArray[np.int64]) -> dict[str, np.ndarray]:
        """The rows of encoder frames ``g`` (sorted), and the rows below them dropped."""
        if len(g) == 0:
            return {k: v[:0] for k, v in self.columns.items()}
        k = np.searchsorted(self.columns["g"], g)
        rows = {name: v[k] for name, v in self.columns.items()}
        self.columns = {name: v[int(k[-1]):] for name, v in self.columns.items()}
        return rows


def placed_chunks(
    chunks: Iterable[FrameArrays], db: cantools.database.can.Database, robot: RobotProfile,
    integrator: str, *, e0: int, breaks: npt.NDArray[np.int64],
    max_wheel_speed_mm_s: int | None,
) -> Iterator[PlacedChunk]:
    """The placement's input over one life's frames (module docstring); ``e0``: the encoder
    frame the reference starts at, ``breaks``: the stalls' (``StreamStalls.breaks`` of a first
    pass; only those after e0 start a segment)."""
    decoder = BulkDecoder(db)
    e2e, numbering = StreamE2E(db), StreamEncoders(decoder)
    poses = StreamPoses(BulkDecoder(db))
    stalls: StreamStalls | None = None
    reference = StreamReference(Geometry.of(robot), integrator,
                                min(robot.counter_bits, WIRE_COUNTER_BITS), max_wheel_speed_mm_s)
    rows, count = _Rows(), 0
    inside = breaks[breaks > e0]
    for chunk in chunks:
        accepted = e2e.feed(chunk)
        enc = numbering.feed(chunk, accepted)
        stalls = stalls or StreamStalls(enc.cycle_s)
        g = count + np.arange(len(enc.index), dtype=np.int64)
        count += len(g)
        from_e0 = g >= e0
        rows.add(g[from_e0], enc.seq[from_e0], reference.feed(_take(enc, from_e0)), inside)
        samples, sent = poses.feed(chunk, accepted, enc)
        watermark = min(float(chunk.timestamp_s[-1]), poses.open_sent_s())
        yield _placed(stalls.feed(samples, sent, enc.timestamp_s, watermark), rows)
    if stalls is None:
        return
    samples, sent = poses.finish()
    yield _placed(stalls.feed(samples, sent, np.zeros(0), np.inf), rows)
    yield _placed(stalls.finish(), rows)


def _take(enc: Encoders, keep: npt.NDArray[np.bool_]) -> Encoders:
    return Encoders(index=enc.index[keep], counter=enc.counter[keep], seq=enc.seq[keep],
                    left=enc.left[keep], right=enc.right[keep],
                    timestamp_s=enc.timestamp_s[keep], cycle_s=enc.cycle_s)


def _placed(samples: dict[str, np.ndarray], rows: _Rows) -> PlacedChunk:
    at = rows.at(samples["enc"])
    return PlacedChunk(samples["x_m"], samples["y_m"], samples["heading_rad"],
                       samples["heading_raw"], at.get("x_m", np.zeros(0)),
                       at.get("y_m", np.zeros(0)), at.get("heading_rad", np.zeros(0)),
                       at.get("segment", np.zeros(0, dtype=np.int64)))
