"""The live judge's window of the latest pose halves and encoder frames (``host.judge.tracking``):
the columns ``samples.match_encoder`` reads, and the plain-Python fast path that gives the common
half (not in a burst, not a repeat) the answer ``match_encoder`` would, without numpy per frame."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.judge.powerup import NAMED_SPAN
from odocan.host.judge.primed import counted_start
from odocan.host.judge.samples import (
    QUEUED_GAP_CYCLES,
    SILENCE_CYCLES,
    Encoders,
    FloatArray,
    match_encoder,
    queued_frames,
    sender_seq,
)
from odocan.host.judge.senderseq import pose_skips
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

HALF_LAP = ENC_COUNTER_LAP // 2  # 8: a COUNTER step read as -8..+7

HALF_WINDOW = 256  # pose halves of each message kept to resolve the frame one names (5 s)
ENC_WINDOW = 512  # encoder frames kept for it, and the reference at each (5 s at 100 Hz)
CYCLE_S = busfacts.ENC_CYCLE_S  # WHEEL_ENCODERS' cycle
RECENT = 32  # latest rows of a window kept as tuples for the fast path (``named_plain``)
# closer sends of one message waited (queued): ``samples.queued_frames``' test of one gap is
# 0 <= gap < QUEUED_GAP_S (a gap going back is a frame reordered, not queued), written out
QUEUED_GAP_S = QUEUED_GAP_CYCLES * CYCLE_S
REPEAT_S = SILENCE_CYCLES * CYCLE_S  # a repeated ENC_COUNTER closer than this is held
# The window's encoder frames: the tracker's seq, the order fed, COUNTER, bus time s, the counts,
# the periods heard since the frame before (``liveplace.StallPlacer.periods``) and CTRL_UPTIME:
# what ``livepose.StepGate.step`` takes, so a reference started late (a backlog, a boot, a set
# pose) steps the frames as the live one stepped them, a controller restart among them included.
ENC_COLUMNS = ("seq", "pos", "counter", "t_s", "left", "right", "periods", "uptime")
# seq, COUNTER, left, right, periods, CTRL_UPTIME, bus time s
Counted = tuple[int, int, int, int, int, int, float]
Row = tuple[int, int, int, float, int, int, int, int]  # a row of ``ENC_COLUMNS`` as appended


def named_plain(halves: deque[tuple[float, ...]], columns: Columns, pos: int) -> int | None:
    """``PoseTracker.named`` for the common half, without numpy: the encoder frame (seq) the
    half at ``pos`` names, -1 when none; None when ``samples.match_encoder``'s held or queued
    rule may apply (``plain_half``). Else its plain rule alone decides, computed here as it
    computes it on the window: the latest encoder frame before the half (less than 8 cycles
    older), the offset of ENC_COUNTER from its COUNTER, and the frame that many sender steps
    (``samples.sender_seq``, pair by pair) back; None too when that reaches back beyond the
    window's rows kept as tuples. ``columns.rows``: seq, pos, COUNTER, bus time s, ..."""
    half = plain_half(halves, pos)
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
    offset = ((int(enc_counter - window[latest][2]) + HALF_LAP) & ENC_COUNTER_MASK) - HALF_LAP
    if offset > 0:
        return -1  # not on the bus before the half
    # the first frame whose seq >= seq[latest] + offset (searchsorted): walk back from latest
    # while the one before still is; ``back``: seq[latest] - seq[j]
    j, back = latest, 0
    while j > -n:
        step = _sender_step(window, j)
        if step is None:
            return None  # a burst after a gap, perhaps a hole of the log: match_encoder judges
        if back + step > -offset:
            break
        back += step
        j -= 1
    else:
        if not columns.whole:
            return None  # the walk may go on before the rows kept: let match_encoder judge
    return int(window[j][0]) if back == -offset else -1


