"""ODOM_TWIST LINEAR_VEL and ANGULAR_VEL judged live (``odocan monitor``, the MQTT bridge):
``host.judge.compare.check_twist``'s rule frame by frame, beside ``host.judge.livedistance``
(whose naming of the encoder frame a twist frame was made after it takes: the tracker's rule).

Per accepted encoder frame: the reference's speeds over the step into it (``compare._step_speeds``
in plain Python, the same operations in the same order: the same bits), from the counts, the
sender's periods the tracker numbered (``liveplace.StallPlacer.periods``), the widening for a
step of several periods and for a frame that waited on a busy bus, none across a motor
controller restart (CTRL_UPTIME gone back: ``livepose.aged``). Per twist frame naming encoder
frame E (not before the largest named: left out, as analyze leaves it out): judged from the
third taken on against its window (``compare.carried_windows``: the steps since the frame that
first named the encoder frame two new ones back; a resend at any depth has its chain head's
window), the band reaching 0 after a silence of the firmware (``compare.after_silence``), the
slack of ``compare.band_excess``. An excess found is latched: TWIST WRONG, the watch's exit 1.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from odocan.host.judge.compare import (
    TWIST_GAP_ACCEL_MPS2,
    TWIST_LSB,
    TWIST_RANGE,
    TWIST_RELATIVE,
    TWIST_SILENCE_S,
)
from odocan.host.judge.livepose import aged
from odocan.host.judge.posewrongs import PoseWrongs
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import WIRE_COUNTER_BITS
from odocan.host.judge.tracking import PoseTracker
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

CYCLE_S = busfacts.ENC_CYCLE_S  # WHEEL_ENCODERS' cycle
UNDO_KEPT = 8  # twists ``new_life`` can withdraw: a reboot's boot window (80 ms, 4), and more
KEEP_STEPS = 64  # steps kept whole after the last frame taken (a twist names one 8 back at most)

Band = tuple[float, float, float]  # lowest, highest per-step speed (NaN: unknown), widest gap
EMPTY: Band = (math.inf, -math.inf, 0.0)
Step = tuple[int, float, float, float, float]  # seq, v (m/s), w (rad/s), their gap slacks
Frame = tuple[int, int, int, float, int]  # COUNTER, left, right, bus time s, CTRL_UPTIME


def joined(a: Band, b: Band) -> Band:
    """Two bands together as ``np.minimum``/``np.maximum`` join them (a NaN wins)."""
    if a[0] != a[0] or b[0] != b[0]:
        return math.nan, math.nan, max(a[2], b[2])
    return min(a[0], b[0]), max(a[1], b[1]), max(a[2], b[2])


def excess(value: float, a: Band, b: Band, zero: bool) -> float:
    """``compare.band_excess`` of one value (NaN: its window holds no step, or a step across a
    controller restart). Plain comparisons: it runs per twist frame."""
    lo, hi, a_gap = a
    b_lo, b_hi, b_gap = b
    if lo != lo or b_lo != b_lo:
        return math.nan
    lo = b_lo if b_lo < lo else lo
    hi = b_hi if b_hi > hi else hi
    if not (-math.inf < lo < math.inf and -math.inf < hi < math.inf):
        return math.nan
    if zero:
        lo, hi = 0.0 if lo > 0.0 else lo, 0.0 if hi < 0.0 else hi  # ``min``, ``max``
    low, high = TWIST_RANGE
    lo = low if lo < low else high if lo > high else lo
    hi = low if hi < low else high if hi > high else hi
    lo_abs, hi_abs = abs(lo), abs(hi)  # ``max``es written out (per twist frame)
    slack = TWIST_LSB + TWIST_RELATIVE * (hi_abs if hi_abs > lo_abs else lo_abs)
    slack += b_gap if b_gap > a_gap else a_gap
    above, below = value - hi - slack, lo - slack - value
    most = above if above > 0.0 else 0.0
    return below if below > most else most


class LiveTwist:
    """The live twist-speed judge (module docstring)."""

    def __init__(self, geometry: Geometry, counter_bits: int,
                 wrongs: PoseWrongs | None = None) -> None:
        self.samples = 0
        self.suspended = False  # a config applied with parameters not known here
        self.max_linear_excess_mps = 0.0
        self.max_angular_excess_rad_s = 0.0
        self._undo: deque[tuple[float, int, float, float]] = deque(maxlen=UNDO_KEPT)  # before
        # each of the latest judged: bus time, samples, excesses
        self.wrongs = wrongs  # the tracker's: its conflict (``follow``)
        self._wrong_at_s: float | None = None  # the bus time a speed was first found wrong
        self.reconfigure(geometry, counter_bits)

    def follow(self, wrongs: PoseWrongs) -> None:
        """Judge as ``wrongs`` (the tracker's POSE WRONG episodes) judges: two firmwares on one
        node ID from its ``judged_until_s`` on, no twist heard from then is judged, and speeds
        first found wrong from then are withdrawn (``PoseWrongs.unjudgeable_from``, as
        ``LiveDistance.follow``)."""
        self.wrongs = wrongs

    def _until_s(self) -> float:
        """The bus time twists are judged until (a conflict's start; inf: none); speeds first
        found wrong from then withdrawn (before then every excess was 0)."""
        until_s = math.inf if self.wrongs is None else self.wrongs.judged_until_s
        if self._wrong_at_s is not None and self._wrong_at_s >= until_s:
            self.max_linear_excess_mps = self.max_angular_excess_rad_s = 0.0
            self._wrong_at_s = None
        return until_s

    def reconfigure(self, geometry: Geometry, counter_bits: int) -> None:
        """New robot parameters (a config command): judged from here as a new life."""
        self._m = (geometry.m_per_count_left, geometry.m_per_count_right)
        self._wheelbase_m = geometry.wheelbase_m
        bits = min(counter_bits, WIRE_COUNTER_BITS)
        self._half, self._mask = 1 << (bits - 1), (1 << bits) - 1
        self._count_mps = max(self._m) / CYCLE_S
        self.suspended = False
        self.new_life()

    def suspend(self) -> None:
        """A config applied whose parameters this judge does not know: the speeds are no
        longer judged (what was found wrong stays latched)."""
        self.suspended = True

    def new_life(self, from_s: float = math.inf) -> None:
        """A reboot: the steps and the frames taken start again (analyze judges each life).
        ``from_s``: the bus time the new firmware's frames start from (its first tick's twist
        comes before the summary that told the reboot, its first ticks' when that summary was held
        back: ``bootticks``): the twists judged from then on (as far as ``UNDO_KEPT`` back) are
        the new firmware's, not the old one's wrong, and their judgement is withdrawn."""
        gone = [undo for undo in self._undo if undo[0] >= from_s]  # the new firmware's
        if gone:
            _, self.samples, self.max_linear_excess_mps, self.max_angular_excess_rad_s = gone[0]
            if not self.wrong:
                self._wrong_at_s = None
        self._undo.clear()
        self._prev: Frame | None = None  # the last accepted encoder frame
        self._steps: list[Step] = []  # after the last frame taken
        self._folded = (EMPTY, EMPTY)  # steps beyond KEEP_STEPS, before any frame to name
        self._running = -1  # the largest encoder frame named
        self._taken = 0
        self._last: tuple[int, float] = (-1, math.nan)  # the last taken: E, bus time
        self._a, self._b = (EMPTY, EMPTY), (EMPTY, EMPTY)  # its window (linear, angular)
        self._since = 2  # chains of resends since the last silence (2: more)

    def on_encoders(self, tracker: PoseTracker, counter: int, left: int, right: int,
                    t_s: float, uptime: int) -> None:
        """An accepted WHEEL_ENCODERS frame, after ``tracker.on_encoders`` numbered it."""
        prev, frame = self._prev, (counter, left, right, t_s, uptime)
        self._prev = frame
        steps = self._steps
        if prev is None:
            steps.append((tracker.enc_seq, math.nan, math.nan, 0.0, 0.0))
        else:
            steps.append(self._step(tracker.enc_seq, prev, frame, tracker.placer.periods))
        if len(steps) > KEEP_STEPS:
            _, v, w, gap_v, gap_w = steps.pop(0)
            self._folded = (joined(self._folded[0], (v, v, gap_v)),
                            joined(self._folded[1], (w, w, gap_w)))

    def _step(self, seq: int, prev: Frame, frame: Frame, periods: int) -> Step:
        """``compare._step_speeds`` of one step into frame ``seq``: v, w, their gap slacks
        (``reference.wrap_delta`` in line: ``& mask`` is ``% 2^bits`` on Python ints)."""
        half, mask = self._half, self._mask
        ds_left = (((frame[1] - prev[1] + half) & mask) - half) * self._m[0]
        ds_right = (((frame[2] - prev[2] + half) & mask) - half) * self._m[1]
        if periods <= 0:  # (numpy: a division by 0, not a finite speed)
            return seq, math.nan, math.nan, 0.0, 0.0
        dt_s = periods * CYCLE_S
        v = (ds_left + ds_right) * 0.5 / dt_s
        w = (ds_right - ds_left) / self._wheelbase_m / dt_s
        gap_v = gap_w = 0.0
        if periods > 1:
            gap_v = TWIST_GAP_ACCEL_MPS2 * (periods - 1) * CYCLE_S + self._count_mps
            gap_w = gap_v * (2.0 / self._wheelbase_m)
        elapsed_s = frame[3] - prev[3]
        if elapsed_s > (periods + 0.5) * CYCLE_S:  # it waited: the firmware may spread it
            gap_v, gap_w = max(gap_v, abs(v)), max(gap_w, abs(w))
        uptime, before = frame[4], prev[4]
        if uptime and before and uptime < (before if (frame[0] - prev[0]) & ENC_COUNTER_MASK == 1
                                           else aged(before, elapsed_s)):
            v = w = math.nan  # the controller restarted: a twist over it is not judged
        return seq, v, w, gap_v, gap_w

    def on_twist(self, e: int, linear_raw: int, angular_raw: int, t_s: float) -> None:
        """An accepted ODOM_TWIST naming encoder frame ``e`` (-1: none; ``livedistance``),
        LINEAR_VEL and ANGULAR_VEL raw (mm/s, mrad/s), at bus time ``t_s``."""
        if e < 0 or e < self._running:
            return
        self._running = e
        last_e, last_t = self._last
        self._last = (e, t_s)
        if self._taken == 0:
            self._taken = 1
            self._drop_to(e)
            return
        if e > last_e:  # a new chain: its head's segment (last E, e]
            self._a, self._b = self._b, self._segment(e)
            self._since += 1
        if t_s - last_t >= TWIST_SILENCE_S:
            self._since = 0
        self._since = 2 if self._since > 2 else self._since  # ``min`` (per twist frame)
        self._taken += 1
        if self._taken < 3 or self.suspended or t_s >= self._until_s():
            return
        zero = self._since <= 1
        linear = excess(linear_raw * TWIST_LSB, self._a[0], self._b[0], zero)
        if linear != linear:
            return
        angular = excess(angular_raw * TWIST_LSB, self._a[1], self._b[1], zero)
        self._undo.append((t_s, self.samples, self.max_linear_excess_mps,
                           self.max_angular_excess_rad_s))
        self.samples += 1
        self.max_linear_excess_mps = max(self.max_linear_excess_mps, linear)
        self.max_angular_excess_rad_s = max(self.max_angular_excess_rad_s, angular)
        if self._wrong_at_s is None and self.wrong:
            self._wrong_at_s = t_s

    def _segment(self, e: int) -> tuple[Band, Band]:
        """The bands of the steps after the last frame taken up to ``e`` (dropped from here)
        joined to the steps folded: lowest and highest speed (NaN when one is: a step across a
        controller restart), widest gap slack; linear, angular."""
        (v_lo, v_hi, v_gap), (w_lo, w_hi, w_gap) = self._folded
        self._folded = (EMPTY, EMPTY)
        unknown = v_lo != v_lo
        steps = self._steps
        n = 0
        for seq, v, w, gap_v, gap_w in steps:
            if seq > e:
                break
            n += 1
            if v != v:
                unknown = True
            else:
                v_lo, v_hi = (v if v < v_lo else v_lo), (v if v > v_hi else v_hi)
                w_lo, w_hi = (w if w < w_lo else w_lo), (w if w > w_hi else w_hi)
            v_gap, w_gap = (gap_v if gap_v > v_gap else v_gap), (gap_w if gap_w > w_gap
                                                                 else w_gap)
        del steps[:n]
        if unknown:
            return (math.nan, math.nan, v_gap), (math.nan, math.nan, w_gap)
        return (v_lo, v_hi, v_gap), (w_lo, w_hi, w_gap)

    def _drop_to(self, e: int) -> None:
        steps = self._steps
        n = 0
        while n < len(steps) and steps[n][0] <= e:
            n += 1
        del steps[:n]
        self._folded = (EMPTY, EMPTY)

    @property
    def wrong(self) -> bool:
        """A speed was found beyond its band (latched; withdrawn from a conflict: ``follow``)."""
        self._until_s()
        return self.max_linear_excess_mps > 0.0 or self.max_angular_excess_rad_s > 0.0

    def verdict(self) -> list[str]:
        """Why the speeds are wrong (empty: they are not)."""
        if not self.wrong:
            return []
        return [f"ODOM_TWIST outside the reference's speeds by up to "
                f"{self.max_linear_excess_mps * 1e3:.3g} mm/s, "  # as analyze's verdict
                f"{self.max_angular_excess_rad_s * 1e3:.3g} mrad/s"]

    def as_dict(self) -> dict[str, Any]:
        """``twist`` in ``monitor --json`` and the bridge's ``status``."""
        return {"samples": self.samples, "suspended": self.suspended,
                "max_linear_excess_mps": self.max_linear_excess_mps,
                "max_angular_excess_rad_s": self.max_angular_excess_rad_s,
                "passed": not self.wrong}
