"""Live alignment of what a robot's bus says: the on-board pose against a float64 reference and
the ground truth, each paired at the very encoder frame it names (ENC_COUNTER), never by time.

Used by ``odocan monitor`` and the MQTT bridge. The offline, bulk version is
``host.judge.analysis``; the live judge resolves the encoder frame a pose half names with the
very same functions (``host.judge.samples.match_encoder``, with its held and queued rules, and
``sender_seq``) applied to a window of the latest frames (``HALF_WINDOW`` halves, ``ENC_WINDOW``
encoder frames). A half is settled once bus time is half an encoder cycle past it or the next
half of its message is heard: only then is it known whether it came out in a burst
(``samples.queued_frames``), so a sample is judged at most half a cycle after its ODOM_POSE_Y
(``take_samples``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from odocan.firmware.ecu import ENCODER_PERIOD_US, MAX_WHEEL_SPEED_MM_S, RESYNC_FRAMES
from odocan.host.judge.losses import drop_errors_of, lost_beyond_gaps, worst_losses_m
from odocan.host.judge.reference import Geometry, ReferenceOdometry, wrap_delta
from odocan.host.judge.samples import (
    QUEUED_GAP_CYCLES,
    SILENCE_CYCLES,
    Encoders,
    FloatArray,
    match_encoder,
    queued_frames,
    sender_seq,
)
from odocan.host.protocol.pose import heading_fields, unwrap_near
from odocan.sim import contract
from odocan.sim.pose import TURN_RAD, wrap_angle

WIRE_COUNTER_BITS = 24  # LEFT_COUNT / RIGHT_COUNT carry the low 24 bits
_RING = 16  # one slot per E2E COUNTER value of WHEEL_ENCODERS
SILENCE_FRAMES = SILENCE_CYCLES  # encoder cycles without a pose: the firmware was stalled
BACKLOG_FRAMES = 6_000  # encoder frames kept while waiting for the integrator (60 s at 100 Hz)
BOOT_COUNT_WAIT_S = 1.0  # after a reboot, how long the count page is waited for (s of bus time)
HALF_WINDOW = 256  # pose halves of each message kept to resolve the frame one names (5 s)
ENC_WINDOW = 512  # encoder frames kept for it, and the reference at each (5 s at 100 Hz)
CYCLE_S = float(contract.message("WHEEL_ENCODERS").cycle_time or 10) / 1000.0  # DBC cycle
_TURN = 2.0 * math.pi
_RECENT = 32  # latest rows of a window kept as tuples for the fast path (``_named_plain``)
_QUEUED_GAP_S = QUEUED_GAP_CYCLES * CYCLE_S  # closer sends of one message waited (queued)
_REPEAT_S = SILENCE_CYCLES * CYCLE_S  # a repeated ENC_COUNTER closer than this is held


def _named_plain(halves: deque[tuple[float, ...]], columns: _Columns, pos: int) -> int | None:
    """``PoseTracker._named`` for the common half, without numpy: the encoder frame (seq) the
    half at ``pos`` names, -1 when none; None when ``samples.match_encoder``'s held or queued
    rule may apply (``_plain_half``). Else its plain rule alone decides, computed here as it
    computes it on the window: the latest encoder frame before the half (less than 8 cycles
    older), the offset of ENC_COUNTER from its COUNTER, and the frame that many sender steps
    (``samples.sender_seq``, pair by pair) back; None too when that reaches back beyond the
    window's rows kept as tuples. ``columns.rows``: seq, pos, COUNTER, bus time s, ..."""
    half = _plain_half(halves, pos)
    if half is None:
        return None
    enc_counter, t_s = half
    window = columns.rows
    n = len(window)
    latest = -1  # negative index into ``window``: the latest frame before the half
    while latest >= -n and window[latest][1] >= pos:
        latest -= 1
    if latest < -n:
        return -1 if columns.whole else None
    if t_s - window[latest][3] >= 8 * CYCLE_S:
        return -1
    offset = ((int(enc_counter - window[latest][2]) + 8) & 0xF) - 8
    if offset > 0:
        return -1  # not on the bus before the half
    # the first frame whose seq >= seq[latest] + offset (searchsorted): walk back from latest
    # while the one before still is; ``back``: seq[latest] - seq[j]
    j, back = latest, 0
    while j > -n:
        step = _sender_step(window, j)
        if back + step > -offset:
            break
        back += step
        j -= 1
    else:
        if not columns.whole:
            return None  # the walk may go on before the rows kept: let match_encoder judge
    return int(window[j][0]) if back == -offset else -1