def plain_half(halves: deque[tuple[float, ...]], pos: int) -> tuple[float, float] | None:
    """ENC_COUNTER and bus time (s) of the half at ``pos`` (one of the last two ``halves`` rows:
    pos, ENC_COUNTER, COUNTER, bus time s); None when it is not there or when it is less than
    ``QUEUED_GAP_CYCLES`` from a neighbour (queued) or repeats its predecessor's ENC_COUNTER
    with own COUNTER + 1 within ``SILENCE_CYCLES`` (held)."""
    n_halves = len(halves)
    if n_halves and halves[-1][0] == pos:
        k = -1
    elif n_halves > 1 and halves[-2][0] == pos:
        k = -2
        if 0 <= halves[-1][3] - halves[-2][3] < QUEUED_GAP_S:  # queued
            return None
    else:
        return None
    _, enc_counter, counter, t_s = halves[k]
    if n_halves > -k:
        _, prev_enc, prev_counter, prev_t = halves[k - 1]
        if 0 <= t_s - prev_t < QUEUED_GAP_S:
            return None
        if (prev_enc == enc_counter and (int(counter - prev_counter) & ENC_COUNTER_MASK) == 1
                and t_s - prev_t < REPEAT_S):
            return None
    return enc_counter, t_s


def _sender_step(window: deque[tuple[float, ...]], j: int) -> int | None:
    """``samples.sender_seq``'s step from frame ``j - 1`` to frame ``j`` (negative indices into
    the window, ``j`` > -len): COUNTER step mod 16, widened by 16 per 16 periods more the bus
    times show unless frame ``j`` queued (less than ``QUEUED_GAP_CYCLES`` from a neighbour)
    with a step other than 0; None where it queued after such a gap: whether that gap is a hole
    of the log (``senderseq.pose_skips``) the rows kept here cannot tell."""
    row, prev = window[j], window[j - 1]  # (by index: no slice made per frame named)
    counter, t_s, prev_t = row[2], row[3], prev[3]
    step = int(counter - prev[2]) & ENC_COUNTER_MASK
    dt = t_s - prev_t
    laps = math.floor((dt / CYCLE_S - step) / ENC_COUNTER_LAP + 0.5)
    laps = laps if laps > 0 else 0  # ``max(0, laps)`` written out (per frame named)
    if step and (0 <= dt < QUEUED_GAP_S  # queued
                 or (j < -1 and 0 <= window[j + 1][3] - t_s < QUEUED_GAP_S)):
        # a step of 0 is widened by the time alone, as ``sender_seq`` widens it
        return None if laps else step
    return step + ENC_COUNTER_LAP * laps


class Columns:
    """The latest ``size`` rows of a few numeric columns, as numpy views (``col``: rows are
    copied in only when a view is asked for, the ones appended since the last, at most
    ``size``: a window never read, as a pose half window mostly is, costs one deque append a
    row), and the latest ``RECENT`` of them as plain tuples (``rows``, a ring buffer for the
    fast path; ``whole``: they are the whole window): the live judge's window of recent
    frames."""

    def __init__(self, names: tuple[str, ...], size: int) -> None:
        self.size = size
        self._col = {name: i for i, name in enumerate(names)}
        self._data = np.zeros((2 * size, len(names)))
        self._n = 0  # rows in ``_data``
        self._count = 0  # rows appended in all
        # rows appended, not in ``_data`` yet (the latest ``size``: older ones are never read)
        self._unflushed: deque[tuple[float, ...]] = deque(maxlen=size)
        self.rows: deque[tuple[float, ...]] = deque(maxlen=RECENT)
        self.last_named: tuple[int, int] = (-1, -1)  # a half's pos and the seq it named

    def append(self, *row: float) -> None:
        self.rows.append(row)
        self._count += 1
        self._unflushed.append(row)  # copied into ``_data`` when a column is read

    def append_row(self, row: tuple[float, ...]) -> None:
        """``append`` of a row made as a tuple already (per encoder frame: none unpacked)."""
        self.rows.append(row)
        self._count += 1
        self._unflushed.append(row)  # copied into ``_data`` when a column is read

    @property
    def holds_first(self) -> bool:
        """The window still holds the first row ever appended (fewer than ``size`` since)."""
        return self._count <= self.size

    @property
    def whole(self) -> bool:
        """``rows`` holds every row of the window (its first is the window's first)."""
        return self._count <= RECENT

    def _flush(self) -> None:
        rows = list(self._unflushed)
        self._unflushed.clear()
        m = len(rows)
        if self._n + m > len(self._data):  # keep the latest ``size`` rows, at the front
            keep = min(self._n, self.size - m)
            self._data[:keep] = self._data[self._n - keep : self._n]
            self._n = keep
        self._data[self._n : self._n + m] = rows
        self._n += m

    def latest_from(self, first: float) -> list[tuple[float, ...]] | None:
        """The rows from the first whose first column (increasing, as ``seq``) is ``first``
        or more to the latest, as plain tuples (those not copied yet as appended, the copied
        ones as floats): the rows ``col`` cut with ``searchsorted`` gives, without copying;
        None when they reach more than ``RECENT`` copied rows back (then read ``col``)."""
        rows: list[tuple[float, ...]] = []
        for row in reversed(self._unflushed):
            if row[0] < first:
                rows.reverse()
                return rows
            rows.append(row)
        start = max(0, self._n + len(self._unflushed) - self.size)  # the window's, in _data
        for k in range(self._n - 1, max(start, self._n - RECENT) - 1, -1):
            row = tuple(self._data[k].tolist())
            if row[0] < first:
                rows.reverse()
                return rows
            rows.append(row)
        if self._n - RECENT <= start:  # the window's first reached: none before ``first``
            rows.reverse()
            return rows
        return None

    def col(self, name: str) -> FloatArray:
        if self._unflushed:
            self._flush()
        column: FloatArray = self._data[max(0, self._n - self.size) : self._n, self._col[name]]
        return column

    def __len__(self) -> int:
        return min(self._count, self.size)


