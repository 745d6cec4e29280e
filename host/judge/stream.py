"""The first stages of the analysis over a log given chunk by chunk (``host.io.logs.iter_log``),
with their state carried across chunk boundaries, so that the result is the whole log's.

* ``StreamE2E``: AUTOSAR E2E Profile 2 (``host.protocol.e2e.check_frames``) a chunk at a time:
  the same counts and the same accepted frames as one check of the whole log. The state of one
  message is the tail of its frames from its last accepted one on (usually that one frame: the
  sequence check of a frame depends only on the frames of its ID since the last accepted one,
  and on the time since the previous frame of its ID); the tail is checked again in front of
  the next chunk and its own verdicts taken off (``counts(tail + chunk) - counts(tail)``);
  the silences, pairs of accepted frames, from each message's last accepted frame's time.
* ``StreamEncoders``: the accepted WHEEL_ENCODERS frames and their place in the sender's sequence
  (``host.judge.samples.encoder_frames``: the COUNTER unwrapped, widened by 16 where the
  timestamps say more periods passed), carried by the last accepted frame's COUNTER, time and
  sequence number: the integer sequence numbers are those of the whole log.

* ``StreamPoses``: the on-board samples (``host.judge.samples.onboard_samples``: ODOM_POSE_X and
  _Y naming one encoder frame, the first of each), carried by the last 16 encoder frames, each
  kind's last pose frame (a repeat of its ENC_COUNTER names what it named), and the halves not
  yet paired; a pose names only a frame before it, so it resolves in its own chunk (SIM_TRUTH,
  not causal: a part naming a frame the log has not reached yet waits), and a sample is given
  out once no later frame can name its encoder frame.

* ``StreamReference``: the steps as the firmware takes them (``reference_path.firmware_steps``:
  plausibility refusals, counter restarts) and their integration from pose 0 (``reference.
  integrate``), carried by the last accepted encoder frame (inside a refusal run, every frame
  since it) and the running sums: ``np.cumsum`` continued from the carried sum is the whole
  log's, bit for bit (adding the carried sum afterwards is not, and the test says so).

Positions (``index``) are positions in the whole log (frames before the chunk counted).

Beside it, each exact at any chunk size against the whole-log function (tests/test_stream*.py,
on a log cut at every frame and on a faulted rig run with a stall and a reboot):
``stream_lives.StreamLives`` (``reboots.split_lives``), ``stream_stalls.StreamStalls``
(``stalls.after_stalls``; with an ``exact`` flag for logs whose times go back),
``stream_truth.StreamTruth`` (``samples.truth_samples``), ``stream_twist.StreamTwist``
(``compare.check_twist``), ``stream_losses.StreamLosses`` and ``SpanDrops``
(``losses.firmware_losses`` and ``loss_allowance``), ``stream_facts.StreamFacts`` (frame
counts, covered seconds, the integrator, the power-up rule's inputs), ``stream_fit.SegmentSums``
and ``BlockDot`` (the rotation fit's segment means and its dot products,
``blockdot.block_dot``).

Chained (``stream_analysis.analyze_file``, what ``odocan analyze`` runs on one log): a pass
over the whole log for the lives (``StreamLives``, with the whole log's E2E) and the facts, then
per life, as a range of frames with E2E afresh: 1. E2E, encoders, samples after stalls, truth,
twist, facts -> the start frame e0 and the stalls' breaks; 2.-4. the start pose
(``stream_place.start_pose``: the heading overlap, the rotation fit's ``SegmentSums`` and
``BlockDot``), fed by ``stream_life.life_chunks`` (the samples with the reference's increments
from e0 and their segments); 5. the segment offsets; 6. the errors, the truth comparison
(``stream_compare.TruthCompare``), the distance and the events' times; ``reboots.merge``
takes the lives' reports without series. The plot and export series are not streamed (those
options read the whole log)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.aheadnamed import forward
from odocan.host.judge.reference import Geometry, SpeedBound
from odocan.host.judge.reference_path import firmware_steps
from odocan.host.judge.refusednames import refused_frames
from odocan.host.judge.resent import resent_differs
from odocan.host.judge.samples import (
    HEADING_LSB_RAD,
    POSITION_LSB_M,
    Encoders,
    _held,
    contract_cycle_s,
    match_encoder,
    named_targets,
)
from odocan.host.judge.step_periods import doubt_origin_s
from odocan.host.judge.stream_e2e import StreamE2E as StreamE2E  # re-exported (its old home)
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP as LAP
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder


@dataclass
class StreamEncoders:
    """The accepted WHEEL_ENCODERS frames of each chunk with their sequence numbers, as
    ``host.judge.samples.encoder_frames`` numbers them over the whole log."""

    decoder: BulkDecoder
    _offset: int = 0  # frames of the log before the next chunk
    _last: tuple[int, float, int] | None = None  # COUNTER, time s, seq of the last accepted

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> Encoders:
        """The chunk's accepted encoder frames (``index``: positions in the whole log)."""
        rows = self.decoder.decode(chunk, "WHEEL_ENCODERS")
        keep = accepted[rows["index"]]
        counter = rows["COUNTER"][keep].astype(np.int64)
        stamps = rows["timestamp_s"][keep]
        cycle_s = contract_cycle_s(self.decoder, "WHEEL_ENCODERS")
        seq = self._numbered(counter, stamps, cycle_s)
        encoders = Encoders(
            index=rows["index"][keep] + self._offset, counter=counter, seq=seq,
            left=rows["LEFT_COUNT"][keep].astype(np.int64),
            right=rows["RIGHT_COUNT"][keep].astype(np.int64),
            timestamp_s=stamps, cycle_s=cycle_s,
            uptime=rows["CTRL_UPTIME"][keep].astype(np.int64) if "CTRL_UPTIME" in rows else None,
        )
        self._offset += len(chunk)
        if len(counter):
            self._last = (int(counter[-1]), float(stamps[-1]), int(seq[-1]))
        return encoders

    def _numbered(
        self, counter: npt.NDArray[np.int64], stamps: npt.NDArray[np.float64],
        cycle_s: float | None,
    ) -> npt.NDArray[np.int64]:
        """Sequence numbers, continuing from the last accepted frame of the chunks before."""
        if len(counter) == 0:  # (numbering from 0 would give the empty chunk one number)
            return np.zeros(0, dtype=np.int64)
        if self._last is not None:
            counter = np.concatenate(([self._last[0]], counter))
            stamps = np.concatenate(([self._last[1]], stamps))
        step = (np.diff(counter) & ENC_COUNTER_MASK).astype(np.int64)
        if cycle_s is not None and len(step):
            laps = np.floor((np.diff(stamps) / cycle_s - step) / LAP + 0.5)  # as sender_seq
            step = step + LAP * np.maximum(0, laps).astype(np.int64)
        if self._last is None:
            return np.concatenate(([0], np.cumsum(step))).astype(np.int64)
        return (self._last[2] + np.cumsum(step)).astype(np.int64)


