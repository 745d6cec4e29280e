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

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapfill import crc_holds
from odocan.host.judge.nearthreshold import least_of
from odocan.host.judge.reference import Geometry, SpeedBound
from odocan.host.judge.samples import WIRE_COUNTER_BITS, Encoders
from odocan.host.judge.stream import StreamE2E, StreamEncoders, StreamPoses, StreamReference
from odocan.host.judge.stream_place import PlacedChunk
from odocan.host.judge.stream_stalls import StreamStalls
from odocan.host.judge.stream_truth import StreamTruth
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.robot import RobotProfile

if TYPE_CHECKING:  # a cantools Database or a plan of it (host.protocol.dbcplan)
    from odocan.host.judge.stream_reprime import ReprimeTap
    from odocan.host.protocol.dbcplan import DatabaseSpec


class GapStep(NamedTuple):
    """A gap of the encoder sequence: the wire counts (left, right) of the frames either side
    and the encoder periods between them (``gapbound.gap_allowance_of_counts``' input)."""

    before: tuple[int, int]
    after: tuple[int, int]
    periods: int


@dataclass
class _Rows:
    """The reference's rows from e0 not yet matched to a sample: encoder frame number g,
    increments, segment."""

    columns: dict[str, np.ndarray] = field(default_factory=dict)
    last_seq: int | None = None  # of the last encoder frame from e0
    segment: int = 0  # the last row's
    openings: list[tuple[int, bool]] = field(default_factory=list)  # per segment from 1: its
    # first encoder frame and whether a gap of the sequence opened it (else a stall's break)
    gap_steps: dict[int, GapStep] = field(default_factory=dict)  # per gap: its frame after
    last_counts: tuple[int, int] = (0, 0)  # of the last encoder frame from e0

    def add(self, g: npt.NDArray[np.int64], enc: Encoders,
            increments: dict[str, np.ndarray], breaks: npt.NDArray[np.int64]) -> None:
        if len(g) == 0:
            return
        seq = enc.seq
        prior = np.concatenate(([self.last_seq if self.last_seq is not None else seq[0]],
                                seq))
        gaps = np.diff(prior) > 1
        if self.last_seq is None:
            gaps[0] = False  # the start frame opens segment 0
        starts = gaps | np.isin(g, breaks)  # breaks after e0 only: e0 itself opens segment 0
        opened = np.flatnonzero(starts)
        self.openings += zip(g[opened].tolist(), gaps[opened].tolist(), strict=True)
        self._gap_steps(g, enc, prior, np.flatnonzero(gaps))
        segment = self.segment + np.cumsum(starts)
        new = {"g": g, "segment": segment, **increments}
        self.columns = ({k: np.concatenate((self.columns[k], v)) for k, v in new.items()}
                        if self.columns else new)
        self.last_seq, self.segment = int(seq[-1]), int(segment[-1])
        self.last_counts = (int(enc.left[-1]), int(enc.right[-1]))

    def _gap_steps(self, g: npt.NDArray[np.int64], enc: Encoders, prior: npt.NDArray[np.int64],
                   gaps: npt.NDArray[np.int64]) -> None:
        """Keep the counts either side of each gap and its periods (its allowance's input)."""
        for k in gaps.tolist():
            before = ((int(enc.left[k - 1]), int(enc.right[k - 1])) if k > 0
                      else self.last_counts)
            self.gap_steps[int(g[k])] = GapStep(before, (int(enc.left[k]), int(enc.right[k])),
                                                int(prior[k + 1] - prior[k]))

    def at(self, g: npt.NDArray[np.int64]) -> dict[str, np.ndarray]:
        """The rows of encoder frames ``g`` (sorted, all present)."""
        if len(g) == 0 or not self.columns:
            return {k: v[:0] for k, v in self.columns.items()}
        k = np.searchsorted(self.columns["g"], g)
        return {name: v[k] for name, v in self.columns.items()}

    def drop_below(self, g: int) -> None:
        """Forget the rows of encoder frames below ``g``."""
        if self.columns:
            k = int(np.searchsorted(self.columns["g"], g))
            self.columns = {name: v[k:] for name, v in self.columns.items()}