def _plain_half(halves: deque[tuple[float, ...]], pos: int) -> tuple[float, float] | None:
    """ENC_COUNTER and bus time (s) of the half at ``pos`` (one of the last two ``halves`` rows:
    pos, ENC_COUNTER, COUNTER, bus time s); None when it is not there or when it is less than
    ``QUEUED_GAP_CYCLES`` from a neighbour (queued) or repeats its predecessor's ENC_COUNTER
    with own COUNTER + 1 within ``SILENCE_CYCLES`` (held)."""
    n_halves = len(halves)
    if n_halves and halves[-1][0] == pos:
        k = -1
    elif n_halves > 1 and halves[-2][0] == pos:
        k = -2
        if halves[-1][3] - halves[-2][3] < _QUEUED_GAP_S:
            return None
    else:
        return None
    _, enc_counter, counter, t_s = halves[k]
    if n_halves > -k:
        _, prev_enc, prev_counter, prev_t = halves[k - 1]
        if t_s - prev_t < _QUEUED_GAP_S:
            return None
        if (prev_enc == enc_counter and (int(counter - prev_counter) & 0xF) == 1
                and t_s - prev_t < _REPEAT_S):
            return None
    return enc_counter, t_s


def _sender_step(window: deque[tuple[float, ...]], j: int) -> int:
    """``samples.sender_seq``'s step from frame ``j - 1`` to frame ``j`` (negative indices into
    the window, ``j`` > -len): COUNTER step mod 16, widened by 16 per 16 periods more the bus
    times show unless frame ``j`` queued (less than ``QUEUED_GAP_CYCLES`` from a neighbour)."""
    _, _, counter, t_s = window[j][:4]
    _, _, prev_counter, prev_t = window[j - 1][:4]
    step = int(counter - prev_counter) & 0xF
    dt = t_s - prev_t
    if dt < _QUEUED_GAP_S or (j < -1 and window[j + 1][3] - t_s < _QUEUED_GAP_S):
        return step
    periods = round(dt / CYCLE_S)
    return step + 16 * max(0, round((periods - step) / 16))


class _Columns:
    """The latest ``size`` rows of a few numeric columns, as numpy views (``col``, amortised
    O(1) append: rows are copied in ``_RECENT`` at a time, or when a view is asked for), and
    the latest ``_RECENT`` of them as plain tuples (``rows``, a ring buffer for the fast path;
    ``whole``: they are the whole window): the live judge's window of recent frames."""

    def __init__(self, names: tuple[str, ...], size: int) -> None:
        self.size = size
        self._col = {name: i for i, name in enumerate(names)}
        self._data = np.zeros((2 * size, len(names)))
        self._n = 0  # rows in ``_data``
        self._count = 0  # rows appended in all
        self._unflushed: list[tuple[float, ...]] = []  # rows appended, not in ``_data`` yet
        self.rows: deque[tuple[float, ...]] = deque(maxlen=_RECENT)

    def append(self, *row: float) -> None:
        self.rows.append(row)
        self._count += 1
        self._unflushed.append(row)
        if len(self._unflushed) >= _RECENT:  # copied in a batch: the state stays small
            self._flush()

    @property
    def whole(self) -> bool:
        """``rows`` holds every row of the window (its first is the window's first)."""
        return self._count <= _RECENT

    def _flush(self) -> None:
        rows, self._unflushed = self._unflushed[-self.size :], []
        m = len(rows)
        if self._n + m > len(self._data):  # keep the latest ``size`` rows, at the front
            keep = min(self._n, self.size - m)
            self._data[:keep] = self._data[self._n - keep : self._n]
            self._n = keep
        self._data[self._n : self._n + m] = rows
        self._n += m

    def col(self, name: str) -> FloatArray:
        if self._unflushed:
            self._flush()
        column: FloatArray = self._data[max(0, self._n - self.size) : self._n, self._col[name]]
        return column

    def __len__(self) -> int:
        return min(self._count, self.size)


@dataclass(slots=True)
class _Half:
    """A pose half heard: its place among the frames fed (``pos``), ENC_COUNTER, its own E2E
    COUNTER, bus time (s) and values (X: X m, HEADING rad; Y: Y m, TURNS)."""

    pos: int
    enc_counter: int
    counter: int
    t_s: float
    value: float
    extra: float


class Sample(NamedTuple):
    """An on-board sample settled: the pose, the reference at its encoder frame (None when
    unknown), the ENC_COUNTER it names, its ODOM_POSE_X's COUNTER and its ODOM_POSE_Y's bus
    time (s)."""

    pose: FramePose
    reference: FramePose | None
    enc_counter: int
    counter: int
    t_s: float


