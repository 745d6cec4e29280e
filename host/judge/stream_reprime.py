"""A stall the firmware declared it re-primed after, judged by the streamed judge as the whole
log's judge does it (issue #11/#13; ``host.judge.stallreprime``), in bounded memory.

The whole log's judge chooses each declared stall's pair (f, r) (``stallreprime.stall_reprimes``)
from the reference's path before any re-prime's steps are left out, at a handful of frames
only: the last sample before the stall's break b (its anchor), the frames b - 1 .. the first
kept sample at or after b (``first``: f and r lie there), and the ``COMPARED`` samples from
``first`` on. Then it leaves the steps into f + 1 .. r out of the reference (``left_out``), bounds
the stall's placement by the merge allowance of the frames b - 1 .. f only, drops the stall's
loss placement (``losses.life_placements``) and reports the event at frame r.

Before, the streamed judge refused every life with such a stall (judged whole, the
whole log in memory: a firmware hang on an hour's CI drive took the CLI to the whole log's
300+ MB). Now ``ReprimeTap`` rides one extra pass over the life (``stream_life.life_chunks``,
only when the firmware's summaries hold such a word: ``stallreprime.any_declared``) and keeps,
per stall break, that window: the rows of the reference's increments (the stream's, element for
element the whole log's), the samples' values, the encoder counts b - 1 .. b - 1 + FIFO_SPAN
(the placement's allowance, ``breakspan.break_allowance`` on them) and the break's bus time
(``stallreprime.declared_at``), and the refused CRC-right encoder frames after b - 1 ..
b - 1 + FIFO_SPAN (``fifolate``). ``_chosen`` then runs on exactly the whole judge's numbers.
The placing passes after it integrate with those steps left out
(``stream.StreamReference.left_out``).

Still refused (``NotStreamable``): a declared stall before the life's first count page (its
ENC_E2E_LOST may pin the pair: ``reprimecount.power_up_lost`` reads the log whole there)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.breakspan import break_allowance
from odocan.host.judge.fifolate import Judged, LateStep, after_frames, late_step
from odocan.host.judge.nearthreshold import Resets
from odocan.host.judge.reference import Geometry
from odocan.host.judge.refusedenc import Refused, refused_encoders
from odocan.host.judge.samples import ENC_E2E_PAGE, Encoders
from odocan.host.judge.stallreprime import (
    COMPARED,
    FIFO_SPAN,
    Pair,
    Reprime,
    _chosen,
    any_declared,
    declared_at,
)
from odocan.host.judge.stream_place import PlacedChunk
from odocan.host.judge.stream_refusal import NotStreamable
from odocan.host.protocol.decode import BulkDecoder, DecodeError

BEFORE_PAGE = ("a stall the firmware declared it re-primed after, before its first count page "
               "(its ENC_E2E_LOST may pin the re-prime: reprimecount)")
Rows = Callable[[npt.NDArray[np.int64]], dict[str, np.ndarray]]
Sample = tuple[int, float, float, float, float, float, float]  # enc, x, y, h, rel x, y, h


@dataclass
class _Window:
    """What one stall's break ``b`` (an encoder frame of the life) needs (module docstring)."""

    b: int
    b_s: float | None = None
    anchor: Sample | None = None  # the last kept sample before b
    first: int | None = None  # the first kept sample's encoder frame at or after b
    rows: dict[str, np.ndarray] = field(default_factory=dict)  # frames b - 1 .. first
    after: list[Sample] = field(default_factory=list)  # the first COMPARED samples from b
    counts: dict[str, list[int]] = field(
        default_factory=lambda: {"seq": [], "left": [], "right": []})  # b - 1 .. + FIFO_SPAN
    late: list[tuple[int, int, int]] = field(default_factory=list)  # refused after those: k, L, R


@dataclass
class StallReprimes:
    """The declared stalls' re-primes of a life (keys: breaks from e0, as
    ``Reference.stall_reprimes``) and each one's placement allowance (by absolute break)."""

    reprimes: dict[int, Reprime] = field(default_factory=dict)
    allowance_m: dict[int, float] = field(default_factory=dict)

    @property
    def left_out(self) -> tuple[tuple[int, int, int, int], ...]:
        """The steps left out: into the frames (f, r] from e0 (``stallreprime.left_out``), and
        the late frame's step into f + 1 (``fifolate``)."""
        return tuple((rep.f, rep.r, *rep.late) for _, rep in sorted(self.reprimes.items()))