@dataclass
class _Halves:
    """Pose frames of one kind (ODOM_POSE_X or _Y) not yet resolved: global frame position,
    ENC_COUNTER, time, and the signal columns."""

    index: npt.NDArray[np.int64]
    enc_counter: npt.NDArray[np.int64]
    timestamp_s: npt.NDArray[np.float64]
    values: dict[str, np.ndarray]

    @classmethod
    def of(cls, rows: dict[str, np.ndarray], offset: int) -> _Halves:
        values = {k: v for k, v in rows.items() if k not in ("index", "timestamp_s")}
        return cls(rows["index"] + offset, rows["ENC_COUNTER"].astype(np.int64),
                   rows["timestamp_s"], values)

    def join(self, other: _Halves) -> _Halves:
        return _Halves(
            np.concatenate((self.index, other.index)),
            np.concatenate((self.enc_counter, other.enc_counter)),
            np.concatenate((self.timestamp_s, other.timestamp_s)),
            {k: np.concatenate((v, other.values[k])) for k, v in self.values.items()},
        )

    def take(self, keep: npt.NDArray[np.bool_]) -> _Halves:
        return _Halves(self.index[keep], self.enc_counter[keep], self.timestamp_s[keep],
                       {k: v[keep] for k, v in self.values.items()})


