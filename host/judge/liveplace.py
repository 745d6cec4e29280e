"""The live judge's placement of the reference after a firmware stall or hold
(``host.judge.tracking``), bounded as ``analyze`` bounds it (``host.judge.breaks``): the position
moves to where the firmware is, no further from where the reference started than the stalls'
merge allowances since plus the tolerance. A gap of the encoder sequence (frames the judge
did not hear, which the firmware may have integrated one by one) places it again too, within
its ``gapbound`` allowance, as ``analyze`` places it; or twice the merge allowance over its
frames when every frame it lacks was heard refused by E2E (``gapfill``; ``livefill``; a stall's
span holding such gaps: ``spanfill``). A part of the latest placement that the firmware's pages
later prove it took as the reference did (``host.judge.livegapseen``) has its allowance
withdrawn (``withdraw``) from the budgets and its step's bound, as ``analyze`` gives it none
(issue #11: a pose raised 10 mm at a 12.4 mm gap PASSed live, withdrawn from the budgets only).
Each placement's step from the one before is bounded too, by its own parts' allowances
(``breaks.placed_step``); a gap placed before its held-back frame was heard takes the fill's
allowance for its step when the frame comes (``_refill``), as ``analyze``, which knows the
frames past the sample, bounds it. A placement never leaves the sample closer to the reference
than the firmware's own poses and the frames the bus carried prove it off (``_narrow``,
``host.judge.liveholdstep``): the live E2E model, which decides each frame before the poses that
prove it wrong are heard, can make gaps the firmware never had."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from odocan.host.judge.breaks import (
    BreakSummary,
    clamp_offset,
    merge_allowance_m,
    merged_breaks,
    overlap_allowance_m,
    path_bound_m,
    placed_step,
    step_slack_m,
)
from odocan.host.judge.gapfill import Counts, gap_or_fill_allowance
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.livedark import DarkRestarts
from odocan.host.judge.livefill import LiveFill
from odocan.host.judge.livegapseen import LiveSeen
from odocan.host.judge.livegapskips import LiveGapSkips
from odocan.host.judge.liveholdstep import BusOrder, excess_m
from odocan.host.judge.livelosses import LiveAllowance
from odocan.host.judge.livepagelaps import page_laps
from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livewindow import CYCLE_S, Columns, window_holes
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound
from odocan.host.judge.samples import POSITION_LSB_M, sender_seq
from odocan.host.judge.senderseq import pose_skips
from odocan.host.judge.spanfill import filled_span_allowance_m
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP

ABS_KEPT = 128  # the latest encoder frames whose count-step sums are kept (a sample names one)
GAPS_KEPT = 64  # gaps of the encoder sequence kept between two placements (no growth)
REPRIMED_KEPT = 64  # counter restarts kept (no page proves a span across one)
PARTS_KEPT = 64  # placements' gaps and stalls waiting for the pages (older ones keep theirs)
LAP = ENC_COUNTER_LAP  # the encoder COUNTER's lap: a step of more periods took one from the stamps
MASK = LAP - 1  # 0xF: a COUNTER step mod the lap


Gap = tuple[int, tuple[int, int], tuple[int, int], int]  # seq after, counts before, after, periods
Part = tuple[bool, int, int, float, int]  # a placement's gap (True: seq after) or stall (its
# span): first and last frame, the allowance it added (m), the placement's frame


def _confirmed(gaps: list[Gap], window: Columns, halves: Columns | None,
               seen: LiveSeen | None = None) -> list[Gap]:
    """The gaps still gaps by ``samples.sender_seq`` over the window from the frame before the
    frame before each (the frames heard since tell a burst after a busy bus, whose first frame
    only looked 16 periods late, from frames lost; and a frame stamped late before it, alone
    below its neighbours' level, whose lap is this step's: ``senderseq.late_lone_frames``), a
    gap the stamps gave a lap (over 16 periods) raised by the laps the pages ``seen`` prove
    (``livepagelaps``); a gap whose frames left the window is kept as heard."""
    if not gaps:
        return gaps
    kept = []
    for gap in gaps:
        numbered = None if gap[3] < 0 else window_step(window, halves, gap[0])
        if numbered is None:
            kept.append(gap)
            continue
        periods = numbered
        if gap[3] > LAP and seen is not None:  # a lap of the stamps: the pages may number it
            periods += LAP * page_laps(window, halves, seen, gap[0])
        if periods > 1:
            kept.append((gap[0], gap[1], gap[2], periods))
    return kept


def window_step(window: Columns, halves: Columns | None, seq: int) -> int | None:
    """The periods ``samples.sender_seq`` numbers over the window, from the frame before the
    frame before it, for the step into encoder frame ``seq``; None when the frame before it
    left the window."""
    seqs = window.col("seq")
    i = int(np.searchsorted(seqs, seq - 1))
    if i >= len(seqs) - 1 or int(seqs[i]) != seq - 1:
        return None
    j = max(i - 1, 0)  # the frame before: its lap may be this step's (late_lone_frames)
    numbered = sender_seq(window.col("counter")[j:].astype(np.int64), window.col("t_s")[j:],
                          CYCLE_S, window_holes(window, halves, j))
    return int(numbered[i - j + 1] - numbered[i - j])


class StallPlacer:
    """The placements of one reference (``restart`` with it) and what they absorbed."""

    def __init__(self) -> None:
        self.position_tolerance_m = POSITION_LSB_M  # the slack of a placement after a stall
        self.halves: Columns | None = None  # the tracker's ODOM_POSE_X halves (its holes)
        self.placements = BreakSummary()  # what this reference's placements absorbed
        self._breaks_before = BreakSummary().as_dict()  # ... the references' before it (merged)
        self._shift = (0.0, 0.0)  # the placements' offset of the reference since its start (m)
        self._budget_m = 0.0  # the stalls' merge allowances summed since its start (m)
        # per recent frame (seq mod ABS_KEPT): its seq and the |count steps| summed up to it
        self._abs_ring = [(-1, -1, -1)] * ABS_KEPT  # a list: one store per frame, no numpy
        self._abs_counts = (0, 0)  # ... up to the latest encoder frame
        self._abs_last: tuple[int, int] | None = None  # ... at the last sample compared
        self.stalled = False  # a stall or hold since the last placement (the tracker sets it)
        self._gaps: list[Gap] = []  # since then
        self.max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED  # the gaps' bound
        self.periods = 1  # encoder periods from the frame heard before to the latest
        self.lapped = False  # ... more than a lap (16): the stamps gave it one (livelaphold)
        self.moved = 0  # ... of which the lap of the step before it (``_moved``)
        self._was_lapped = False  # ``lapped`` of the frame before the latest
        self._before: tuple[float, ...] | None = None  # the window's row before the latest
        self.seen = LiveSeen()  # what the firmware's pages prove it took (its life's)
        self.skips = LiveGapSkips()  # the latest frames' counts: a gap the pages prove (gapskips)
        self.dark = DarkRestarts()  # restarts after the input went dark (host.judge.livedark)
        self._reprimed: tuple[int, ...] = ()  # the latest counter restarts re-primed on
        self._parts: list[Part] = []  # the placements' parts whose allowance pages may withdraw
        # the latest placements: frame, the offset its sample asked (from the reference then),
        # the step it made, the budget then, its step's bound, its offset asked (m), by a gap
        self._history: list[list[float]] = []
        self.losses: LiveAllowance | None = None  # the tracker's: samples judged again
        self._owed = (0.0, 0.0)  # the offset withdrawn, not applied yet (m)
        self.withdrawn = 0  # placements whose allowance the pages withdrew
        self.fill = LiveFill()  # the refused frames heard, by sender number (gapfill)
        # per recent gap (seq after; the latest GAPS_KEPT, placed or not: a stall's span may
        # hold one placed before it): the sender number before, its periods
        self._gap_sender: dict[int, tuple[int, int]] = {}
        self.fill.heard = self._refill  # a frame heard late may fill a gap placed already
        self.bus = self.fill.bus = BusOrder(CYCLE_S)  # the frames heard, in bus order
        # gaps placed before their frames were all heard: seq after -> (sender number before,
        # counts before, after, periods, the placement's frame, the bound's arguments)
        self._unfilled: dict[int, tuple[int, Gap, int, tuple[Geometry, int, str]]] = {}

    def restart(self) -> None:
        """A new reference: no offset, no allowance yet, no placement (``watch_breaks``)."""
        self._breaks_before, self.placements = self.watch_breaks(), BreakSummary()
        self._shift, self._budget_m = (0.0, 0.0), 0.0
        self.stalled, self._gaps, self._parts, self._owed = False, [], [], (0.0, 0.0)
        self._history = []
        self._unfilled = {}
        self._gap_sender = {}
        self.bus.restart()

    def watch_breaks(self) -> dict[str, Any]:
        """``reference_breaks`` of the watch: every reference's placements (merged)."""
        return merged_breaks([self._breaks_before, self.placements.as_dict()])

    def on_encoders(self, seq: int, frame: tuple[int, int, int, float],
                    prev: tuple[float, ...] | None, bits: int) -> bool:
        """``_on_encoders``, and the frame to ``seen``."""
        gap = self._on_encoders(seq, frame, prev, bits)
        self._before = prev
        self.skips.heard(seq, self.fill.sender, frame[1], frame[2])
        self.bus.heard(seq, frame[0], frame[1], frame[2], frame[3])  # (by position: per frame)
        periods = self.periods - self.moved  # the stamps' numbering: sums kept
        self.seen.on_encoders(seq, frame[3], periods)
        if self.dark.dark:  # (else ``on_encoders`` has nothing to note: no dark gap)
            self.dark.on_encoders(seq, periods)
        return gap

    def _moved(self, periods: int, frame: tuple[int, int, int, float],
               prev: tuple[float, ...]) -> int:
        """``periods`` (the stamps' numbering of the step from ``prev``, the window's row of the
        frame before, to ``frame``) with the lap of the step before it when that one's frame
        lies alone below its neighbours' level (``senderseq.late_lone_frames`` over the three
        frames: the frames after it, which ``analyze`` reads too, are not heard yet; the samples
        wait for them, ``host.judge.livelaphold``). The gate steps this frame with it (a frame
        stamped 13 periods late before a chunk of 20 left 4 periods for the chunk: the gate
        refused its frames and re-primed, 0.47 m); ``moved``: the periods added."""
        before, self.moved = self._before, 0
        if not self._was_lapped or before is None or int(before[0]) != int(prev[0]) - 1:
            return periods  # (only a lap of the step before can move: no arrays per frame)
        counter, t_s = np.array([int(before[2]), int(prev[2]), frame[0]]), np.array(
            [float(before[3]), float(prev[3]), frame[3]])
        holes = np.zeros(2, dtype=bool)
        if self.halves is not None:
            holes[0] = pose_skips(np.array([int(before[1]), int(prev[1])]),
                                  self.halves.col("pos").astype(np.int64),
                                  self.halves.col("counter").astype(np.int64))[0]
        step = np.diff(sender_seq(counter, t_s, CYCLE_S, holes))
        self.moved = max(0, int(step[1]) - periods)
        return periods + self.moved

    def _on_encoders(self, seq: int, frame: tuple[int, int, int, float],
                     prev: tuple[float, ...] | None, bits: int) -> bool:
        """Encoder frame ``seq`` (``frame``: COUNTER, counts left and right, bus time s;
        ``prev``: the window's row of the frame before: seq, pos, COUNTER, time, left, right).
        True after a gap of the sender's sequence (``samples.sender_seq``): the reference is to
        be placed again at the next sample."""
        counter, left, right, t_s = frame
        self._was_lapped = self.lapped
        self.periods, self.lapped, self.moved = 1, False, 0
        if prev is None:
            self._abs_ring[seq % ABS_KEPT] = (seq, *self._abs_counts)
            self.fill.accepted(1, counter, t_s)
            return False
        (abs_left, abs_right), half, wrap = self._abs_counts, 1 << (bits - 1), 1 << bits  # wrap
        abs_left += abs((left - int(prev[4]) + half) % wrap - half)
        abs_right += abs((right - int(prev[5]) + half) % wrap - half)
        self._abs_counts, self._abs_ring[seq % ABS_KEPT] = (abs_left, abs_right), (  # a fixed
            seq, abs_left, abs_right)  # ring: no growth (``wrap_delta`` in line, per frame)
        periods = (counter - int(prev[2])) & MASK
        if periods == 1 and t_s - float(prev[3]) < 8.0 * CYCLE_S:
            self.fill.accepted(1, counter, t_s)
            return False  # the next frame (the fast path: no arrays)
        periods = int(sender_seq(np.array([int(prev[2]), counter]),
                                 np.array([float(prev[3]), t_s]), CYCLE_S)[1])
        self.periods = self._moved(periods, frame, prev)
        self.lapped = self.periods > LAP
        sender_before = self.fill.sender
        self.fill.accepted(periods, counter, t_s)
        if periods <= 1:
            return False
        if len(self._gaps) < GAPS_KEPT:  # more before a sample: no bound (free, counted)
            self._gaps.append((seq, (int(prev[4]), int(prev[5])), (left, right), periods))
            self._gap_sender[seq] = (sender_before, periods)
            if len(self._gap_sender) > GAPS_KEPT:
                del self._gap_sender[next(iter(self._gap_sender))]  # the oldest
        else:
            self._gaps[-1] = (seq, (0, 0), (0, 0), -1)
        return True

    def reprimed(self, seq: int, by_uptime: bool = True) -> bool:
        """The reference re-primed on encoder frame ``seq`` (a counter restart): no page proves
        a span across it (``gapseen.Seen``'s ``reprimed``). A controller restart told by
        CTRL_UPTIME (``by_uptime``): a gap that ends there carried no motion on board (the
        firmware integrates nothing across it), so it allows no placement
        (``reference_path``'s rule)."""
        self._reprimed = (*self._reprimed[-REPRIMED_KEPT + 1:], seq)
        if by_uptime:
            self._gaps = [gap for gap in self._gaps if gap[0] != seq]
        return self.dark.restarted(seq, by_uptime, self.seen)  # a new start (livedark)

    @property
    def reprimed_frames(self) -> frozenset[int]:
        """The latest counter restarts re-primed on (``gapseen.Seen``'s ``reprimed``)."""
        return frozenset(self._reprimed)

    def gap_at(self, seq: int) -> Gap | None:
        """The gap (since the last placement) that ends at encoder frame ``seq``, if any."""
        return next((gap for gap in self._gaps if gap[0] == seq), None)

    def took_gap(self, gap: Gap) -> None:
        """A gap ``reprimed`` left out was taken after all (``host.judge.livechoice``): a
        placement part again, with its allowance."""
        if gap[0] not in {g[0] for g in self._gaps}:
            self._gaps = sorted([*self._gaps, gap])

    def compared(self, pose: FramePose) -> None:
        """The on-board sample ``pose`` was compared."""
        self._abs_last = self._abs_at(pose.seq)
        self.bus.last_pose = pose

    def _abs_at(self, seq: int) -> tuple[int, int] | None:
        """The |count steps| summed up to encoder frame ``seq``, None when no longer kept."""
        kept_seq, abs_left, abs_right = self._abs_ring[seq % ABS_KEPT]
        return (abs_left, abs_right) if kept_seq == seq else None

    def shift(self, pose: FramePose, ref: FramePose, last_compared: int, window: Columns,
              reference: tuple[Geometry, int, str],
              folded: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float] | None:
        """How far (dx, dy m) to move the reference's position so that it starts again where
        the firmware is (``pose`` against ``ref``), bounded (module docstring): the merge
        allowance from ``last_compared`` to ``pose`` (``reference``: geometry, counter bits,
        integrator) joins the budget after a stall, and each gap's since (``gapbound``). None:
        nothing to place (no stall, and the gaps suspected were a burst after a busy bus).
        ``folded``: what the fit anchored at the previous placement moved the reference by
        (``livefit.LiveFit.placed_shift_m``), taken into it with this placement
        (``livefit.rebase``): counted in the placements' offset, so the bound is on the offset
        from the reference as started, as ``breaks.bound_offsets`` bounds it (uncounted, up to
        half an LSB on each axis per placement walked the reference away: 0.24 mm after 20
        stalls of a correct firmware's loaded capture, beyond a budget of 0)."""
        geometry, bits, integrator = reference
        stalled, parts, self.skips.reference = self.stalled, [], reference
        if stalled:
            allowance = self._allowance_m(last_compared, pose.seq, window, reference)
            parts.append((False, last_compared, pose.seq, allowance, pose.seq))
        later = [gap for gap in self._gaps if gap[0] > pose.seq]  # after a held sample's
        gaps = _confirmed([gap for gap in self._gaps if gap[0] <= pose.seq], window,
                          self.halves, self.seen)  # frame (livelaphold): the next sample's
        self._gaps, self.stalled = later, False
        sx, sy = self._shift[0] - self._owed[0], self._shift[1] - self._owed[1]  # applied
        owed, self._owed = self._owed, (0.0, 0.0)
        if not gaps and not stalled and owed == (0.0, 0.0):  # a burst after a busy bus, not a
            return None  # gap: nothing to place (and nothing of the fit taken into it)
        self._shift = (self._shift[0] + folded[0], self._shift[1] + folded[1])
        sx, sy = sx + folded[0], sy + folded[1]
        if not gaps and not stalled:
            return owed  # an allowance withdrawn
        for seq, before, after, periods in gaps:
            sender = self._gap_sender.get(seq)
            filled = self.fill.fill(sender[0], periods) if sender and periods > 1 else None
            if filled is None and sender and periods > 1:
                self._unfilled = dict(list(self._unfilled.items())[1 - PARTS_KEPT:])
                self._unfilled[seq] = (sender[0], (seq, before, after, periods), pose.seq,
                                       reference)
            parts.append((True, seq, seq, math.inf if periods < 0 else gap_or_fill_allowance(
                filled, before, after, periods, geometry, bits, integrator,
                self.max_wheel_speed_mm_s), pose.seq))
        step_m = sum(part[3] for part in parts)  # this placement's parts (its step's bound)
        self._budget_m += step_m
        want_x, want_y = sx + pose.x_m - ref.x_m, sy + pose.y_m - ref.y_m
        self._parts = (self._parts + parts)[-PARTS_KEPT:]
        limit = self._budget_m + self.position_tolerance_m
        if math.isinf(limit):  # no bound known (a stall left the window, 64 gaps): free
            self.placements.free += 1
        else:
            add = self.placements.add_gap if gaps else self.placements.add_stall
            add(math.hypot(want_x, want_y), limit)
        px, py = self._shift  # the placement before, as made again (an owed part folded in)
        self._shift = placed_step(self._shift, clamp_offset(want_x, want_y, limit),
                                  (want_x, want_y),
                                  step_m + step_slack_m(self.position_tolerance_m),
                                  self.placements)
        self._history = [*self._history[1 - PARTS_KEPT:], [
            pose.seq, want_x - px, want_y - py, self._shift[0] - px, self._shift[1] - py,
            self._budget_m, step_m, math.hypot(want_x, want_y), float(bool(gaps))]]
        self._narrow(pose, (want_x, want_y), reference)
        return self._shift[0] - sx, self._shift[1] - sy

    def _narrow(self, pose: FramePose, want: tuple[float, float],
                reference: tuple[Geometry, int, str]) -> None:
        """Keep the placed reference at least the error the firmware's own poses and the bus
        prove (``liveholdstep``) away from ``pose``: the sample is judged by the larger of the
        two (``want``: the offset that would put the reference on the pose, m)."""
        before = self.bus.last_pose
        halves = None if self.halves is None else list(zip(
            self.halves.col("enc_counter").astype(int).tolist(),
            self.halves.col("t_s").tolist(), strict=True))
        chain = None if before is None else self.bus.chain(before.seq, pose.seq, halves)
        if before is None or chain is None or any(
                before.seq < seq <= pose.seq for seq in self._reprimed):
            return
        excess = excess_m(before, pose, chain, reference)
        rest_x, rest_y = want[0] - self._shift[0], want[1] - self._shift[1]
        rest = math.hypot(rest_x, rest_y)
        if excess <= rest:
            return
        unit_x, unit_y = (rest_x / rest, rest_y / rest) if rest > 0.0 else (1.0, 0.0)
        self._shift = (want[0] - unit_x * excess, want[1] - unit_y * excess)

    def withdraw(self, seen: Seen) -> bool:
        """The parts of the placements (since the reference started, the latest
        ``PARTS_KEPT``) that ``seen`` proves the firmware took as the reference did (a gap it
        missed too, a stall over which it took exactly the log's frames: ``gapseen.Seen``) lose
        their allowance: the budget of every placement from theirs on shrinks by it, and each
        is clamped again within it, as ``breaks.bound_offsets`` places them (``_replace``). A
        gap inside a run it received exactly and refused ``m`` of (``livegapskips``) is lowered
        to ``gapskips``' allowance, in the budgets and its step's bound, as ``analyze`` bounds
        it. True when the reference is to move at the next sample."""
        reprimed = frozenset(self._reprimed)
        proven = [part for part in self._parts if not math.isinf(part[3]) and (
            seen.gap_missed(part[1], reprimed) if part[0]
            else seen.took_all(part[1] - 1, part[2], reprimed))]
        self._parts = [part for part in self._parts if part not in proven]
        self.skips.fill, self.skips.speed = self.fill, self.max_wheel_speed_mm_s  # (received)
        skipped = self.skips.lowered(self._parts, seen, reprimed)
        if not proven and not skipped:
            return False
        for part in proven:  # in the budgets and its step's bound, as analyze gives it none
            self._lower(part, part[3], part[3])  # (module docstring)
        for part, allowance_m in skipped:  # kept, with its allowance lowered
            self._parts[self._parts.index(part)] = (*part[:3], allowance_m, part[4])
            self._lower(part, part[3] - allowance_m, part[3] - allowance_m)
        self._replace()
        self.withdrawn += 1
        return self.owed

    def _lower(self, part: Part, by_m: float, step_by_m: float) -> None:
        """The allowance of a placement's ``part`` lowered: by ``by_m`` in the budget of every
        placement from its own on, by ``step_by_m`` in its own step's bound (``_replace``
        places them again)."""
        self._budget_m -= by_m
        for placed in self._history:
            placed[5] -= by_m if placed[0] >= part[4] else 0.0
            placed[6] -= step_by_m if placed[0] == part[4] else 0.0

    def _refill(self) -> None:
        """A refused frame was heard (``LiveFill.heard``): a gap placed before every frame it
        lacks was heard, now filled, takes ``gapfill``'s allowance over its known counts instead
        of ``gapbound``'s (the whole-log judge's, which knows the frames held back past the
        sample), and its placement is made again within it (``_replace``): a firmware that
        moved at such a gap is not absorbed by the worst split of a travel the log knows."""
        lowered = False
        for seq, (sender, gap, at, reference) in list(self._unfilled.items()):
            filled = self.fill.fill(sender, gap[3])
            if filled is None:
                continue
            del self._unfilled[seq]
            part = next((p for p in self._parts if p[0] and p[1] == seq and p[4] == at), None)
            if part is None:
                continue
            allowance = gap_or_fill_allowance(filled, gap[1], gap[2], gap[3], *reference,
                                              self.max_wheel_speed_mm_s)
            if allowance < part[3]:  # the step's bound only: the budget from the start keeps
                # it (the live offset from the start holds the start fit's corrections too)
                self._lower(part, 0.0, part[3] - allowance)
                lowered = True
        if lowered:
            self._replace()

    def _replace(self) -> None:
        """Each placement kept made again, in order, within its budget now: the offset its
        sample asked, less what the placements before it moved less, clamped (each step
        bounded, not the offset from the start: the start fit's corrections taken into the
        reference at each placement, within a pose's rounding, are not the placements'). The
        samples judged from each to the next are judged again by how much less the reference
        moved (``livelosses.LiveAllowance.rejudge``); the latest's difference is owed: the
        reference moves by it at the next sample (``shift``)."""
        less_x, less_y = 0.0, 0.0  # how much less the placements so far moved the reference
        for k, placed in enumerate(self._history):
            seq, asked_x, asked_y, old_x, old_y, budget_m, step_m, want_m, by_gap = placed
            self.placements.rebound(want_m, by_gap > 0.0, budget_m + self.position_tolerance_m)
            asked_x, asked_y = asked_x - less_x, asked_y - less_y
            new_x, new_y = clamp_offset(asked_x, asked_y, min(
                budget_m + self.position_tolerance_m,
                max(0.0, step_m) + step_slack_m(self.position_tolerance_m)))
            placed[1:5] = asked_x, asked_y, new_x, new_y
            less_x, less_y = less_x + new_x - old_x, less_y + new_y - old_y
            until = int(self._history[k + 1][0]) if k + 1 < len(self._history) else None
            if self.losses is not None and (less_x, less_y) != (0.0, 0.0):
                self.losses.rejudge(int(seq), until, (less_x, less_y))
        self._owed = (self._owed[0] + less_x, self._owed[1] + less_y)
        self._shift = (self._shift[0] + less_x, self._shift[1] + less_y)

    def due(self, seq: int) -> bool:
        """Whether a placement is due at the sample of encoder frame ``seq``: a stall, a gap
        into its frame or before, or an allowance withdrawn."""
        return self.stalled or self.owed or any(gap[0] <= seq for gap in self._gaps)

    @property
    def gapped(self) -> bool:
        """Gaps wait for the next placement (heard after the frame of a sample held:
        ``host.judge.livelaphold``)."""
        return bool(self._gaps)

    @property
    def waiting(self) -> bool:
        """Placements' parts wait for the pages (``withdraw``)."""
        return bool(self._parts)

    @property
    def owed(self) -> bool:
        """An allowance was withdrawn (``withdraw``): the reference is to move at the next
        sample (``shift`` gives how far)."""
        return self._owed != (0.0, 0.0)

    def _allowance_m(self, before: int, after: int, window: Columns,
                     reference: tuple[Geometry, int, str]) -> float:
        """``breaks.merge_allowance_m`` from encoder frame ``before`` (the last sample compared)
        to ``after`` (seq), from the window's counts (plus ``breaks.overlap_allowance_m`` when a
        gap of the sender's sequence lies between, or ``spanfill``'s when the refused frames
        heard fill every such gap), or the path bound from the sums of the count steps when
        ``before`` left the window; inf when neither is known."""
        geometry, counter_bits, integrator = reference
        seqs = window.col("seq")
        i0 = int(np.searchsorted(seqs, before))
        i1 = int(np.searchsorted(seqs, after))
        if before >= 0 and i0 < len(seqs) and seqs[i0] == before and i1 < len(seqs):
            left = window.col("left")[i0 : i1 + 1].astype(np.int64)
            right = window.col("right")[i0 : i1 + 1].astype(np.int64)
            periods = sender_seq(window.col("counter")[i0 : i1 + 1].astype(np.int64),
                                 window.col("t_s")[i0 : i1 + 1], CYCLE_S,  # a gap within
                                 window_holes(window, self.halves, i0, i1 + 1))
            filled = filled_span_allowance_m(  # the fills heard for its gaps: spanfill
                left, right, periods, lambda k: self._gap_fill(
                    before + k, int(periods[k] - periods[k - 1])), geometry, counter_bits,
                integrator, self.max_wheel_speed_mm_s)
            if filled is not None:
                return filled
            ends = [(int(periods[k]), int(left[k]), int(right[k])) for k in (0, -1)]
            return merge_allowance_m(left, right, geometry, counter_bits, integrator,
                                     periods) + \
                overlap_allowance_m(ends[0], ends[1], len(left), geometry, counter_bits,
                                    integrator, self.max_wheel_speed_mm_s)
        now = self._abs_at(after)
        if self._abs_last is None or now is None:
            return math.inf
        return path_bound_m(now[0] - self._abs_last[0], now[1] - self._abs_last[1], geometry)

    def _gap_fill(self, seq: int, periods: int) -> list[Counts] | None:
        """The counts of the frames the gap of ``periods`` into encoder frame ``seq`` lacks,
        when every one was heard refused (``livefill``) and the gap is the one recorded; else
        None."""
        sender, recorded = self._gap_sender.get(seq, (0, 0))
        return self.fill.fill(sender, periods) if recorded == periods else None