@dataclass(slots=True)
class Half:
    """A pose half heard: its place among the frames fed (``pos``), ENC_COUNTER, its own E2E
    COUNTER, bus time (s) and values (X: X m, HEADING rad; Y: Y m, TURNS)."""

    pos: int
    enc_counter: int
    counter: int
    t_s: float
    value: float
    extra: float


def window_encoders(window: Columns, halves: Columns | None = None) -> Encoders:
    """The window's encoder frames as ``samples.Encoders`` (sequence numbers by
    ``samples.sender_seq``, as ``samples.encoder_frames`` numbers a log's; the holes of the
    log told by the pose ``halves`` heard, ``window_holes``)."""
    counter = window.col("counter").astype(np.int64)
    return Encoders(index=window.col("pos").astype(np.int64), counter=counter,
                    seq=sender_seq(counter, window.col("t_s"), CYCLE_S,
                                   window_holes(window, halves)),
                    left=window.col("left").astype(np.int64),
                    right=window.col("right").astype(np.int64),
                    timestamp_s=window.col("t_s"), cycle_s=CYCLE_S)


def window_holes(window: Columns, halves: Columns | None, first: int = 0,
                 last: int | None = None) -> npt.NDArray[np.bool_] | None:
    """``senderseq.pose_skips`` of the window's encoder frames ``first`` .. ``last`` (slice
    bounds), from the pose ``halves`` heard (one kind: each has its own COUNTER); None without
    them."""
    if halves is None:
        return None
    return pose_skips(window.col("pos")[first:last].astype(np.int64),
                      halves.col("pos").astype(np.int64), halves.col("counter").astype(np.int64))


def named_in_window(halves: Columns, w: Columns, pos: int) -> tuple[int, bool]:
    """The encoder frame (seq) the half at ``pos`` of ``halves`` names, -1 when none, and
    whether it queued: ``host.judge.samples.match_encoder`` over the window ``w`` (the held and
    queued rules, the age bound, the causal rule)."""
    if not len(w):
        return -1, False
    enc = window_encoders(w, halves)
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
    seq = int(w.col("seq")[found]) if found >= 0 else -1
    if own is not None and k > 0 and not halves.holds_first and _held_from_start(halves, k):
        prev_pos, prev_seq = halves.last_named  # the run began before the window: carried
        seq = prev_seq if prev_pos == int(at[k - 1]) else seq
    halves.last_named = (pos, seq)
    return seq, queued


def _held_from_start(halves: Columns, k: int) -> bool:
    """Every half of the window up to ``k`` repeats its predecessor's ENC_COUNTER with its own
    COUNTER + 1 within ``REPEAT_S`` (``samples._held``'s run): the run that half ``k`` holds
    began before the window's first half, which the window alone would name by the plain rule,
    a frame 16, 32, ... ahead of the one held (a firmware refusing every frame for 20 s, its
    pose and twist held on its last: the live twist judge FAILed it, 204 mm/s)."""
    enc_counter = halves.col("enc_counter")[: k + 1]
    counter = halves.col("counter")[: k + 1].astype(np.int64)
    t_s = halves.col("t_s")[: k + 1]
    return bool(np.all(np.diff(enc_counter) == 0)
                and np.all((np.diff(counter) & ENC_COUNTER_MASK) == 1)
                and np.all(np.diff(t_s) < REPEAT_S))