# encoder frames kept from the chunks before: ENC_COUNTER names -8..+7, and the one a lap
# before the frame named tells a flood (``samples.flooded_out``)
RECENT_ENCODERS = 32


def known_encoders(known: dict[str, np.ndarray], cycle_s: float | None) -> Encoders:
    """The carried and the chunk's encoder frames (``known``: g, index, counter, seq, t) as
    ``Encoders`` for ``samples.match_encoder`` (positions in ``known``; no counts)."""
    none = np.zeros(len(known["index"]), dtype=np.int64)
    return Encoders(index=known["index"], counter=known["counter"], seq=known["seq"],
                    left=none, right=none, timestamp_s=known["t"], cycle_s=cycle_s)


@dataclass
class StreamPoses:
    """The on-board samples of ``host.judge.samples.onboard_samples`` (ODOM_POSE_X and
    ODOM_POSE_Y naming one encoder frame, the first of each), chunk by chunk.

    A pose frame resolves against the latest accepted encoder frame before it (-8..+7 in the
    sequence) and names only a frame before it in the log (``samples.match_encoder``, causal),
    so it resolves in its own chunk; a frame repeating the ENC_COUNTER of its kind's previous
    one names what that one named (``samples._held``: carried across chunks by the last frame
    of each kind). The first frame naming an encoder frame wins. A sample is given out once no
    later frame can name its encoder frame (its sequence number more than 8 below the latest
    encoder frame's), in encoder order; ``enc`` counts the accepted encoder frames of the
    whole log.

    ``causal`` False (``stream_truth.StreamTruth``: the simulator names its own sample, whenever
    its encoder frame reaches the bus): a frame naming one the log has not reached yet waits
    for the next chunk, and so do the frames of its kind after it."""

    decoder: BulkDecoder
    unmatched: int = 0  # pose frames naming no accepted encoder frame of the log
    lone: int = 0  # halves given out without their partner (host.judge.lonehalves: judged whole)
    ahead: int = 0  # frames naming ahead of every one heard (host.judge.aheadnamed: judged whole)
    _offset: int = 0
    _enc_count: int = 0
    _recent: dict[str, np.ndarray] = field(default_factory=dict)  # g, index, counter, seq, t

    def unmatched_sent(self) -> int:
        """``lonehalves.unmatched_sent`` of a streamed log: a log with a lone half is read
        whole (``stream_first``), so here an unmatched half's partner is unmatched too (its
        pose's two, one pose) or lost (half up: one alone is one pose)."""
        return (self.unmatched + 1) // 2

    _pending: dict[str, _Halves] = field(default_factory=dict)  # (not causal) frames waiting
    _first: dict[str, dict[int, tuple[int, dict[str, float], float]]] = field(
        default_factory=lambda: {"ODOM_POSE_X": {}, "ODOM_POSE_Y": {}})
    # per kind, its last pose frame: ENC_COUNTER, COUNTER, time, encoder frame named (g), seq
    _last_row: dict[str, tuple[int, int, float, int, int]] = field(default_factory=dict)
    _given_below: float = -np.inf  # samples of sequence numbers below this are given out
    causal: bool = True  # a frame names only an encoder frame before it (held ones carried)
    resent: set[int] = field(default_factory=set)  # frames a differing resend names (resent.py)
    named_again: set[int] = field(default_factory=set)  # frames two of a kind named (a hold's)
    _last_pose: dict[str, tuple[int, dict[str, float]]] = field(default_factory=dict)

    def feed(
        self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_], enc: Encoders
    ) -> tuple[dict[str, np.ndarray], npt.NDArray[np.float64]]:
        """The samples that are final after this chunk (``enc`` its encoder frames from
        ``StreamEncoders``): columns enc, x_m, y_m, heading_rad, heading_raw, seq (the encoder
        frame's sequence number); and sent_s."""
        known = self._known(enc)
        floor = np.inf
        for name in self._first:
            rows = self._rows(chunk, name)
            keep = accepted[rows["index"]]
            new = _Halves.of({k: v[keep] for k, v in rows.items()}, self._offset)
            halves = self._pending[name].join(new) if name in self._pending else new
            floor = min(floor, self._resolve(name, halves, known, final=False))
        self._offset += len(chunk)
        self._enc_count += len(enc.index)
        self._recent = {k: v[-RECENT_ENCODERS:] for k, v in known.items()}
        return self._emit(floor)

    def _rows(self, chunk: FrameArrays, name: str) -> dict[str, np.ndarray]:
        """The chunk's decoded frames of one kind (with ENC_COUNTER)."""
        return self.decoder.decode(chunk, name)

    def open_sent_s(self, name: str = "ODOM_POSE_Y") -> float:
        """The earliest time of a ``name`` frame fed but not yet given out in a sample
        (waiting for its encoder frame or its partner); inf when none."""
        times = [t for _, _, t in self._first[name].values()]
        if name in self._pending and len(self._pending[name].timestamp_s):
            times.append(float(np.min(self._pending[name].timestamp_s)))
        return min(times, default=math.inf)

    def finish(self) -> tuple[dict[str, np.ndarray], npt.NDArray[np.float64]]:
        """The samples left at the end of the log."""
        known = self._recent
        for name, halves in list(self._pending.items()):
            self._resolve(name, halves, known, final=True)
        return self._emit(np.inf)

    def _known(self, enc: Encoders) -> dict[str, np.ndarray]:
        """The recent encoder frames and this chunk's: g (number in the log), index, counter,
        seq, timestamp_s."""
        now = {"g": self._enc_count + np.arange(len(enc.index), dtype=np.int64),
               "index": enc.index, "counter": enc.counter, "seq": enc.seq,
               "t": enc.timestamp_s}
        if not self._recent:
            return now
        return {k: np.concatenate((self._recent[k], v)) for k, v in now.items()}

    def _resolve(
        self, name: str, halves: _Halves, known: dict[str, np.ndarray], *, final: bool
    ) -> float:
        """Resolve what can be (causal, or ``final``: everything); keep the first frame naming
        each encoder frame not given out yet; returns the lowest sequence number a frame not
        resolved yet may name (inf when none waits)."""
        if len(known["seq"]) == 0:  # no encoder frame before any of them: none can match
            self.unmatched += len(halves.index)
            self._pending[name] = halves.take(np.zeros(len(halves.index), dtype=bool))
            return -np.inf if not final else np.inf  # (no sample either: nothing to give out)
        g, seq, latest, beyond = self._named(halves, known)
        top = int(known["seq"][-1])
        waits = beyond & (not final) & (not self.causal)
        cut = int(np.argmax(waits)) if waits.any() else len(halves.index)
        self._pending[name] = halves.take(np.arange(len(halves.index)) >= cut)
        g, seq = g[:cut], seq[:cut]
        cycle_s = contract_cycle_s(self.decoder, "WHEEL_ENCODERS")
        prev_t_s = self._last_row[name][2] if name in self._last_row else None
        if self.causal and cycle_s is not None and len(halves.index):
            g, seq = self._held(name, halves, g, seq, cycle_s)
            newest = known["seq"][np.maximum(latest[:cut], 0)]  # samples.lapped_out
            g = np.where((g >= 0) & (latest[:cut] >= 0) & (newest - seq >= LAP), -1, g)
        self.unmatched += int(np.count_nonzero(g < 0))
        if self.causal and cycle_s is not None:
            self.ahead += int(np.count_nonzero(forward(
                known_encoders(known, cycle_s), halves.index[:cut], halves.enc_counter[:cut],
                halves.timestamp_s[:cut], g, prev_t_s)))
        self._keep_first(name, halves, g, seq, known)
        if cut == len(halves.index):
            return float(top - 8) if not final else np.inf
        return float(min(known["seq"][np.maximum(latest[cut:], 0)].min(), top) - 8)

    def _keep_first(
        self, name: str, halves: _Halves, g: npt.NDArray[np.int64], seq: npt.NDArray[np.int64],
        known: dict[str, np.ndarray],
    ) -> None:
        """The first frame of ``halves`` naming each encoder frame not given out yet; and in
        ``resent`` the frame when a later one naming it differs from it, -1 when one naming
        what its kind's last frame named (given out) differs from that (``host.judge.resent``)."""
        firsts = self._first[name]
        hits = np.flatnonzero(g >= 0)
        columns = {k: v[hits].tolist() for k, v in halves.values.items()}  # plain Python values
        last = self._last_pose.get(name, (-1, {}))
        at = np.minimum(np.searchsorted(known["g"], g[hits] + 1), max(len(known["g"]) - 1, 0))
        came = ((known["g"][at] == g[hits] + 1) & (known["t"][at] <= halves.timestamp_s[hits])
                if len(known["g"]) else np.zeros(len(hits), dtype=bool)).tolist()
        for i, (gi, si, t) in enumerate(zip(g[hits].tolist(), seq[hits].tolist(),
                                            halves.timestamp_s[hits].tolist(), strict=True)):
            row = {k: v[i] for k, v in columns.items()}
            if (gi in firsts or last[0] == gi) and came[i]:  # stalls.named_again: after the
                # next frame came
                self.named_again.add(gi)
            if si >= self._given_below and gi not in firsts:
                firsts[gi] = (si, row, t)
            elif (gi in firsts or last[0] == gi) and resent_differs(
                    firsts[gi][1] if gi in firsts else last[1], row):
                self.resent.add(gi if gi in firsts else -1)
            last = (gi, row)
        self._last_pose[name] = last

    def _named(
        self, halves: _Halves, known: dict[str, np.ndarray]
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64],
               npt.NDArray[np.bool_]]:
        """The encoder frame each pose frame names: g (number in the log; -1 when none of the
        log's accepted frames, before it when causal) and its sequence number (-1 likewise);
        the latest encoder frame before each (position in ``known``); and which name a frame
        beyond the latest known one (not causal: they wait for the next chunk)."""
        enc = known_encoders(known, contract_cycle_s(self.decoder, "WHEEL_ENCODERS"))
        at = match_encoder(enc, halves.index, halves.enc_counter, halves.timestamp_s,
                           causal=self.causal)
        g = np.where(at >= 0, known["g"][np.maximum(at, 0)], -1).astype(np.int64)
        seq = np.where(at >= 0, known["seq"][np.maximum(at, 0)], -1).astype(np.int64)
        latest = np.searchsorted(known["index"], halves.index) - 1
        if self.causal:  # a frame named later in the log is not named: nothing waits
            return g, seq, latest, np.zeros(len(at), dtype=bool)
        has, target = named_targets(enc, halves.index, halves.enc_counter, halves.timestamp_s)
        return g, seq, latest, has & (target > known["seq"][-1])

    def _held(
        self, name: str, halves: _Halves, g: npt.NDArray[np.int64], seq: npt.NDArray[np.int64],
        cycle_s: float,
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """``samples._held`` across chunks: the kind's last frame carried in front."""
        counter = halves.values["COUNTER"].astype(np.int64)
        ec, own, t = halves.enc_counter, counter, halves.timestamp_s
        if name in self._last_row:
            e0, c0, t0, g0, s0 = self._last_row[name]
            ec, own, t = np.r_[e0, ec], np.r_[c0, own], np.r_[t0, t]
            g, seq = np.r_[g0, g], np.r_[s0, seq]
        run_start = _held(np.arange(len(g), dtype=np.int64), ec, own, t, cycle_s)
        g, seq = g[run_start], seq[run_start]
        self._last_row[name] = (int(ec[-1]), int(own[-1]), float(t[-1]), int(g[-1]),
                                int(seq[-1]))
        cut = len(g) - len(halves.index)
        return g[cut:], seq[cut:]

    def _emit(self, floor: float) -> tuple[dict[str, np.ndarray], npt.NDArray[np.float64]]:
        """The samples of encoder frames below sequence ``floor``, in encoder order; halves
        there that found no partner are dropped."""
        self._given_below = max(self._given_below, floor)
        xs, ys = self._first["ODOM_POSE_X"], self._first["ODOM_POSE_Y"]
        done = sorted(g for g in xs.keys() | ys.keys()
                      if (xs[g][0] if g in xs else ys[g][0]) < floor)
        both = [g for g in done if g in xs and g in ys]
        self.lone += len(done) - len(both)
        sx = [xs[g][1] for g in both]
        sy = [ys[g][1] for g in both]
        sent = np.array([ys[g][2] for g in both], dtype=np.float64)
        seq = np.array([ys[g][0] for g in both], dtype=np.int64)
        for g in done:
            xs.pop(g, None)
            ys.pop(g, None)
        heading_raw = np.array([s["HEADING"] for s in sx], dtype=np.int64)
        turns = np.array([s["TURNS"] for s in sy]).astype(np.float64)
        x = np.array([s["X"] for s in sx])
        y = np.array([s["Y"] for s in sy])
        samples = {
            "enc": np.array(both, dtype=np.int64),
            "x_m": x * POSITION_LSB_M,
            "y_m": y * POSITION_LSB_M,
            "heading_rad": turns * 2 * math.pi + heading_raw * HEADING_LSB_RAD,
            "heading_raw": heading_raw,
            "seq": seq,  # the encoder frame's sequence number
        }
        return samples, sent


@dataclass
class StreamReference:
    """The reference's increments from encoder frame 0 of the chunks fed (the steps as the
    firmware takes them, ``reference_path.firmware_steps``, integrated as
    ``reference.integrate`` from pose 0), chunk by chunk, element for element the whole log's.

    Carried: the last accepted encoder frame (and, inside a run of refused frames, every frame
    since it: the refusal state machine is run again from it, its earlier verdicts dropped), the
    integer count sums and the running float sums (``np.cumsum`` continued from the carried
    sum is the whole log's cumsum)."""

    geometry: Geometry
    integrator: str
    bits: int
    max_wheel_speed_mm_s: SpeedBound
    refused: int = 0
    reprimed: list[int] = field(default_factory=list)  # encoder frames a counter restart primed
    by_uptime: list[int] = field(default_factory=list)  # of them, CTRL_UPTIME went back
    ambiguous: list[int] = field(default_factory=list)  # of those, an ambiguous step's
    _window: dict[str, np.ndarray] = field(default_factory=dict)  # left, right, seq, g, t, uptime
    _sums: tuple[int, int, float, float, float, float] = (0, 0, 0.0, 0.0, 0.0, 0.0)
    _count: int = 0  # encoder frames fed
    _origin_s: float | None = None  # the carried frame's doubt origin (``doubt_origin_s``)
    left_out: tuple[tuple[int, int, int, int], ...] = ()  # re-primes' (f, r], late (stream_reprime)
    last_steps: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]] | None = None  # the
    # firmware's step into each frame of the last chunk fed (d_left, d_right; host.judge.distance)
    last_refused: npt.NDArray[np.bool_] | None = None  # its frames refused in a run (refusednames)

    def feed(self, enc: Encoders) -> dict[str, np.ndarray]:
        """The increments at this chunk's encoder frames: x_m, y_m, heading_rad, distance_m."""
        g = self._count + np.arange(len(enc.index), dtype=np.int64)
        first_chunk = self._count == 0
        self._count += len(enc.index)
        new: dict[str, npt.NDArray[Any]] = {
            "left": enc.left, "right": enc.right, "seq": enc.seq, "g": g, "t": enc.timestamp_s,
            "counter": enc.counter,
            "uptime": enc.uptime if enc.uptime is not None else np.zeros_like(g)}
        win = ({k: np.concatenate((self._window[k], v)) for k, v in new.items()}
               if self._window else new)
        carried = len(win["g"]) - len(g)
        if len(g) == 0:
            return {k: np.zeros(0) for k in ("x_m", "y_m", "heading_rad", "distance_m")}
        window = Encoders(index=win["g"], counter=win["counter"], seq=win["seq"],
                          left=win["left"], right=win["right"],
                          timestamp_s=win["t"], cycle_s=enc.cycle_s, uptime=win["uptime"])
        steps = firmware_steps(window, 0, self.geometry, self.bits, self.max_wheel_speed_mm_s,
                               first_origin_s=self._origin_s)
        self.refused += steps.refused - max(0, carried - 1)  # carried refusals counted before
        self.reprimed += [int(win["g"][k]) for k in steps.reprimed]  # decided in this window
        self.by_uptime += [int(win["g"][k]) for k in steps.by_uptime]
        self.ambiguous += [int(win["g"][k]) for k in steps.ambiguous]  # (``ambiguity``)
        skip = max(carried, 1) - 1  # step k leads into window frame k + 1
        out = self._integrate(*self._held(win["g"][skip + 1:], steps.d_left[skip:],
                                          steps.d_right[skip:]))
        last = steps.open_from if steps.open_from is not None else len(win["g"]) - 1
        self._window = {k: v[last:] for k, v in win.items()}
        self._origin_s = None if enc.cycle_s is None else doubt_origin_s(
            win["t"], enc.cycle_s, last, steps.taken_before, self._origin_s)
        first = np.zeros(1 if first_chunk else 0, dtype=np.int64)  # no step into frame 0
        self.last_steps = (np.concatenate((first, steps.d_left[skip:])),
                           np.concatenate((first, steps.d_right[skip:])))
        self.last_refused = refused_frames(steps, len(win["g"]))[carried:]
        if first_chunk:  # the very first frame: pose 0 before any step
            out = {k: np.concatenate(([0.0], v)) for k, v in out.items()}
        return out

    def _held(self, into: npt.NDArray[np.int64], d_left: npt.NDArray[np.int64],
              d_right: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64], ...]:
        """The steps into frames ``into`` with those a declared stall's re-prime left out
        zeroed (``left_out``: frames (f, r], ``stallreprime.left_out``), the reference's only."""
        held = np.zeros(len(into), dtype=np.bool_)
        for f, r, _, _ in self.left_out:
            held |= (into > f) & (into <= r)
        if not held.any():
            return d_left, d_right
        d_left, d_right = np.where(held, 0, d_left), np.where(held, 0, d_right)
        for f, _, late_left, late_right in self.left_out:  # a late frame's step (fifolate)
            d_left, d_right = (np.where(into == f + 1, late_left, d_left),
                               np.where(into == f + 1, late_right, d_right))
        return d_left, d_right

    def _integrate(
        self, d_left: npt.NDArray[np.int64], d_right: npt.NDArray[np.int64]
    ) -> dict[str, np.ndarray]:
        """``reference.integrate`` from pose 0, continued from the carried sums."""
        g = self.geometry
        cum_l0, cum_r0, h_old0, sx0, sy0, dist0 = self._sums
        ds_left = d_left * g.m_per_count_left
        ds = 0.5 * (ds_left + d_right * g.m_per_count_right)
        cum_left = np.cumsum(np.concatenate(([cum_l0], d_left)))[1:]
        cum_right = np.cumsum(np.concatenate(([cum_r0], d_right)))[1:]
        heading = (0.0 + (g.m_per_count_right / g.wheelbase_m) * cum_right
                   - (g.m_per_count_left / g.wheelbase_m) * cum_left)
        heading_old = np.concatenate(([h_old0], heading[:-1]))
        if self.integrator == "euler":
            direction = heading
        else:
            direction = 0.5 * (heading_old + heading)
            if self.integrator == "exact":
                ds = ds * np.sinc((heading - heading_old) / (2.0 * math.pi))
        sx = np.cumsum(np.concatenate(([sx0], ds * np.cos(direction))))[1:]
        sy = np.cumsum(np.concatenate(([sy0], ds * np.sin(direction))))[1:]
        dist = np.cumsum(np.concatenate(([dist0], np.abs(0.5 * (ds_left + d_right
                                                               * g.m_per_count_right)))))[1:]
        if len(heading):
            self._sums = (int(cum_left[-1]), int(cum_right[-1]), float(heading[-1]),
                          float(sx[-1]), float(sy[-1]), float(dist[-1]))
        return {"x_m": 0.0 + sx, "y_m": 0.0 + sy, "heading_rad": heading, "distance_m": dist}