@dataclass
class LifeInfo:
    """What a pass over a life learns besides its chunks: the reference's refusals, the
    encoder frames a counter restart primed, the segments of every encoder frame from e0,
    and the times of the encoder frames asked for (``times_of``)."""

    refused: int = 0
    reprimed: list[int] = field(default_factory=list)
    by_uptime: list[int] = field(default_factory=list)  # of them, CTRL_UPTIME went back
    ambiguous: list[int] = field(default_factory=list)  # of those, an ambiguous step's
    segments: int = 0  # the last encoder frame's segment (reference_path's ``restarts``)
    openings: list[tuple[int, bool]] = field(default_factory=list)  # ``_Rows.openings``
    gap_steps: dict[int, GapStep] = field(default_factory=dict)  # ``_Rows.gap_steps``
    times_s: dict[int, float] = field(default_factory=dict)
    least: int | None = None  # the fewest periods of an ambiguous step (``nearthreshold``)


@dataclass(frozen=True)
class TruthChunk:
    """Truth samples (encoder frame, x, y, heading) with the reference's increments and
    segment at their encoder frames (those from e0 only), and the lowest encoder frame a
    truth sample still to come may name."""

    enc: npt.NDArray[np.int64]
    x_m: npt.NDArray[np.float64]
    y_m: npt.NDArray[np.float64]
    heading_rad: npt.NDArray[np.float64]
    rel_x_m: npt.NDArray[np.float64]
    rel_y_m: npt.NDArray[np.float64]
    rel_heading_rad: npt.NDArray[np.float64]
    segment: npt.NDArray[np.int64]
    floor: float


def life_chunks(
    chunks: Iterable[FrameArrays], db: DatabaseSpec, robot: RobotProfile,
    integrator: str, *, e0: int, breaks: npt.NDArray[np.int64],
    max_wheel_speed_mm_s: SpeedBound, info: LifeInfo | None = None,
    times_of: frozenset[int] = frozenset(),
    on_encoders: Callable[[Encoders], None] | None = None,
    left_out: tuple[tuple[int, int, int, int], ...] = (), tap: ReprimeTap | None = None,
) -> Iterator[tuple[PlacedChunk, TruthChunk]]:
    """``placed_chunks`` with the truth samples beside them (``stream_truth.StreamTruth``),
    each with the reference's rows at its encoder frame; ``info`` filled at the end;
    ``on_encoders``: told each chunk's accepted encoder frames; ``left_out``: the steps the
    declared stalls' re-primes left out (``stream.StreamReference.left_out``); ``tap``: shown
    each chunk and each placed chunk with the rows still held (``stream_reprime``)."""
    decoder = BulkDecoder(db)
    e2e, numbering = StreamE2E(db), StreamEncoders(decoder)
    poses, truth = StreamPoses(decoder), StreamTruth(decoder)  # one decoder: its cache too
    stalls: StreamStalls | None = None
    reference = StreamReference(Geometry.of(robot), integrator,
                                min(robot.counter_bits, WIRE_COUNTER_BITS), max_wheel_speed_mm_s,
                                left_out=left_out)
    rows, count, last_sample = _Rows(), 0, -1
    inside = breaks[breaks > e0]
    wanted = np.array(sorted(times_of), dtype=np.int64)
    info = info if info is not None else LifeInfo()
    for chunk in chunks:
        accepted = e2e.feed(chunk)
        enc = numbering.feed(chunk, accepted)
        if on_encoders is not None:
            on_encoders(enc)
        stalls = stalls or StreamStalls(enc.cycle_s, named_again=poses.named_again)
        g = count + np.arange(len(enc.index), dtype=np.int64)
        count += len(g)
        if tap is not None:
            tap.encoders(chunk, accepted, enc, g)
        asked = np.isin(g, wanted)
        info.times_s.update(zip(g[asked].tolist(), enc.timestamp_s[asked].tolist(), strict=True))
        from_e0 = g >= e0
        taken = _take(enc, from_e0)
        increments = reference.feed(taken)
        rows.add(g[from_e0], taken, increments, inside)
        samples, sent = poses.feed(chunk, accepted, enc)
        watermark = min(float(chunk.timestamp_s[-1]), poses.open_sent_s())
        pose_y = decoder.select(chunk, "ODOM_POSE_Y")
        pose_t = chunk.timestamp_s[pose_y[accepted[pose_y] | crc_holds(  # stalls.pose_sent_times
            chunk, decoder, pose_y, "ODOM_POSE_Y")]]
        placed = _placed(stalls.feed(samples, sent, enc.timestamp_s, watermark, pose_t), rows)
        told = _truth(truth.feed(chunk, accepted, enc)[0], rows, e0,
                      _truth_floor(truth, count - 1))
        if tap is not None:
            tap.placed(placed, rows.at)
        last_sample = int(placed.enc[-1]) if len(placed.enc) else last_sample
        rows.drop_below(int(min(last_sample, told.floor)))
        yield placed, told
    if stalls is None:
        return
    samples, sent = poses.finish()
    placed = _placed(stalls.feed(samples, sent, np.zeros(0), np.inf), rows)
    if tap is not None:
        tap.placed(placed, rows.at)
    yield placed, _truth(truth.finish()[0], rows, e0, np.inf)
    placed = _placed(stalls.finish(), rows)
    if tap is not None:
        tap.placed(placed, rows.at)
    yield placed, _truth(_no_truth(), rows, e0, np.inf)
    info.refused, info.segments, info.openings = reference.refused, rows.segment, rows.openings
    info.gap_steps = rows.gap_steps
    info.reprimed = [e0 + k for k in reference.reprimed]
    info.by_uptime = [e0 + k for k in reference.by_uptime]
    info.ambiguous = [e0 + k for k in reference.ambiguous]
    info.least = least_of(reference.geometry, reference.bits, reference.max_wheel_speed_mm_s)