class ReprimeTap:
    """Rides a ``life_chunks`` pass over a life: keeps each break's window (module docstring)
    and where the life's first accepted count page lies (in encoder frames before it)."""

    def __init__(self, decoder: BulkDecoder, breaks: list[int]) -> None:
        self.decoder = decoder
        self.windows = [_Window(b) for b in breaks]
        self.page_at: int | None = None  # encoder frames before the first accepted count page
        self.cycle_s: float | None = None  # the encoder frames' (the DBC's)
        self._frames = self._encoders = 0  # the life's frames and encoder frames fed

    def encoders(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_], enc: Encoders,
                 g: npt.NDArray[np.int64]) -> None:
        """A chunk, its E2E verdicts and accepted encoder frames (``g``: their numbers)."""
        self.cycle_s = enc.cycle_s
        g0 = int(g[0]) if len(g) else 0  # the numbers run on: g0, g0 + 1, ...
        refused: tuple[Refused, npt.NDArray[np.int64]] | None = None
        for w in self.windows:
            if w.b - 1 + FIFO_SPAN < g0 or w.b - 1 >= g0 + len(g):
                continue
            if refused is None:  # the late frames a resumed firmware may take (fifolate)
                late = refused_encoders(chunk, accepted, self.decoder)
                refused = late, g0 + after_frames(late, enc.timestamp_s)
            w.late += [(int(k), int(left), int(right)) for k, left, right in zip(
                *refused[1:], refused[0].left, refused[0].right, strict=True)
                if w.b - 1 <= k <= w.b - 1 + FIFO_SPAN]
            if 0 <= w.b - g0 < len(g):
                w.b_s = float(enc.timestamp_s[w.b - g0])
            for k in range(max(w.b - 1 - g0, 0), min(w.b + FIFO_SPAN - g0, len(g))):
                for name, values in (("seq", enc.seq), ("left", enc.left),
                                     ("right", enc.right)):
                    w.counts[name].append(int(values[k]))
        if self.page_at is None:
            self._page(chunk, accepted, enc)
        self._frames += len(chunk)
        self._encoders += len(g)

    def _page(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_], enc: Encoders) -> None:
        try:
            page = self.decoder.decode_page(chunk, "ODOM_STATUS", ENC_E2E_PAGE)
        except DecodeError:
            return
        if "ENC_E2E_LOST" not in page:
            return
        keep = accepted[page["index"]]
        if keep.any():
            at = int(page["index"][keep][0]) + self._frames
            self.page_at = self._encoders + int(np.searchsorted(enc.index, at))

    def placed(self, chunk: PlacedChunk, rows: Rows) -> None:
        """Kept samples in encoder order, the reference's rows still held (all from the last
        sample given out before them on)."""
        if len(chunk.enc) == 0:
            return
        for w in self.windows:
            if len(w.after) == COMPARED:
                continue
            before = np.flatnonzero(chunk.enc < w.b)
            if len(before) and w.first is None:
                w.anchor = _sample(chunk, int(before[-1]))
            later = np.flatnonzero(chunk.enc >= w.b)
            if len(later) and w.first is None:
                w.first = int(chunk.enc[later[0]])
                w.rows = rows(np.arange(w.b - 1, w.first + 1, dtype=np.int64))
            w.after += [_sample(chunk, k) for k in later[: COMPARED - len(w.after)].tolist()]

    def chosen(self, e0: int, resets: Resets, least: int | None,
               start: tuple[float, float, float] | None, geometry: Geometry, bits: int,
               integrator: str) -> StallReprimes:
        """``stallreprime.stall_reprimes`` of the windows kept (``start``: the exact start at
        e0, None when fitted), with each one's placement allowance."""
        out = StallReprimes()
        if self.cycle_s is None:
            return out
        declared = declared_at({w.b: w.b_s for w in self.windows if w.b > e0
                                and w.b_s is not None}, self.cycle_s, e0, resets, least)
        if self.page_at is not None and any(0 < b + e0 < self.page_at for b in declared):
            raise NotStreamable(BEFORE_PAGE)
        by_break = {w.b: w for w in self.windows}
        for b, (stall_s, sure) in sorted(declared.items()):
            pair = _pair(by_break[b + e0], e0, start, Judged(geometry, integrator, bits),
                         unsure=not sure)
            if pair is None:
                continue
            out.reprimes[b] = Reprime(pair[0] - e0, pair[1] - e0, stall_s, sure, pair[2])
            out.allowance_m[b + e0] = _allowance(by_break[b + e0], pair[0], geometry, bits,
                                                 integrator)
        return out