class StepGate:
    """The firmware's plausibility rule on the reference's steps (firmware/ecu.py, the same as
    ``host.judge.analysis``): a frame beyond ``MAX_WHEEL_SPEED_MM_S`` over the periods its COUNTER
    advanced since the last accepted one is refused; ``RESYNC_FRAMES`` refused frames plausible
    among themselves are a counter restart: one step from the first of them, never the jump."""

    def __init__(self, geometry: Geometry, counter_bits: int) -> None:
        travel_m = MAX_WHEEL_SPEED_MM_S * 1e-3 * ENCODER_PERIOD_US * 1e-6
        self.bound = (math.ceil(travel_m / geometry.m_per_count_left) + 1,
                      math.ceil(travel_m / geometry.m_per_count_right) + 1)
        self.bits = counter_bits
        self.prev: tuple[int, int, int] | None = None  # counter, left, right of the last accepted
        self._refused: list[tuple[int, int, int]] = []
        self.counter_restarts = 0

    def _delta(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> tuple[int, int]:
        return wrap_delta(b[1] - a[1], self.bits), wrap_delta(b[2] - a[2], self.bits)

    def _plausible(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> bool:
        periods = ((b[0] - a[0]) % _RING) or _RING
        d = self._delta(a, b)
        return abs(d[0]) <= periods * self.bound[0] and abs(d[1]) <= periods * self.bound[1]

    def step(self, counter: int, left: int, right: int) -> tuple[int, int] | None:
        """The count step to integrate for this frame; None when it primes or is refused."""
        frame = (counter, left, right)
        prev, self.prev = self.prev, frame
        if prev is None:
            return None
        if self._plausible(prev, frame):
            self._refused = []
            return self._delta(prev, frame)
        self.prev = prev  # refused: the base stays
        consistent = bool(self._refused) and self._plausible(self._refused[-1], frame)
        self._refused = [*self._refused, frame] if consistent else [frame]
        if len(self._refused) < RESYNC_FRAMES:
            return None
        first, self._refused, self.prev = self._refused[0], [], frame
        self.counter_restarts += 1
        return self._delta(first, frame)


def difference(a: FramePose, b: FramePose) -> dict[str, float]:
    """a - b: position (m), distance (m) and heading wrapped to (-pi, pi] (rad)."""
    dx, dy = a.x_m - b.x_m, a.y_m - b.y_m
    return {"dx_m": dx, "dy_m": dy, "dpos_m": math.hypot(dx, dy),
            "dheading_rad": wrap_angle(a.heading_rad - b.heading_rad)}


class FramePose(NamedTuple):
    """A pose at one encoder frame (``seq``: the how-many-th encoder frame the monitor heard,
    -1 when unknown); ``heading_rad`` is cumulative (unwrapped), ``pose_dict`` names both forms.
    A plain ``sim.pose.FramePose`` with the frame it is of: on-board, reference and truth samples
    are paired by ``seq``, never by time."""

    seq: int
    x_m: float
    y_m: float
    heading_rad: float


@dataclass
class ErrorStats:
    """A - B for a stream of pose pairs: the latest difference and the largest so far."""

    samples: int = 0
    latest: dict[str, float] = field(default_factory=dict)
    max_dpos_m: float = 0.0
    max_dheading_rad: float = 0.0

    def add(self, a: FramePose, b: FramePose) -> None:
        """Record ``a - b`` (position in m, heading wrapped to (-pi, pi] in rad)."""
        self.latest = difference(a, b)
        self.samples += 1
        self.max_dpos_m = max(self.max_dpos_m, self.latest["dpos_m"])
        self.max_dheading_rad = max(self.max_dheading_rad, abs(self.latest["dheading_rad"]))

    def as_dict(self) -> dict[str, Any] | None:
        """JSON form; None before the first sample."""
        if not self.samples:
            return None
        return {**self.latest, "max_dpos_m": self.max_dpos_m,
                "max_dheading_rad": self.max_dheading_rad, "samples": self.samples}


class PoseTracker:
    """On-board pose vs the float64 reference (aligned by ENC_COUNTER) and vs SIM_TRUTH.

    Each pose half names the encoder frame it was made after, resolved as ``analyze`` resolves it
    (module docstring: the same functions on a window of recent frames, a half settled half a
    cycle after it is heard); an ODOM_POSE_X and an ODOM_POSE_Y naming one encoder frame make one
    on-board sample (the first of each, as ``host.judge.samples.onboard_samples``).

    The reference starts at the first on-board pose heard, primed with the counts of the
    encoder frame that pose names and stepped with every accepted WHEEL_ENCODERS frame after it.
    When the integrator is not known yet (``integrator`` None: the one ODOM_STATUS reports), the
    poses and encoder frames heard meanwhile are kept (up to ``BACKLOG_FRAMES``) and compared
    once it is, so the monitor (which waits for ODOM_STATUS) and the bridge (told the integrator)
    start at the same pose and judge the same samples as ``analyze``. The reference starts again
    when ODOM_STATUS reports another integrator. At power-up the first pose is exactly (0, 0, 0),
    the start ``analyze`` uses; mid-drive the start inherits the pose signals' rounding (0.1 mm,
    2 pi/65536 rad; ``analyze`` fits it instead), so the difference stays within about one LSB.
    """

    def __init__(
        self, geometry: Geometry, counter_bits: int, integrator: str | None = None
    ) -> None:
        """``counter_bits``: the robot's hardware counter width (16 wraps within the 24 on the
        bus); ``integrator`` None: the one ODOM_STATUS reports."""
        self.geometry = geometry
        self.counter_bits = min(counter_bits, WIRE_COUNTER_BITS)
        self.forced = integrator is not None
        self.integrator = integrator
        self.enc_seq = -1
        self.stalls = 0  # firmware silences after which the reference restarted
        self._pos = 0  # frames fed so far (the order of encoder frames and pose halves)
        self._counts: list[tuple[int, int, int] | None] = [None] * _RING  # seq, left, right
        self._window = _Columns(("seq", "pos", "counter", "t_s", "left", "right"), ENC_WINDOW)
        self._halves = {"x": _Columns(("pos", "enc_counter", "counter", "t_s"), HALF_WINDOW),
                        "y": _Columns(("pos", "enc_counter", "counter", "t_s"), HALF_WINDOW)}
        self._unsettled: dict[str, _Half] = {}  # per message, the latest half heard
        self._xs: dict[int, _Half] = {}  # settled X halves by the encoder frame they name
        self._ys: dict[int, tuple[_Half, bool]] = {}  # settled Y halves (and queued) waiting
        self._sampled: set[int] = set()  # encoder frames an on-board sample was made of
        self._settled: list[Sample] = []  # samples settled since ``take_samples``
        self._ref_at: dict[int, FramePose] = {}  # the reference at the latest encoder frames
        self._ref: ReferenceOdometry | None = None
        self._gate = StepGate(geometry, self.counter_bits)
        self._pending: FramePose | None = None  # the first pose, heard before the integrator
        self._backlog_counts: list[tuple[int, int, int, int]] = []  # seq, counter, left, right
        self._backlog_poses: list[FramePose] = []
        self._truth_parts: dict[int, tuple[int, float]] = {}
        self._last_pair: tuple[FramePose, FramePose] | None = None  # on-board, reference
        self._last_sample_t: float | None = None  # bus time of the last sample's ODOM_POSE_Y
        self._last_compared = -1  # the encoder frame of the last sample compared
        self._place_at_next = False  # after a stall or a held pose: place the position again
        self._lost_page: tuple[int, int] | None = None  # ENC_E2E_LOST, latest frame then
        self._allowances: list[tuple[int, float]] = []  # (first frame, m) per lossy span
        self._revisable: deque[tuple[int, float]] = deque()  # (frame, m) of samples since
        self._revisable_in_order = True  # ``_revisable`` by frame (then settled from its head)
        self._beyond_settled_m = 0.0  # largest error beyond its allowance of the other samples
        self._now_s = 0.0  # the latest bus time (s)
        self._boot: tuple[int, float] | None = None  # after a reboot: primed guess, wait until
        self._boot_poses: list[FramePose] = []  # the new life's samples while it waits
        self.pose: FramePose | None = None
        self.pose_t_s = 0.0  # bus time of the ODOM_POSE_Y of ``pose`` (s)
        self.reference: FramePose | None = None
        self.truth: FramePose | None = None
        self.reference_starts = 0
        self.vs_reference = ErrorStats()
        self.vs_truth = ErrorStats()
        self.reference_vs_truth = ErrorStats()

    fast_path = True  # False: every half by ``match_encoder`` over the window (tests compare)

    # --- frames ---

    def advance(self, t_s: float) -> None:
        """Bus time is now ``t_s`` (any frame heard): pose halves heard half an encoder cycle or
        more before are settled (no half of their message can come close after them); a new
        life that waited ``BOOT_COUNT_WAIT_S`` for its count page starts without it."""
        self._now_s = t_s
        if self._boot is not None and t_s > self._boot[1]:
            self._finish_boot(self._boot[0])
        if not self._unsettled:
            return
        for name, half in sorted(self._unsettled.items(), key=lambda item: item[1].pos):
            if t_s - half.t_s >= _QUEUED_GAP_S:
                self._settle(name)

    def on_encoders(self, counter: int, left: int, right: int, t_s: float) -> None:
        """An accepted WHEEL_ENCODERS frame (raw 24-bit counts) heard at bus time ``t_s``."""
        self.advance(t_s)
        self.enc_seq += 1
        self._pos += 1
        self._window.append(self.enc_seq, self._pos, counter, t_s, left, right)
        if self.enc_seq % ENC_WINDOW == 0:
            self._forget(self.enc_seq - ENC_WINDOW)
        self._counts[counter] = (self.enc_seq, left, right)
        ref = self._ref
        if ref is not None:
            step = self._gate.step(counter, left, right)
            if step is not None:
                ref.step_deltas(*step)
            self._keep_ref(FramePose(self.enc_seq, ref.x_m, ref.y_m, ref.heading_rad))
        elif self._pending is not None:
            self._backlog_counts.append((self.enc_seq, counter, left, right))
            if len(self._backlog_counts) > BACKLOG_FRAMES:  # too long: start at a later pose
                self._drop_backlog()

    def _forget(self, before: int) -> None:
        """Drop what is kept of the encoder frames before ``before`` (seq): the state stays
        bounded whatever the bus says."""
        self._xs = {seq: half for seq, half in self._xs.items() if seq >= before}
        self._ys = {seq: half for seq, half in self._ys.items() if seq >= before}
        self._sampled = {seq for seq in self._sampled if seq >= before}
        self._ref_at = {seq: ref for seq, ref in self._ref_at.items() if seq >= before}

    def _keep_ref(self, ref: FramePose) -> None:
        self._ref_at[ref.seq] = ref
        self._ref_at.pop(ref.seq - ENC_WINDOW, None)

    def on_pose_x(self, enc_counter: int, x_m: float, heading_rad: float, *, counter: int,
                  t_s: float) -> None:
        """ODOM_POSE_X (X in m, HEADING in rad within the turn; its E2E COUNTER, bus time s)."""
        self._on_half("x", _Half(0, enc_counter, counter, t_s, x_m, heading_rad))

    def on_pose_y(self, enc_counter: int, y_m: float, turns: int, *, counter: int,
                  t_s: float) -> None:
        """ODOM_POSE_Y (Y in m, TURNS; its E2E COUNTER, bus time s): with the ODOM_POSE_X of
        the same encoder frame, one on-board sample once settled (``take_samples``)."""
        self._on_half("y", _Half(0, enc_counter, counter, t_s, y_m, turns))

    def take_samples(self) -> list[Sample]:
        """The on-board samples settled since the last call, in the order settled."""
        settled, self._settled = self._settled, []
        return settled

    def _on_half(self, name: str, half: _Half) -> None:
        self.advance(half.t_s)
        self._pos += 1
        half.pos = self._pos
        self._halves[name].append(half.pos, half.enc_counter, half.counter, half.t_s)
        if name in self._unsettled:  # its successor is heard: it is known whether it queued
            self._settle(name)
        self._unsettled[name] = half

    def _settle(self, name: str) -> None:
        """Resolve the encoder frame the unsettled half of ``name`` names, and pair it."""
        half = self._unsettled.pop(name)
        seq, queued = self._named(self._halves[name], half.pos)
        if seq < 0:
            return  # left out, as analyze leaves it out (unmatched)
        if name == "x":
            self._xs.setdefault(seq, half)
            waiting = self._ys.pop(seq, None)
            if waiting is not None:
                self._pair(seq, half, *waiting)
        elif seq in self._xs:
            self._pair(seq, self._xs[seq], half, queued)
        else:
            self._ys.setdefault(seq, (half, queued))

    def _named(self, halves: _Columns, pos: int) -> tuple[int, bool]:
        """The encoder frame (seq) the half at ``pos`` names, -1 when none, and whether it
        queued: ``host.judge.samples.match_encoder`` over the window (the held and queued rules,
        the age bound, the causal rule); a half neither queued nor repeating its predecessor's
        ENC_COUNTER by the plain rule alone, in plain Python (``_named_plain``: the same
        result)."""
        if self.fast_path:
            plain = _named_plain(halves.rows, self._window, pos)
            if plain is not None:
                return plain, False
        if not len(self._window):
            return -1, False
        w = self._window
        counter = w.col("counter").astype(np.int64)
        enc = Encoders(index=w.col("pos").astype(np.int64), counter=counter,
                       seq=sender_seq(counter, w.col("t_s"), CYCLE_S),
                       left=w.col("left").astype(np.int64), right=w.col("right").astype(np.int64),
                       timestamp_s=w.col("t_s"), cycle_s=CYCLE_S)
        at = halves.col("pos").astype(np.int64)
        k = int(np.searchsorted(at, pos))
        stop = k + 2  # the half and the one after it, if heard
        t_s = halves.col("t_s")[:stop]
        # The bus times must show the send period for the queued rule: a bus stamped on receipt
        # from a sender faster than real time (a lockstep rig forwarded) shows every frame in a
        # burst. Then the plain rule (the latest frame on the bus) is the only one left, where
        # analyze, given such a log, pairs nothing.
        clocked = len(t_s) < 3 or float(np.median(np.diff(t_s))) >= QUEUED_GAP_CYCLES * CYCLE_S
        own = halves.col("counter")[:stop].astype(np.int64) if clocked else None
        named = match_encoder(enc, at[:stop], halves.col("enc_counter")[:stop].astype(np.int64),
                              t_s, own)
        queued = clocked and bool(queued_frames(t_s, CYCLE_S)[k])
        found = int(named[k])
        return (int(w.col("seq")[found]) if found >= 0 else -1), queued

    # --- samples ---

    def _pair(self, seq: int, x: _Half, y: _Half, queued: bool) -> None:
        """The X and Y halves naming encoder frame ``seq``: one on-board sample (the first)."""
        self._ys.pop(seq, None)
        if seq in self._sampled:
            return
        self._sampled.add(seq)
        pose = self.pose = FramePose(seq, x.value, y.value, y.extra * TURN_RAD + x.extra)
        self.pose_t_s = y.t_s
        ref = self._compare(pose, y, queued)
        self._settled.append(Sample(pose, ref, y.enc_counter, x.counter, y.t_s))

    def _silent_before(self, y: _Half, queued: bool) -> bool:
        """The firmware was silent before this sample (``stalls.after_stalls``): its
        ODOM_POSE_Y came ``SILENCE_CYCLES`` - 0.5 cycles or more after the previous sample's
        while the encoder frames went on (``SILENCE_CYCLES`` - 1 or more heard between), and
        it was not let out in a burst."""
        last, self._last_sample_t = self._last_sample_t, y.t_s
        if last is None or queued or y.t_s - last < (SILENCE_CYCLES - 0.5) * CYCLE_S:
            return False
        stamps = self._window.col("t_s")
        heard = int(np.searchsorted(stamps, y.t_s) - np.searchsorted(stamps, last))
        return heard >= SILENCE_CYCLES - 1

    def _compare(self, pose: FramePose, y: _Half, queued: bool) -> FramePose | None:
        """Judge one on-board sample; the reference at its encoder frame, None when unknown."""
        seq = pose.seq
        if self._silent_before(y, queued) and self._ref is not None:
            # The firmware was stalled: this pose names a backlog frame, and it took the
            # frames it missed as one step: the reference's position is placed again at the
            # next pose (its heading, a function of the counts, goes on).
            self.stalls += 1
            self._place_at_next = True
            return None
        held = 0 <= self._last_compared <= seq - SILENCE_FRAMES and not queued
        if self._ref is not None and held and not self._place_at_next:
            # The firmware held its pose that long, then took the frames since as one step,
            # which a fine reference cannot follow on a curve: placed again, as after a stall.
            self.stalls += 1
            self._place_at_next = True
        if self._boot is not None:  # a new life waiting for the frame it primed on
            self._boot_poses.append(pose)
            return None
        if self._ref is None:
            if self._pending is None:
                self._pending = pose
                seqs = self._window.col("seq")
                keep = seqs >= seq
                self._backlog_counts = list(zip(
                    seqs[keep].astype(int).tolist(),
                    self._window.col("counter")[keep].astype(int).tolist(),
                    self._window.col("left")[keep].astype(int).tolist(),
                    self._window.col("right")[keep].astype(int).tolist(), strict=True))
            if self.integrator is None:
                self._backlog_poses.append(pose)
                return None
            self._start_reference(self._pending, self._backlog_counts, [])
            self._drop_backlog()
        ref = self._ref_at.get(seq)
        if ref is None:
            return None
        if self._place_at_next:
            ref = self._place(pose, ref)
        self._record(pose, ref)
        return ref

    def _record(self, pose: FramePose, ref: FramePose) -> None:
        self.reference = ref
        self._last_pair = (pose, ref)
        self._last_compared = pose.seq
        self.vs_reference.add(pose, ref)
        revisable = self._revisable
        if revisable and pose.seq < revisable[-1][0]:
            self._revisable_in_order = False
        revisable.append((pose.seq, self.vs_reference.latest["dpos_m"]))
        if revisable[0][0] < pose.seq - ENC_WINDOW:  # beyond any span's reach
            self._settle_errors(pose.seq - ENC_WINDOW)

    def _settle_errors(self, upto: int) -> None:
        """The samples up to encoder frame ``upto`` can get no more allowance."""
        revisable = self._revisable
        if self._revisable_in_order and self.fast_path:  # those up to ``upto`` lead
            settled = []
            while revisable and revisable[0][0] <= upto:
                settled.append(revisable.popleft())
        else:
            settled = [(f, e) for f, e in revisable if f <= upto]
            self._revisable = deque((f, e) for f, e in revisable if f > upto)
            frames = [f for f, _ in self._revisable]
            self._revisable_in_order = frames == sorted(frames)
        if not settled:
            return
        self._beyond_settled_m = max([self._beyond_settled_m,
                                      *(e - self.allowance_m(f) for f, e in settled)])

    # --- encoder frames the firmware lost that the bus carried (host.judge.compare) ---

    def on_enc_lost(self, lost: int) -> None:
        """ODOM_STATUS page E2E_WHEEL_ENCODERS: the firmware's ENC_E2E_LOST (u8). Where it grew
        by more than the bus's own gaps since the previous page, the firmware lost frames the
        bus carried (``losses.firmware_losses``): the position may leave the fine reference by
        the sum of the largest errors that many lost frames make there (``loss_allowance``),
        from the frame of the previous page on, as ``analyze`` allows it."""
        upto = self.enc_seq
        before, self._lost_page = self._lost_page, (lost, upto)
        if before is None or self._ref is None or not len(self._window):
            return
        seqs = self._window.col("seq")
        i0, i1 = np.searchsorted(seqs, before[1]), len(seqs) - 1
        if i0 >= len(seqs) or seqs[i0] != before[1]:
            return  # the previous page's frame left the window: not judged
        w = self._window
        counter = w.col("counter").astype(np.int64)
        sent = sender_seq(counter, w.col("t_s"), CYCLE_S)
        n = int(lost_beyond_gaps(np.array(before[0]), np.array(lost), sent[i0], sent[i1],
                                 np.array(i1 - i0)))
        if n > 0:
            assert self.integrator is not None
            enc = Encoders(index=w.col("pos").astype(np.int64), counter=counter, seq=sent,
                           left=w.col("left").astype(np.int64),
                           right=w.col("right").astype(np.int64), timestamp_s=w.col("t_s"),
                           cycle_s=CYCLE_S)
            drop = drop_errors_of(enc, self.geometry, self.counter_bits, self.integrator)
            drop[np.isin(seqs.astype(np.int64), list(self._sampled))] = 0.0  # were not lost
            self._allowances.append((before[1], worst_losses_m(drop, int(i0), int(i1), n)))
        self._settle_errors(upto)  # later spans start at this page's frame

    def allowance_m(self, seq: int | None = None) -> float:
        """The loss allowance (m) at encoder frame ``seq`` (default: the latest sample's)."""
        seq = self._last_compared if seq is None else seq
        return sum(a for first, a in self._allowances if seq > first)

    @property
    def max_beyond_allowance_m(self) -> float:
        """The largest on-board vs reference position error beyond its loss allowance (m);
        analyze's ``max_position_error_beyond_allowance_m``."""
        recent = (e - self.allowance_m(f) for f, e in self._revisable)
        return max([self._beyond_settled_m, *recent]) if self.vs_reference.samples else 0.0

    # --- lives and restarts ---

    def on_integrator(self, name: str) -> None:
        """ODOM_STATUS reports the firmware's integrator; a change restarts the reference."""
        if self.forced or name == self.integrator:
            return
        first = self.integrator is None
        self.integrator = name
        if first and self._pending is not None:  # judge what was heard while waiting
            self._start_reference(self._pending, self._backlog_counts, self._backlog_poses)
            self._drop_backlog()
        else:
            self.restart_reference()

    def restart_reference(self) -> None:
        """Start the reference again at the next on-board pose (after a set-pose or config)."""
        self._ref = None
        self._last_compared = -1
        self._last_sample_t = None
        self._place_at_next = False
        self._ref_at = {}
        self._settle_errors(self.enc_seq)
        self._allowances = []
        self._drop_backlog()

    def power_up(self, primed_now: bool) -> None:
        """A firmware reboot (``host.judge.sources``): the new firmware's life starts at its
        power-up pose, (0, 0, 0) at the encoder frame it primed on, as ``analyze`` starts it
        (``host.judge.reboots``). That frame is the one its first page of WHEEL_ENCODERS E2E
        counts names (``on_enc_counts``: the ENC_E2E_OK-th encoder frame back), whatever the
        summary said (the recorder may have missed the boot summary: those of the first second
        all say UPTIME 0); until that page, or ``BOOT_COUNT_WAIT_S`` without one, the new
        life's samples wait. Without the page: the latest accepted encoder frame when the boot
        summary says UPTIME 0 and not INIT (``primed_now``: it primed in its first tick), else
        the next one. No pose is adopted, so a firmware that comes up wrong shows its error.
        Without a known integrator it falls back to ``restart_reference`` (the next pose is
        adopted)."""
        self.restart_reference()
        self._lost_page = None  # the new firmware counts from 0
        if self.integrator is None:
            return
        guess = self.enc_seq if primed_now else self.enc_seq + 1
        self._boot = (guess, self._now_s + BOOT_COUNT_WAIT_S)
        self._boot_poses = []

    @property
    def awaiting_boot(self) -> bool:
        """A new firmware life waits for the frame it primed on (its samples are not judged
        yet)."""
        return self._boot is not None

    def _finish_boot(self, primed: int) -> None:
        """Start the new life's reference at (0, 0, 0) at encoder frame ``primed`` (seq) and
        judge the samples heard since the reboot; adopt the next pose when that frame is not
        known (not heard yet, or no longer in the window)."""
        poses, self._boot, self._boot_poses = self._boot_poses, None, []
        seqs = self._window.col("seq")
        keep = seqs >= primed
        if not keep.any() or int(seqs[keep][0]) != primed:
            self.restart_reference()
            return
        counts = list(zip(seqs[keep].astype(int).tolist(),
                          self._window.col("counter")[keep].astype(int).tolist(),
                          self._window.col("left")[keep].astype(int).tolist(),
                          self._window.col("right")[keep].astype(int).tolist(), strict=True))
        self._start_reference(FramePose(primed, 0.0, 0.0, 0.0), counts, poses)

    def on_enc_counts(self, ok: int, lost: int) -> None:
        """ODOM_STATUS page E2E_WHEEL_ENCODERS: the firmware's ENC_E2E_OK (encoder frames it
        accepted since its boot, u16 wrapping) and ENC_E2E_LOST. The first page after a reboot
        names the frame it primed on (``power_up``); then ``on_enc_lost``."""
        if self._boot is not None and 0 < ok <= self.enc_seq + 1:
            self._finish_boot(self.enc_seq - ok + 1)
        self.on_enc_lost(lost)

    def _drop_backlog(self) -> None:
        self._pending = None
        self._backlog_counts = []
        self._backlog_poses = []

    def set_geometry(self, geometry: Geometry, counter_bits: int) -> None:
        """New robot parameters (a config command); the reference restarts at the next pose."""
        self.geometry = geometry
        self.counter_bits = min(counter_bits, WIRE_COUNTER_BITS)
        self.restart_reference()

    def _place(self, pose: FramePose, ref: FramePose) -> FramePose:
        """Move the reference's position (now and at the frames heard since ``ref``) by
        ``pose - ref``: it starts again where the firmware is, within the pose's rounding (so
        within about 1.4 LSB after), while its heading goes on exact. Returns the moved ``ref``."""
        assert self._ref is not None
        dx, dy = pose.x_m - ref.x_m, pose.y_m - ref.y_m
        self._ref.x_m += dx
        self._ref.y_m += dy
        self._ref_at = {seq: r if seq < ref.seq else r._replace(x_m=r.x_m + dx, y_m=r.y_m + dy)
                        for seq, r in self._ref_at.items()}
        self._place_at_next = False
        return ref._replace(x_m=ref.x_m + dx, y_m=ref.y_m + dy)

    def on_truth(
        self, part: int, enc_counter: int, value: float
    ) -> tuple[FramePose, FramePose | None] | None:
        """A SIM_TRUTH part (0 X m, 1 Y m, 2 HEADING rad); three of one encoder frame: a sample.

        Returns (truth, reference at that encoder frame or None) once the sample is complete.
        """
        self._truth_parts[part] = (enc_counter, value)
        parts = self._truth_parts
        if len(parts) < 3 or len({p[0] for p in parts.values()}) != 1:
            return None
        self._truth_parts = {}
        named = self._recent(self._counts[enc_counter])
        ref = self._ref_at.get(named[0]) if named is not None else None
        truth = self.truth = FramePose(
            ref.seq if ref else -1, parts[0][1], parts[1][1], self._truth_heading(parts[2][1], ref)
        )
        if ref is None:
            return truth, None
        self.reference_vs_truth.add(ref, truth)
        if self._last_pair is not None:  # the on-board pose carried to this frame
            pose, at = self._last_pair
            estimate = FramePose(
                ref.seq, pose.x_m - at.x_m + ref.x_m, pose.y_m - at.y_m + ref.y_m,
                pose.heading_rad - at.heading_rad + ref.heading_rad,
            )
            self.vs_truth.add(estimate, truth)
        return truth, ref

    @property
    def counter_restarts(self) -> int:
        """Counter restarts the current reference re-primed on (as the firmware does)."""
        return self._gate.counter_restarts

    def _truth_heading(self, wrapped_rad: float, ref: FramePose | None) -> float:
        """SIM_TRUTH's HEADING ([0, 2 pi) on the bus) made cumulative: the turn nearest the
        reference at that encoder frame, else nearest the previous truth (rad)."""
        if ref is not None:
            return unwrap_near(wrapped_rad, ref.heading_rad)
        if self.truth is not None:
            return unwrap_near(wrapped_rad, self.truth.heading_rad)
        return wrap_angle(wrapped_rad)

    def _recent(self, entry: Any) -> Any:
        """A ring entry if it is one of the last 8 encoder frames (not one 16 frames older)."""
        if entry is None or self.enc_seq - entry[0] >= _RING // 2:
            return None
        return entry

    def _start_reference(
        self, pose: FramePose, counts: list[tuple[int, int, int, int]], poses: list[FramePose]
    ) -> None:
        """Start the reference at ``pose``, primed on the first of ``counts`` (seq, counter,
        left, right: the encoder frame ``pose`` names and those after it), catch up, and compare
        the ``poses`` heard meanwhile."""
        assert self.integrator is not None
        ref = self._ref = ReferenceOdometry(
            self.geometry, self.integrator, self.counter_bits,
            x_m=pose.x_m, y_m=pose.y_m, heading_rad=pose.heading_rad,
        )
        self.reference_starts += 1
        self._ref_at = {}
        self._gate = StepGate(self.geometry, self.counter_bits)
        for seq, counter, left, right in counts:
            step = self._gate.step(counter, left, right)  # the first primes: stays at pose
            if step is not None:
                ref.step_deltas(*step)
            self._keep_ref(FramePose(seq, ref.x_m, ref.y_m, ref.heading_rad))
        for heard in poses:
            at = self._ref_at.get(heard.seq)
            if at is not None:
                self._record(heard, at)

    def _vs_reference_dict(self) -> dict[str, Any] | None:
        """``vs_reference`` with ``loss_allowance_m`` (at the latest sample) and
        ``max_dpos_beyond_allowance_m``."""
        stats = self.vs_reference.as_dict()
        if stats is None:
            return None
        return {**stats, "loss_allowance_m": self.allowance_m(),
                "max_dpos_beyond_allowance_m": self.max_beyond_allowance_m}

    def snapshot(self) -> dict[str, Any]:
        """``pose``, ``reference``, ``truth`` (None until known) and ``error``."""
        return {
            "pose": pose_dict(self.pose),
            "reference": {**(pose_dict(self.reference) or {}), "integrator": self.integrator,
                          "starts": self.reference_starts,
                          "counter_restarts": self.counter_restarts, "stalls": self.stalls},
            "truth": pose_dict(self.truth),
            "error": {
                "pose_vs_reference": self._vs_reference_dict(),
                "pose_vs_truth": self.vs_truth.as_dict(),
                "reference_vs_truth": self.reference_vs_truth.as_dict(),
            },
        }


def pose_dict(pose: FramePose | None) -> dict[str, float] | None:
    """JSON form: ``x_m``, ``y_m``, ``heading_rad`` in (-pi, pi], ``heading_unwrapped_rad``."""
    if pose is None:
        return None
    return {"x_m": pose.x_m, "y_m": pose.y_m, **heading_fields(pose.heading_rad)}
