"""The live judge's poses and their errors (``host.judge.tracking``): a pose at the encoder frame
it names, a sample, the step gate that refuses implausible encoder steps as the firmware does, and
the running error statistics."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple, overload

from odocan.firmware.encoders import (
    CTRL_UPTIME_MAX,
    RESTART_SLACK_PERIODS,
    RESYNC_FRAMES,
)
from odocan.host.judge.ambiguity import least_ambiguous_periods
from odocan.host.judge.ctrlrestart import in_window
from odocan.host.judge.livewindow import CYCLE_S, Counted
from odocan.host.judge.nearthreshold import NEAR_DETAIL, near
from odocan.host.judge.reference import Geometry, wrap_delta
from odocan.host.judge.reference_path import restart_detail
from odocan.host.judge.turns import unwrapped_error
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_PERIODS_PER_S as PERIODS_PER_S
from odocan.host.protocol.pose import heading_fields, unwrap_near
from odocan.sim.pose import wrap_angle

RING = busfacts.ENC_COUNTER_LAP  # 16: one slot per E2E COUNTER value of WHEEL_ENCODERS
RING_MASK = RING - 1  # 0xF: a COUNTER step mod the lap
MARKS_KEPT = 128  # pairs ``ErrorStats.withdraw_from`` can take back: a reboot's boot window
# (``bootticks.BOOT_WINDOW_MS``, 80 ms: 4 poses), and the poses of a firmware that rebooted in
# a silence heard until its summary told it (``livesilentboot``: up to 2 s, 100 poses)
WIRE_BITS = busfacts.ENC_WIRE_COUNTER_BITS  # WHEEL_ENCODERS carries the low 24 bits of each counter
WIRE_MASK = (1 << WIRE_BITS) - 1
# ``step_periods.doubted_bound_periods``: frames closer than half a period share one burst's
# doubt; a burst a period and a half or more after the frame before has one
HALF_CYCLE_S = 0.5 * CYCLE_S
DOUBTED_GAP_S = 1.5 * CYCLE_S


class Sample(NamedTuple):
    """An on-board sample settled: the pose, the reference at its encoder frame (None when
    unknown), the ENC_COUNTER it names, its ODOM_POSE_X's COUNTER and its ODOM_POSE_Y's bus
    time (s)."""

    pose: FramePose
    reference: FramePose | None
    enc_counter: int
    counter: int
    t_s: float


Held = tuple[tuple[int, int, int], int, int, float]  # (COUNTER, left, right), seq, uptime, t (s)


class StepGate:
    """The firmware's plausibility rule on the reference's steps (firmware/ecu.py, the same as
    ``host.judge.analysis``): a frame beyond the robot's maximum wheel speed
    (``Geometry.max_wheel_speed_mm_s``) over the periods its COUNTER advanced since the last
    accepted one is refused; ``RESYNC_FRAMES`` refused frames plausible
    among themselves are a counter restart: one step from the first of them, never the jump; a
    frame whose CTRL_UPTIME is below the last accepted one's (both non-zero), or below what it
    aged to over a silence (``aged``) when it is not that one's E2E successor (a successor may
    have waited behind the silence), is held: if the next frame confirms it
    (firmware/restarthold.py: CTRL_UPTIME the same or one more, its counts young and within the
    bound of the held frame's over their COUNTER advance) the reference re-primes on the held
    frame (the motor controller restarted) and steps from it to the next; else the held frame is
    refused and the next judged against the last accepted one; a frame whose step from the
    last accepted one is ambiguous (its periods' bound reaches half the counters' range,
    ``ambiguity``) re-primes it. Each restart is told to ``told``."""

    def __init__(self, geometry: Geometry, counter_bits: int, told: RestartLog) -> None:
        self.bound = (0, 0)  # counts per period, left and right (``rebound``)
        self.least = 1  # the fewest periods of an ambiguous step (``rebound``)
        self.bits = counter_bits
        # ``wrap_delta``'s at this width, in line per step (``& mask``: ``% 2^bits`` on ints)
        self._half, self._mask = 1 << (counter_bits - 1), (1 << counter_bits) - 1
        self.rebound(geometry)
        self.prev: tuple[int, int, int] | None = None  # counter, left, right of the last accepted
        self._refused: list[tuple[int, int, int]] = []
        self._seq = self._prev_seq = 0  # periods heard, at the latest frame and at ``prev``
        self.counter_restarts = 0
        self.uptime = 0  # CTRL_UPTIME of the last accepted frame (0: not reported)
        self._prev_t = 0.0  # its bus time (s)
        self._told = told
        self._held: Held | None = None  # a restart's first frame, until the next confirms it
        # the last accepted frame's bus time and ``step_periods.doubt_origin_s`` (-1.0: nothing
        # to doubt)
        self._doubt: tuple[float, float] = (0.0, -1.0)

    def rebound(self, geometry: Geometry) -> None:
        """Gate the next frames with ``geometry``'s speed bound (the firmware's, from its PROFILE
        page): the frames accepted so far stay, the next one is judged against the last of them
        over the periods since."""
        self.bound = geometry.period_counts(geometry.max_wheel_speed_mm_s)
        self.least = least_ambiguous_periods(self.bound, self.bits)

    def _delta(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> tuple[int, int]:
        half, mask = self._half, self._mask
        return ((b[1] - a[1] + half) & mask) - half, ((b[2] - a[2] + half) & mask) - half

    def _young(self, frame: tuple[int, int, int], uptime: int) -> bool:
        """The counts a controller ``uptime`` seconds old can have run from 0 (a restart's)."""
        bits, periods = min(self.bits, 24), uptime * PERIODS_PER_S
        return (abs(wrap_delta(frame[1], bits)) <= periods * self.bound[0]
                and abs(wrap_delta(frame[2], bits)) <= periods * self.bound[1])

    def _plausible(self, a: tuple[int, int, int], b: tuple[int, int, int]) -> bool:
        periods = ((b[0] - a[0]) % RING) or RING
        d = self._delta(a, b)
        return abs(d[0]) <= periods * self.bound[0] and abs(d[1]) <= periods * self.bound[1]

    def step(self, heard_frame: Counted) -> tuple[int, int] | None:
        """The count step to integrate for this frame (``livewindow.Counted``: its seq, COUNTER,
        counts, the periods since the frame heard before, ``samples.sender_seq``'s, widened by
        the bus times past 16 periods, its CTRL_UPTIME and bus time); None when it primes or is
        refused, (0, 0) when it re-primes on a controller restart."""
        seq, counter, left, right, heard, uptime, t_s = heard_frame
        self._seq += heard
        if self.bits < WIRE_BITS and ((left | right) & WIRE_MASK) >> self.bits:
            return None  # beyond the counters' width: refused outright (lossgate.beyond_width)
        frame = (counter, left, right)
        if self._held is not None and self._confirms(self._held, frame, uptime):
            return self._confirmed(self._held, frame, uptime, t_s)
        self._held = None  # refused, if one was held: this frame is judged on its own
        prev, self.prev = self.prev, frame
        prev_seq, self._prev_seq = self._prev_seq, self._seq
        last_uptime, self.uptime = self.uptime, uptime
        last_t, self._prev_t = self._prev_t, t_s
        doubt = self._doubt
        origin_t = doubt[1]
        self._doubt = (t_s, _taken_origin(t_s, *doubt) if prev else -1.0)
        if prev is None:
            return None
        if uptime and last_uptime and (uptime < last_uptime or (
                t_s - last_t > AGED_AFTER_S and (counter - prev[0]) & RING_MASK != 1  # not waited
                and uptime < aged(last_uptime, t_s - last_t))) \
                and in_window(counter - prev[0], t_s - last_t, CYCLE_S) \
                and self._young(frame, uptime):
            self.prev, self._prev_seq, self.uptime = prev, prev_seq, last_uptime  # held
            self._prev_t, self._doubt = last_t, doubt
            self._held = (frame, seq, uptime, t_s)
            return None
        periods = self._seq - prev_seq
        if periods + RING >= self.least and near(  # (a plain test first: it runs per frame)
                ((counter - prev[0]) & RING_MASK) or RING, t_s - last_t, CYCLE_S, self.least):
            self._told.near_threshold(seq, t_s)  # either decision: a new start (nearthreshold)
        if periods >= self.least and not self._taken(last_t, t_s):  # ambiguous: re-primed
            return self._ambiguous(seq, (last_t, t_s), hole=heard > 1,
                                   taken=self._delta(prev, frame))
        half, mask = self._half, self._mask  # ``_plausible`` and ``_delta`` in line (per frame)
        d_left, d_right = ((left - prev[1] + half) & mask) - half, (
            (right - prev[2] + half) & mask) - half
        bound = self.bound
        if (abs(d_left) <= periods * bound[0] and abs(d_right) <= periods * bound[1]) or (
                origin_t >= 0.0 and self._doubted(periods, t_s - origin_t, d_left, d_right)):
            if self._refused:
                self._refused = []
            return d_left, d_right
        self.prev, self._prev_seq, self.uptime = prev, prev_seq, last_uptime  # refused: kept
        self._prev_t, self._doubt = last_t, doubt
        consistent = bool(self._refused) and self._plausible(self._refused[-1], frame)
        self._refused = [*self._refused, frame] if consistent else [frame]
        if len(self._refused) < RESYNC_FRAMES:
            return None
        first, self._refused, self.prev, self.uptime = self._refused[0], [], frame, uptime
        self._prev_seq, self._prev_t = self._seq, t_s  # the next step counts from this frame
        self._doubt = (t_s, _taken_origin(t_s, *doubt))
        self._restarted(seq, t_s, by_uptime=False)
        return self._delta(first, frame)

    def _doubted(self, periods: int, since_s: float, d_left: int, d_right: int) -> bool:
        """Whether a step the bound refused over ``periods`` lies within it over the periods
        counted from the frame heard before the last accepted frame's burst (``since_s``
        before this one: that frame's sample may lie the silence before it back;
        ``step_periods.doubted_bound_periods``, the firmware's ``sampledoubt``)."""
        widened = periods + RING * max(0, math.floor(
            (round(since_s / CYCLE_S) - periods) / RING + 0.5))
        return abs(d_left) <= widened * self.bound[0] and abs(d_right) <= widened * self.bound[1]

    def _ambiguous(self, seq: int, span_s: tuple[float, float], *, hole: bool,
                   taken: tuple[int, int]) -> tuple[int, int]:
        """An ambiguous step into encoder frame ``seq`` (``ambiguity``; ``span_s``: the bus times
        of the last accepted frame and of this one) re-primes; behind a ``hole`` of the frames
        heard where no page told yet what the firmware took (``host.judge.evidenceless``) it
        may as well have taken them one by one (the step ``taken``): both are held until the
        pages or the next pose choose (``host.judge.livechoice``); when no choice can be held,
        the reference starts again from the next pose, or, pages of the life heard (they may
        prove the hole missed: ``LiveSeen.heard_in``), stays re-primed."""
        if hole and not self._refused and not self._told.choose(seq, span_s, taken) \
                and not self._told.heard_in(*span_s):
            self._told.owe(seq)
        self._refused = []
        self._restarted(seq, span_s[1], by_uptime=True, ambiguous=True)
        return 0, 0

    def _taken(self, a_s: float, b_s: float) -> bool:
        """Whether the firmware's pages prove it took frames between the last accepted frame
        (bus time ``a_s``) and this one (``b_s``), its longest step there below an ambiguous
        one (``holetaken``): the firmware did not re-prime, the gap is a gap."""
        longest = None if self._refused else self._told.through(a_s, b_s)
        return longest is not None and longest < self.least

    def _confirms(self, held: Held, frame: tuple[int, int, int], uptime: int) -> bool:
        """``frame`` (its CTRL_UPTIME ``uptime``) confirms the ``held`` restart frame
        (firmware/restarthold.py ``RestartHold.confirms``)."""
        first, _, held_uptime, _ = held
        bits, periods = min(self.bits, WIRE_BITS), (frame[0] - first[0]) & RING_MASK
        return (periods != 0 and held_uptime <= uptime <= held_uptime + 1
                and abs(wrap_delta(frame[1] - first[1], bits)) <= periods * self.bound[0]
                and abs(wrap_delta(frame[2] - first[2], bits)) <= periods * self.bound[1]
                and self._young(frame, uptime))

    def _confirmed(self, held: Held, frame: tuple[int, int, int], uptime: int,
                   t_s: float) -> tuple[int, int]:
        """Re-prime on the ``held`` frame (told at its seq and time), then one step from it."""
        first, seq, _, held_t = held
        self._held, self._refused = None, []
        self._restarted(seq, held_t, by_uptime=True)
        self._doubt = (t_s, _taken_origin(t_s, *self._doubt))
        self.prev, self._prev_seq, self.uptime, self._prev_t = frame, self._seq, uptime, t_s
        return self._delta(first, frame)

    def _restarted(self, seq: int, t_s: float, *, by_uptime: bool,
                   ambiguous: bool = False) -> None:
        self.counter_restarts += 1
        self._told.add(seq, t_s, by_uptime, ambiguous=ambiguous)


class RestartLog:
    """The counter restarts the live reference re-primed on, as ``analyze``'s
    ``counter_restart`` events (the same detail: ``reference_path.restart_detail``), appended to
    ``events`` (the monitor's, the bridge's); a frame stepped again (a reference started again
    over frames already gated) is told once."""

    def __init__(self, reprimed: Callable[[int, bool], bool | None]) -> None:
        """``reprimed``: called with the frame of each restart and whether CTRL_UPTIME told
        it; True: a new start after frames the host never heard (``host.judge.livedark``)."""
        self.events: deque[dict[str, Any]] = deque(maxlen=16)  # the owner's deque replaces it
        self._told = -1  # the latest encoder frame (seq) told
        self._reprimed = reprimed
        self.through: Callable[[float, float], int | None] = _unproven  # ``LiveSeen.through``
        self.owe: Callable[[int], None] = _owed  # ``livedark.DarkRestarts.owe``
        self.heard_in: Callable[[float, float], bool] = _unheard  # ``LiveSeen.heard_in``
        self.choose: Callable[[int, tuple[float, float], tuple[int, int]], bool] = _unchosen

    def near_threshold(self, seq: int, t_s: float) -> None:
        """A step within a period of the ambiguity threshold into encoder frame ``seq`` (bus
        time ``t_s``): the firmware may have decided either way and its word comes later, so
        the reference restarts from the next on-board pose (``owe``), told as an event."""
        self.owe(seq)
        self.events.append({"t_s": t_s, "kind": "near_threshold", "encoder_frame": seq,
                            "detail": NEAR_DETAIL})

    def add(self, seq: int, t_s: float, by_uptime: bool, *, ambiguous: bool = False) -> None:
        """A restart on encoder frame ``seq`` at bus time ``t_s`` (``by_uptime``: nothing
        integrated into it; ``ambiguous``: a step too long to read, ``ambiguity``)."""
        unseen = bool(self._reprimed(seq, by_uptime))
        if seq <= self._told:
            return
        self._told = seq
        self.events.append({"t_s": t_s, "kind": "counter_restart", "encoder_frame": seq,
                            "detail": restart_detail(by_uptime, unseen, ambiguous=ambiguous)})


def _owed(_seq: int) -> None:
    """No new start to owe (``RestartLog.owe``: a gate of its own)."""


def _unchosen(_seq: int, _span_s: tuple[float, float], _taken: tuple[int, int]) -> bool:
    """No choice held (``RestartLog.choose``: ``livechoice.LiveChoice.open``): a new start."""
    return False


def _unheard(_a_s: float, _b_s: float) -> bool:
    """No pages: none heard in a hole (``RestartLog.heard_in``)."""
    return False


def _unproven(_a_s: float, _b_s: float) -> int | None:
    """No pages: nothing proven taken in a hole (``RestartLog.through``)."""
    return None


# below this silence ``aged`` is the last CTRL_UPTIME itself (the per-frame test skips it)
AGED_AFTER_S = (PERIODS_PER_S + RESTART_SLACK_PERIODS - 0.5) * CYCLE_S


def _taken_origin(t_s: float, last_t: float, last_origin_t: float) -> float:
    """``step_periods.doubt_origin_s`` of a frame taken at bus time ``t_s`` after the frame taken
    last (at ``last_t``, its own origin ``last_origin_t``): within half a period of it, in its
    burst, that one's origin; else that one's time after a silence of a period and a half or
    more (refused frames heard between do not count: the firmware counts from its last
    acceptance), -1.0 (nothing to doubt) after less."""
    gap_s = t_s - last_t
    if gap_s < HALF_CYCLE_S:
        return last_origin_t
    return last_t if gap_s >= DOUBTED_GAP_S else -1.0


def aged(uptime: int, elapsed_s: float) -> int:
    """``reference_path.aged_uptime`` of one step (plain Python: it runs per frame)."""
    periods = round(elapsed_s / CYCLE_S) - RESTART_SLACK_PERIODS
    if periods < PERIODS_PER_S:
        return uptime
    return min(CTRL_UPTIME_MAX, uptime + periods // PERIODS_PER_S)


def recent(entry: tuple[int, int, int] | None, enc_seq: int) -> tuple[int, int, int] | None:
    """A ring entry (seq, left, right) if it is one of the last 8 encoder frames up to
    ``enc_seq`` (not one 16 frames older)."""
    return None if entry is None or enc_seq - entry[0] >= RING // 2 else entry


def difference(a: FramePose, b: FramePose) -> dict[str, float]:
    """a - b: position (m), distance (m) and heading (rad): wrapped to (-pi, pi], plus 2 pi per
    whole turn the cumulative headings differ beyond it (``host.judge.turns``: a TURNS off)."""
    dx, dy = a.x_m - b.x_m, a.y_m - b.y_m
    d = a.heading_rad - b.heading_rad
    # within half a turn ``wrap_angle(d)`` is ``d`` itself (IEEE remainder by 2 pi, quotient 0:
    # exact; at pi the tie goes to the even quotient 0): no call per sample
    dheading = d
    if not -math.pi < d <= math.pi:  # beyond half a turn: TURNS may be off (else it is not)
        dheading = unwrapped_error(a.heading_rad, b.heading_rad, wrap_angle(d))
    return {"dx_m": dx, "dy_m": dy, "dpos_m": math.hypot(dx, dy), "dheading_rad": dheading}


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
    marks: deque[tuple[float, int, float, float]] = field(
        default_factory=lambda: deque(maxlen=MARKS_KEPT))  # before each of the latest added

    def add(self, a: FramePose, b: FramePose, t_s: float = math.nan) -> None:
        """Record ``a - b`` (position in m, heading wrapped to (-pi, pi] in rad); ``t_s``: its
        bus time (s), for ``withdraw_from``."""
        self.marks.append((t_s, self.samples, self.max_dpos_m, self.max_dheading_rad))
        self.latest = difference(a, b)
        self.samples += 1
        dpos_m, dheading_rad = self.latest["dpos_m"], abs(self.latest["dheading_rad"])
        if dpos_m > self.max_dpos_m:  # ``max`` written out (per sample)
            self.max_dpos_m = dpos_m
        if dheading_rad > self.max_dheading_rad:
            self.max_dheading_rad = dheading_rad

    def withdraw_from(self, t_s: float) -> None:
        """The pairs added from bus time ``t_s`` on were not one life's (a reboot told late,
        ``bootticks``: the new firmware's poses against the old life's reference): the counts
        and largest errors go back to before them, as far as ``MARKS_KEPT`` pairs back."""
        kept = [mark for mark in self.marks if mark[0] < t_s]
        gone = [mark for mark in self.marks if mark[0] >= t_s]
        if gone:
            _, self.samples, self.max_dpos_m, self.max_dheading_rad = gone[0]
            self.marks = deque(kept, maxlen=MARKS_KEPT)

    def as_dict(self) -> dict[str, Any] | None:
        """JSON form; None before the first sample."""
        if not self.samples:
            return None
        return {**self.latest, "max_dpos_m": self.max_dpos_m,
                "max_dheading_rad": self.max_dheading_rad, "samples": self.samples}


@overload
def pose_dict(pose: FramePose) -> dict[str, float]: ...


@overload
def pose_dict(pose: FramePose | None) -> dict[str, float] | None: ...


def pose_dict(pose: FramePose | None) -> dict[str, float] | None:
    """JSON form: ``x_m``, ``y_m``, ``heading_rad`` in (-pi, pi], ``heading_unwrapped_rad``."""
    if pose is None:
        return None
    return {"x_m": pose.x_m, "y_m": pose.y_m, **heading_fields(pose.heading_rad)}


def truth_heading(wrapped_rad: float, near: FramePose | None) -> float:
    """SIM_TRUTH's HEADING ([0, 2 pi) on the bus) made cumulative: the turn nearest ``near``
    (the reference at that encoder frame, else the previous truth), else wrapped (rad)."""
    return wrap_angle(wrapped_rad) if near is None else unwrap_near(wrapped_rad, near.heading_rad)