def stream_reprimes(pass_with: Callable[[ReprimeTap], None], decoder: BulkDecoder,
                    breaks: list[int], e0: int, resets: Resets, least: int | None,
                    start: tuple[float, float, float] | None,
                    judged: tuple[Geometry, int, str]) -> StallReprimes:
    """The life's declared stalls' re-primes (module docstring) from one pass
    (``pass_with``: runs ``stream_life.life_chunks`` over the life with the tap, nothing left
    out) when any of its ``breaks`` after ``e0`` may be one (``resets``: the firmware's
    summaries, ``stallreprime.any_declared``); ``judged``: geometry, counter bits, integrator."""
    if not any(b > e0 for b in breaks) or not any_declared(resets, resets.cycle_s, least):
        return StallReprimes()
    tap = ReprimeTap(decoder, [b for b in breaks if b > e0])
    pass_with(tap)
    return tap.chosen(e0, resets, least, start, *judged)


def _sample(chunk: PlacedChunk, k: int) -> Sample:
    return (int(chunk.enc[k]), float(chunk.x_m[k]), float(chunk.y_m[k]),
            float(chunk.heading_rad[k]), float(chunk.rel_x_m[k]), float(chunk.rel_y_m[k]),
            float(chunk.rel_heading_rad[k]))


def _pair(w: _Window, e0: int, start: tuple[float, float, float] | None, judged: Judged, *,
          unsure: bool = False) -> Pair | None:
    """``stallreprime._chosen`` on the window (absolute frames): its frames laid out as
    one short path (the anchor, frames b - 1 .. first, the samples after), positions for
    frames (the pair's ranges lie in b - 1 .. first, contiguous there)."""
    if w.first is None or not w.after:
        return None
    if w.anchor is not None:
        anchor = w.anchor
    elif start is not None:
        anchor = (e0, *start, 0.0, 0.0, 0.0)  # the reference's pose 0 at e0
    else:
        return None
    frames = [anchor[0], *range(w.b - 1, w.first + 1), *(s[0] for s in w.after)]
    rel = [[anchor[4]], [anchor[5]], [anchor[6]]]
    for axis, name in enumerate(("x_m", "y_m", "heading_rad")):
        rel[axis] += w.rows[name].tolist() + [s[4 + axis] for s in w.after]
    layout = sorted(set(frames))
    values = {f: (x, y, h) for f, x, y, h in zip(frames, *rel, strict=True)}
    position = {f: k for k, f in enumerate(layout)}
    rx, ry, rh = (np.array([values[f][axis] for f in layout]) for axis in range(3))
    shift = position[w.b] - w.b
    samples = (np.array([position[s[0]] for s in w.after], dtype=np.int64),
               np.array([s[1] for s in w.after]), np.array([s[2] for s in w.after]),
               np.array([s[3] for s in w.after]))
    pair = _chosen(position[w.b], position[w.first], (position[anchor[0]], *anchor[1:4]),
                   (rx, ry, rh), samples, unsure=unsure, late=_late(w, position, judged))
    return None if pair is None else (pair[0] - shift, pair[1] - shift, pair[2])


def _late(w: _Window, position: dict[int, int], judged: Judged) -> list[LateStep]:
    """The window's late frames' steps (``fifolate``), their ``k`` laid out as ``_pair``'s."""
    counts = w.counts
    return [late_step(position[k], (left, right), (counts["left"][k - w.b + 1],
                                                   counts["right"][k - w.b + 1]), judged)
            for k, left, right in w.late
            if k in position and k - w.b + 1 < len(counts["left"])]


def _allowance(w: _Window, f: int, geometry: Geometry, bits: int, integrator: str) -> float:
    """``breakspan.break_allowance(enc, b, [f], ...)`` on the counts kept from b - 1 (the
    whole log's judge's bound of a re-primed stall's placement: ``reference_path``)."""
    seq, left, right = (np.array(w.counts[k], dtype=np.int64) for k in ("seq", "left", "right"))
    enc = Encoders(index=np.arange(len(seq), dtype=np.int64), counter=seq % 16, seq=seq,
                   left=left, right=right, timestamp_s=np.zeros(len(seq)), cycle_s=None)
    return break_allowance(enc, 1, np.array([f - (w.b - 1)], dtype=np.int64), geometry, bits,
                           integrator)