def counted(row: Row) -> Counted:
    """A row of ``ENC_COLUMNS`` as the reference steps it (``Counted``; no conversion: per
    frame)."""
    seq, _, counter, t_s, left, right, periods, uptime = row
    return seq, counter, left, right, periods, uptime, t_s


def window_counts(window: Columns, first: int) -> list[Counted]:
    """The encoder frames of the window from seq ``first`` on (``Counted``)."""
    keep = window.col("seq") >= first
    names = ("seq", "counter", "left", "right", "periods", "uptime")
    columns = [window.col(name)[keep].astype(int).tolist() for name in names]
    return list(zip(*columns, window.col("t_s")[keep].tolist(), strict=True))


def silent_since(last_s: float | None, t_s: float, ys: Columns, window: Columns) -> bool:
    """The firmware was silent before a sample whose ODOM_POSE_Y came at ``t_s`` (not let out
    in a burst; ``last_s``: the previous sample's), the rule of ``stalls.after_stalls``:
    ``SILENCE_CYCLES`` from the last ODOM_POSE_Y sent (``ys``), with encoder frames on time
    meanwhile (``window``)."""
    if last_s is None or t_s - last_s < (SILENCE_CYCLES - 0.5) * CYCLE_S:
        return False  # the last, decided without numpy (the common case): talked >= last
    sent = ys.col("t_s")[: int(np.searchsorted(ys.col("t_s"), t_s, side="left"))]
    talked = max(last_s, float(sent[-1])) if len(sent) else last_s
    if t_s - talked < (SILENCE_CYCLES - 0.5) * CYCLE_S:
        return False
    stamps = window.col("t_s")
    on_time = ~queued_frames(stamps, CYCLE_S)
    lo, hi = np.searchsorted(stamps, talked), np.searchsorted(stamps, t_s)
    return int(np.count_nonzero(on_time[lo:hi])) >= SILENCE_CYCLES - 1


def held_on_time(window: Columns, last_seq: int, seq: int) -> bool:
    """``stalls.frozen_breaks``' test of a hold between the samples of encoder frames
    ``last_seq`` and ``seq``: ``SILENCE_CYCLES`` or more of the frames after ``last_seq`` up to
    ``seq`` came on time (not ``queued_frames``: frames a busy bus, or a starved recorder's
    stamps, let out at once tell no hold: a firmware draining them in its next tick missed
    none). The live judge takes the window's frames (the one after ``seq`` when heard)."""
    seqs = window.col("seq")
    lo = int(np.searchsorted(seqs, last_seq, side="right"))
    hi = int(np.searchsorted(seqs, seq, side="right"))
    on_time = ~queued_frames(window.col("t_s"), CYCLE_S)
    return int(np.count_nonzero(on_time[lo:hi])) >= SILENCE_CYCLES


def primed_at(window: Columns, ok: int, lost: int) -> int | None:
    """The encoder frame (the tracker's seq) a rebooted firmware primed on, from its first page
    of WHEEL_ENCODERS E2E counts (ENC_E2E_OK ``ok``, ENC_E2E_LOST ``lost``) heard after the
    window's latest frame: ``primed.counted_start`` over the window (the earliest the counts
    allow: its mailbox may have lost frames the bus carried). None when the window lacks it."""
    if not len(window):
        return None
    seqs = window.col("seq").astype(np.int64)
    return counted_start((seqs, window.col("counter").astype(np.int64)), int(seqs[-1]) + 1,
                         ok, lost)


def first_named_seq(halves: Columns, window: Columns) -> int | None:
    """The encoder frame (seq) the first pose half heard (``halves``: the ODOM_POSE_X halves)
    names: its ENC_COUNTER is the COUNTER of the latest of the last ``NAMED_SPAN`` frames heard
    before it with that COUNTER, as ``powerup.named_count``. None when it cannot be told: no
    half heard yet, the windows no longer hold it or the frames before it, or none has it."""
    if not len(halves) or not halves.holds_first:
        return None
    pos, named = halves.col("pos")[0], halves.col("enc_counter")[0]
    before = np.flatnonzero(window.col("pos") < pos)[-NAMED_SPAN:]
    seqs = window.col("seq")
    if len(before) < NAMED_SPAN and not window.holds_first:  # frames before it forgotten
        return None
    hits = before[window.col("counter")[before] == named]
    return int(seqs[hits[-1]]) if len(hits) else None