def _truth_floor(truth: StreamTruth, top: int) -> float:
    """The lowest encoder frame a truth sample to come may name: one resolved and waiting
    for its other parts, or one named by a frame still to come (8 frames back from the latest
    encoder frame at most)."""
    waiting = [g for part in truth._first.values() for g in part]
    return float(min(min(waiting, default=top), top - 8))


def _no_truth() -> dict[str, np.ndarray]:
    return {"enc": np.zeros(0, dtype=np.int64), "x_m": np.zeros(0), "y_m": np.zeros(0),
            "heading_rad": np.zeros(0)}


def _truth(samples: dict[str, np.ndarray], rows: _Rows, e0: int, floor: float) -> TruthChunk:
    """The truth samples from e0 with their rows."""
    keep = samples["enc"] >= e0
    enc = samples["enc"][keep]
    at = rows.at(enc)
    empty = np.zeros(0)
    return TruthChunk(enc, samples["x_m"][keep], samples["y_m"][keep],
                      samples["heading_rad"][keep], at.get("x_m", empty), at.get("y_m", empty),
                      at.get("heading_rad", empty),
                      at.get("segment", np.zeros(0, dtype=np.int64)), floor)


def placed_chunks(
    chunks: Iterable[FrameArrays], db: DatabaseSpec, robot: RobotProfile,
    integrator: str, *, e0: int, breaks: npt.NDArray[np.int64],
    max_wheel_speed_mm_s: SpeedBound, info: LifeInfo | None = None,
) -> Iterator[PlacedChunk]:
    """The placement's input over one life's frames (module docstring); ``e0``: the encoder
    frame the reference starts at, ``breaks``: the stalls' (``StreamStalls.breaks`` of a first
    pass; only those after e0 start a segment)."""
    for placed, _ in life_chunks(chunks, db, robot, integrator, e0=e0, breaks=breaks,
                                 max_wheel_speed_mm_s=max_wheel_speed_mm_s, info=info):
        yield placed


def _take(enc: Encoders, keep: npt.NDArray[np.bool_]) -> Encoders:
    return Encoders(index=enc.index[keep], counter=enc.counter[keep], seq=enc.seq[keep],
                    left=enc.left[keep], right=enc.right[keep],
                    timestamp_s=enc.timestamp_s[keep], cycle_s=enc.cycle_s,
                    uptime=None if enc.uptime is None else enc.uptime[keep])


def _placed(samples: dict[str, np.ndarray], rows: _Rows) -> PlacedChunk:
    at = rows.at(samples["enc"])
    empty = np.zeros(0)
    return PlacedChunk(samples["x_m"], samples["y_m"], samples["heading_rad"],
                       samples["heading_raw"], at.get("x_m", empty), at.get("y_m", empty),
                       at.get("heading_rad", empty),
                       at.get("segment", np.zeros(0, dtype=np.int64)),
                       at.get("distance_m", empty), samples["enc"])
