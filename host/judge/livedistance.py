"""ODOM_TWIST DISTANCE judged live (``odocan monitor``): ``host.judge.distance``'s rule frame by
frame, beside ``host.judge.tracking.PoseTracker`` (whose numbering of the encoder frames and
periods between them it reads, and whose stalls it follows).

Per accepted encoder frame the firmware's step (its own ``livepose.StepGate``: refusals, counter
restarts) adds |dS| rounded to 2^-40 m to an exact int sum, as the whole-log judge does, with the
same slack (``distance.base_slack``: the wire's 0.5 mm, 2^-39 m a frame, 2^-48 m a count) and the
same gap allowance above (the firmware may have taken a gap's frames one by one:
``distance.gap_extra_m``; withdrawn where the pages prove it took none of them, the twists after a
gap waiting for them: ``host.judge.livedistgaps``). Below, the fine path over the union of the spans
whose frames the firmware may have merged, each frame once (``host.judge.liveunion``, as
``analyze``'s ``distance.merged_path_m``): a stall the tracker tells (the last sample's frame to the
first judged after it); a stall before the first pose (``livefirst``: from the frame the firmware
could first have primed on, from the life's first frame once that left: looser by the path between);
an ODOM_STATUS page whose ENC_E2E_LOST grew beyond the bus's own gaps since the page before
(``losses.lost_beyond_gaps``, ``analyze``'s ``firmware_losses``: the page before's latest frame to
its own; any growth was one before, and under ``delay=0.2:40,stall=2:0.1`` every page's was, so a
DISTANCE 10 mm low from 5 s PASSed live where ``analyze`` FAILed it by 9.99 mm); a span
where ENC_E2E_OK grew by more than ``skipdefect.MAX_RUN`` less than the frames the host took. Where
it grew by fewer less (a jittered capture: the host's E2E took frames the firmware refused),
``skipdefect``'s defect allowance, as ``analyze`` gives it. A twist is judged once the page after
its frame is heard (``host.judge.liveskip``), with the spans known then. Summed span by span
(before), a 3 s stall mid-drive let DISTANCE fall 3.09 m from the last twist before it to the first
judged after, where ``analyze`` lets it fall 1.52 m: a DISTANCE 2.3 m short PASSed live.

A sample (ODOM_TWIST) names its encoder frame by the tracker's rule for a pose half
(``samples.match_encoder`` over its window: the sender's steps, the age bound, the held and
queued rules, resolved when the sample is heard; one held back on the bus where it was sent, a
repeated ENC_COUNTER carried by send times: ``livelatetwists``, as ``analyze`` names them): the
first naming each frame is judged (not the first after a silence, a life's first measured
from its ODOM_STATUS: ``livefirst``), and each resend right after it
(``host.judge.resentdistance``; a sample naming none, or a frame before the last named, or a
frame with a twin, or one the step gate refused, ``refusednames``, is left out). Its offset interval
[r - upper, r + lower] must meet every earlier one of the life (``distance`` module
docstring); in the first life, once the tracker has proven a power-up at frame 0 (its
reference's exact start; or the first page came before any frame: it primes on the first), the
offset must be 0. A reboot starts a new life (its offset free again; the twists heard from the
new firmware's first tick, before the summary that told it, are not the old life's: ``new_life``);
an interval found empty is latched (``wrong_lives``, an ended life's too): the verdict DISTANCE
WRONG, and the watch's exit 1."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from odocan.host.judge.distance import (
    COUNT_SLACK_M,
    STEP_SLACK_M,
    UNITS_PER_M,
    WIRE_MM,
    WIRE_SLACK_MM,
    Feasible,
    firmware_m_per_count,
    gap_extra_m,
)
from odocan.host.judge.livedistgaps import HeldGaps, exact_bound_m
from odocan.host.judge.livelatetwists import TwistNames
from odocan.host.judge.livepose import RestartLog, StepGate
from odocan.host.judge.liveresent import may_alias_live
from odocan.host.judge.liveskip import WAIT_FRAMES, LiveSkips
from odocan.host.judge.liveunion import MergedSpans
from odocan.host.judge.livewindow import HALF_WINDOW, Columns
from odocan.host.judge.losses import lost_beyond_gaps
from odocan.host.judge.posewrongs import PoseWrongs
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound
from odocan.host.judge.samples import SILENCE_CYCLES
from odocan.host.judge.tracking import PoseTracker
from odocan.host.protocol import busfacts
from odocan.sim.robot import RobotProfile

KEPT_FRAMES = 64  # encoder frames kept for the samples to name (less than 8 cycles old)
CYCLE_S = busfacts.ENC_CYCLE_S  # WHEEL_ENCODERS' cycle


def robot_of(name: str, geometry: Geometry, counter_bits: int) -> RobotProfile:
    """The robot profile of a geometry (its speed bound included) and counter width."""
    return RobotProfile(name, geometry.counts_per_rev, geometry.wheel_radius_left_m,
                        geometry.wheel_radius_right_m, geometry.wheelbase_m, counter_bits,
                        geometry.max_wheel_speed_mm_s / 1000)


class LiveDistance:
    """The live DISTANCE judge (module docstring)."""

    def __init__(self, robot: RobotProfile, max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED,
                 wrongs: PoseWrongs | None = None) -> None:
        self.robot = robot
        self.max_wheel_speed_mm_s = max_wheel_speed_mm_s
        self._m = firmware_m_per_count(robot)
        self.samples = 0
        self.suspended = False  # a config applied with parameters not known here
        self.wrong_lives = 0  # lives whose intervals did not meet (latched)
        self.worst_excess_m = 0.0
        self.judged_at_end = 0  # twists judged at the watch's end, their page not heard
        self._held = HeldGaps()  # gaps whose bound above the pages may withdraw (livedistgaps)
        self.withdrawn_m = 0.0  # the gaps' bounds above the pages withdrew (m)
        self.wrongs = wrongs  # the tracker's: its conflict (``follow``)
        self._ended: list[tuple[float, float]] = []  # ended lives found wrong: from (s), m
        self.new_life()

    def follow(self, wrongs: PoseWrongs) -> None:
        """Judge as ``wrongs`` (the tracker's POSE WRONG episodes) judges: two firmwares on one
        node ID from its ``judged_until_s`` on, no twist heard from then is judged, and a life
        found wrong by one of them is withdrawn, as the pose's episodes are
        (``PoseWrongs.unjudgeable_from``; before, the second firmware's DISTANCE, counted from
        its own power-up, FAILed a correct one by 7536 mm beside the CONFLICT)."""
        self.wrongs = wrongs

    def _until_s(self) -> float:
        """The bus time twists are judged until (a conflict's start; inf: none)."""
        return math.inf if self.wrongs is None else self.wrongs.judged_until_s

    def reconfigure(self, geometry: Geometry, counter_bits: int) -> None:
        """New robot parameters (a config command): the firmware's DISTANCE goes on with its
        new constants from a value this judge cannot know: judged from here as a new life."""
        self.robot = robot_of(self.robot.name, geometry, counter_bits)
        self._m = firmware_m_per_count(self.robot)
        self.suspended = False
        self.new_life()

    def take_speed_bound(self, geometry: Geometry) -> None:
        """The firmware's plausibility bound (its PROFILE page, ``geometry``'s): this judge's
        step gate and its gaps' allowance take it from the next frame on."""
        self.max_wheel_speed_mm_s = geometry.max_wheel_speed_mm_s
        if self._gate is not None:
            self._gate.rebound(geometry)

    def suspend(self) -> None:
        """A config applied whose parameters this judge does not know: DISTANCE is no longer
        judged (what was found wrong stays latched)."""
        self.suspended = True

    def new_life(self, from_s: float = math.inf) -> None:
        """A reboot: the firmware's DISTANCE restarts; so does the judgement (offset free).
        ``from_s``: the bus time the new firmware's frames start from (its first ticks' twists
        come before the summary that told the reboot: ``bootticks``, as ``LiveTwist.new_life``):
        the twists heard from then are not the old life's, and what they found is withdrawn."""
        self._held.gaps.clear()  # no page of the old life comes now: their bounds kept
        if waiting := getattr(self, "_waiting", None):  # the old life's twists judged with what
            waiting[:] = [taken for taken in waiting if taken[3] < from_s]  # is known
            self._take_waiting(math.inf)
        if getattr(self, "_grew", None):  # the old life's wrong kept (before, lost unless a
            self._end_life(from_s)  # status had asked for the verdict before the reboot)
        self._held = HeldGaps()
        self._frames: dict[int, tuple[int, int, int, float]] = {}  # seq: units, n, c, up
        self._refused: set[int] = set()  # those of them the gate refused (refusednames)
        self._sums: tuple[int, int, int, float] = (0, 0, 0, 0.0)
        self._gate: StepGate | None = None
        self._twists = Columns(("pos", "enc_counter", "counter", "t_s"), HALF_WINDOW)
        self.named = -1  # the encoder frame the last twist named (-1: none)
        self._names = TwistNames()  # where each names, a late one where sent (livelatetwists)
        self._last_e = -1  # the last frame judged
        self._running = -1  # the largest frame named
        self._judged_last = False  # the last twist was judged (a resend of it is too)
        self._last_twist: tuple[float, int] = (math.nan, 0)  # bus time, frames heard before
        self._union = MergedSpans()  # the spans whose frames may be merged (liveunion)
        self._merged = (-1, 0)  # the last twist judged: its path, the union's growth to it
        # lossy pages' spans, for the twists heard after them: twists heard before, span
        self._lossy: list[tuple[int, tuple[int, int, int, int]]] = []
        self._last_units = 0  # the path at the last frame judged (``_last_e``)
        self._stalls = -1
        self._page: tuple[int, int] | None = None  # the last ENC_E2E page: latest frame, path
        self._lost: tuple[int, int] | None = None  # the last page's ENC_E2E_LOST and _OK
        self._bus_gaps = 0  # the sender's periods the bus lacked since that page (``_lossy``)
        self._r0: float | None = None
        self._feasible: Feasible | None = None
        self._zero = Feasible(0.0, 0.0)  # the same samples judged from 0 at the first frame
        self._grew: list[tuple[float, float]] = []  # this life's excess grown: heard (s), mm
        self._heard_s = -math.inf  # when the last twist judged was heard
        self._skips = LiveSkips()  # ENC_E2E_OK grown by less than the frames taken (liveskip)
        # twists waiting for the page after their frame: frame, its path, (judge, lo, hi mm,
        # up m), bus time heard
        self._waiting: list[tuple[int, int, list[tuple[Feasible, float, float, float]],
                                  float]] = []
        self._queued = self._judged = 0  # twists queued, judged (``_lossy``)
        self.first_seq: int | None = None
        self.power_up = False  # the first life, heard from the firmware's power-up

    def on_encoders(self, tracker: PoseTracker, counter: int, left: int, right: int,
                    t_s: float, uptime: int) -> None:
        """An accepted WHEEL_ENCODERS frame, after ``tracker.on_encoders`` numbered it."""
        seq = tracker.enc_seq
        if self._gate is None:
            # its own gate: the restarts it re-primes on are the tracker's to tell
            told = RestartLog(lambda _seq, _by_uptime: None)
            told.through = tracker.placer.seen.through  # the tracker's gate's (holetaken)
            self._gate = StepGate(tracker.geometry, tracker.counter_bits, told)
            self.first_seq = seq
        periods = tracker.placer.periods
        step = self._gate.step((seq, counter, left, right, periods, uptime, t_s))
        d_left, d_right = step if step is not None else (0, 0)
        if step is None and self._gate.prev != (counter, left, right):  # refused: refusednames
            self._refused.add(seq)
        self._refused.discard(seq - KEPT_FRAMES)
        m_left, m_right = self._m
        signed_m = 0.5 * (d_left * m_left + d_right * m_right)
        ds_m = abs(signed_m)
        self._skips.on_step(seq, signed_m)
        self._bus_gaps += max(periods - tracker.placer.moved - 1, 0)  # the stamps' (sums kept)
        units, n, c, up = self._sums
        frames = self._frames
        if periods > 1 and frames:
            extra_m = exact_bound_m(gap_extra_m(self.robot, self.max_wheel_speed_mm_s, periods,
                                                ds_m))  # >= 0, withdrawn exactly (livedistgaps)
            up += extra_m
            self._held.add(seq, extra_m, t_s)  # the twists from here wait for the pages
        sums = self._sums = (units + round(ds_m * UNITS_PER_M), n + 1,
                             c + abs(d_left) + abs(d_right), up)
        frames[seq] = sums
        frames.pop(seq - KEPT_FRAMES, None)
        if seq >= self._union.want:  # a span's end: the frame after a page (liveskip's)
            self._union.on_frame(seq, sums[0])
        if self._held.gaps:  # a gap's proof may have come (livedistgaps)
            self._settle(tracker, seq, False)
        if self._waiting and self._waiting[0][0] <= seq - WAIT_FRAMES:  # no page came for them
            self._take_waiting(seq - WAIT_FRAMES)

    def on_counts(self, tracker: PoseTracker, ok: int, lost: int, proven: bool) -> None:
        """ODOM_STATUS page E2E_WHEEL_ENCODERS. The first life's first page, after a first
        summary of UPTIME 0, counting exactly the frames heard when it was made (``proven``:
        ``SourceWatch.on_page``): a power-up at the first frame heard (``analyze``'s and the
        tracker's rule), the offset 0. ENC_E2E_LOST (u8) grown: the fine path since the page
        before may have been merged on board."""
        if proven and self.first_seq is None:  # no frame heard yet: it primes on the first
            self.power_up = True  # (the page counted none: ``_skips`` takes it as it is)
        if proven and self.first_seq == 0:
            self.power_up = True
            self._skips.start(0)
            if self._feasible is not None:  # judged from 0 all along, as the whole log is
                self._zero.excess_mm = max(self._zero.excess_mm, self._feasible.excess_mm)
                self._feasible, self._r0 = self._zero, 0.0
                self._note(self._heard_s)
        seq, units = tracker.enc_seq, self._sums[0]
        if self._lost is not None and self._page is not None and lost_on_board(
                self._lost, (lost, ok), seq - self._page[0], self._bus_gaps):
            self._lossy.append((self._queued, (*self._page, seq, units)))
        self._lost, page_before, self._page = (lost, ok), self._page, (seq, units)
        self._bus_gaps = 0
        self._skips.on_page(ok, seq, tracker.late_refused)
        for first, end in self._skips.merged:  # past MAX_RUN frames skipped: the fine path
            start = page_before if page_before and page_before[0] == first else None
            self._union.add(first, start[1] if start else self._frames.get(first, (0,))[0],
                            end, None)
        self._skips.merged.clear()
        self._take_waiting(self._skips.covered)

    def on_twist(self, tracker: PoseTracker, enc_counter: int, raw_mm: int, t_s: float,
                 counter: int) -> None:
        """An accepted ODOM_TWIST (``counter``: its own E2E COUNTER): judge its DISTANCE at the
        encoder frame it names (not the first after a stall: ``distance.DistanceJudge.take``)."""
        pos = tracker.take_place()  # its place among the frames heard
        sent_s = self._names.sent_s(tracker, t_s, counter)  # held back on the bus: livelatetwists
        self._twists.append(pos, enc_counter, counter, sent_s)
        e = self.named = self._names.name(tracker, enc_counter, counter, t_s, sent_s, lambda: (
            tracker.named(self._twists, pos)[0]))  # (livetwist takes it)
        e = -1 if e >= 0 and tracker.twins.twinned(e) else e
        resend = (e >= 0 and e == self._running and self._judged_last  # resentdistance.py
                  and not may_alias_live(e, t_s, tracker))
        first, self._running = e > self._running, e if e > self._running else self._running
        last_t, last_heard = self._last_twist
        if last_t != last_t and (talked := tracker.first.talked_before(t_s)) is not None:
            last_t, last_heard = talked  # the first: after the firmware's ODOM_STATUS (livefirst)
        self._last_twist = (t_s, tracker.enc_seq + 1)
        quiet = (t_s - last_t >= (SILENCE_CYCLES - 0.5) * CYCLE_S
                 and tracker.enc_seq + 1 - last_heard >= SILENCE_CYCLES - 1)
        at = self._frames.get(e)
        self._judged_last = not (self.suspended or quiet or not (first or resend) or at is None
                                 or t_s >= self._until_s())  # (a conflict from then: follow)
        if not self._judged_last or at is None or e in self._refused:
            return  # (naming a frame the gate refused: the firmware's chain, refusednames)
        if self._stalls >= 0 and tracker.stall.stalls > self._stalls and self._last_e >= 0:
            # merged since the last sample (its path kept: a 3 s stall outlives the frames
            # kept, and the allowance was unbounded, a DISTANCE 20 m short then PASSed)
            self._union.add(self._last_e, self._last_units, e, at[0])
        elif self._last_e < 0 and (primed := tracker.first.stalled_from) is not None \
                and self.first_seq is not None and primed >= self.first_seq:
            before = self._frames.get(primed)  # a stall before the first pose (livefirst):
            self._union.add(primed, before[0] if before else 0, e, at[0])  # merged since
        self._stalls, self._last_e, self._last_units = tracker.stall.stalls, e, at[0]
        units, n, c, up = at
        diff = raw_mm - units * (1000.0 / UNITS_PER_M)
        r = diff - WIRE_MM * round(diff / WIRE_MM)
        if self._feasible is None:  # the offset: 0 from a power-up, else free
            self._r0 = 0.0 if self.power_up else r
            self._feasible = self._zero if self.power_up else Feasible(-math.inf, math.inf)
        base = WIRE_SLACK_MM + 1e3 * (n * STEP_SLACK_M + c * COUNT_SLACK_M)
        takes = []
        if self._feasible is not self._zero:  # a power-up proven later (a page held back)
            takes.append((self._zero, r - base, r + base, up))
        r0 = self._r0 or 0.0
        r = r0 + (r - r0) - WIRE_MM * round((r - r0) / WIRE_MM)
        takes.append((self._feasible, r - base, r + base, up))
        self._waiting.append((e, units, takes, t_s))  # judged once a page covers it (liveskip)
        self.samples += 1
        self._queued += 1

    def _settle(self, tracker: PoseTracker, seq: int, ends: bool) -> None:
        """The gaps held decided (``livedistgaps.HeldGaps.settle``): a proven one's bound above
        withdrawn from the path at its frame and after (the twists waiting, the frames kept,
        the sums), then the twists it held judged."""
        decided = self._held.settle(tracker.placer.seen, tracker.placer.reprimed_frames, seq,
                                    ends)
        for b, extra_m in decided:
            if extra_m > 0.0:
                self._lower(b, extra_m)
        if decided:
            self._take_waiting(self._held.upto)

    def _lower(self, b: int, extra_m: float) -> None:
        """The bound ``extra_m`` above of the gap into encoder frame ``b`` withdrawn: no twist
        naming ``b`` or later was judged (they waited for it)."""
        self.withdrawn_m += extra_m
        units, n, c, up = self._sums
        self._sums = (units, n, c, up - extra_m)
        frames = self._frames
        for seq in [seq for seq in frames if seq >= b]:
            f_units, f_n, f_c, f_up = frames[seq]
            frames[seq] = (f_units, f_n, f_c, f_up - extra_m)
        self._waiting = [(e, e_units, takes if e < b else [
            (judge, lo, hi, up_m - extra_m) for judge, lo, hi, up_m in takes], heard_s)
                         for e, e_units, takes, heard_s in self._waiting]

    def _take_waiting(self, upto: float) -> None:
        """Judge the twists waiting whose frame is ``upto`` or before, in order, with the
        allowance below known at their frame: the union of the merged spans (``liveunion``)
        and ``liveskip``'s defects; not from a twist naming a gap's frame or later while the
        gap waits for its pages (``livedistgaps``)."""
        self._held.upto = max(self._held.upto, upto)
        held = self._held.first()
        if held is not None:
            upto = min(upto, held - 1)
        k = 0
        while k < len(self._waiting) and self._waiting[k][0] <= upto:
            e, units, takes, heard_s = self._waiting[k]
            while self._lossy and self._lossy[0][0] <= self._judged:  # heard after the page:
                self._union.add(*self._lossy.pop(0)[1])  # the twists before it judged without
            self._judged += 1
            since, grown = self._merged
            self._merged = (units, grown + self._union.grown_units(since, e, units))
            down_mm = 1e3 * (self._merged[1] / UNITS_PER_M + self._skips.allowance_m(e))
            for judge, lo, hi, up_m in takes:
                judge.take_one(lo, hi, 1e3 * up_m, down_mm)
            self._note(heard_s)
            k += 1
        del self._waiting[:k]

    def finish(self, tracker: PoseTracker | None = None) -> int:
        """The watch ends (no later page comes): the twists still waiting for the page after
        their frame judged with the spans known, as ``new_life`` judges an old life's and
        ``analyze`` the twists after a log's last page; how many there were (before, they were
        never judged: a DISTANCE wrong in the watch's last 0.6-1.8 s passed)."""
        waiting = len(self._waiting)
        if tracker is not None and self._held.gaps:  # the pages kept prove what they can
            self._settle(tracker, tracker.enc_seq, True)
        self._held.gaps.clear()
        self._take_waiting(math.inf)
        self.judged_at_end += waiting
        return waiting

    def _note(self, heard_s: float) -> None:
        """The excess after judging the twist heard at bus time ``heard_s``, kept where it grew
        (``_end_life`` withdraws what the new firmware's twists found; ``follow``)."""
        excess_mm = self._feasible.excess_mm if self._feasible is not None else 0.0
        if excess_mm > (self._grew[-1][1] if self._grew else 0.0):
            self._grew.append((heard_s, excess_mm))
        self._heard_s = heard_s

    def _end_life(self, from_s: float) -> None:
        """The life ends: its wrong, as found by the twists heard before ``from_s``, kept."""
        grew = [grown for grown in self._grew if grown[0] < from_s]
        if grew:
            self._ended.append((grew[0][0], grew[-1][1] * 1e-3))
        self._grew = []

    def verdict(self) -> list[str]:
        """Why DISTANCE is wrong (empty: it is not), latched once found (in a life's last
        twists, withdrawn where they were the new firmware's: ``new_life``); a life found wrong
        by a twist heard from a conflict's start on is not (``follow``)."""
        until_s = self._until_s()
        now = [(self._grew[0][0], self._grew[-1][1] * 1e-3)] if self._grew else []
        lives = [life for life in self._ended + now if life[0] < until_s]
        self.wrong_lives = len(lives)
        self.worst_excess_m = max((excess_m for _, excess_m in lives), default=0.0)
        if not self.wrong_lives:
            return []
        return [f"ODOM_TWIST DISTANCE off the reference's path length by "
                f"{self.worst_excess_m * 1e3:.3f} mm beyond its tolerance"]

    def as_dict(self) -> dict[str, Any]:
        """``distance`` in ``monitor --json``."""
        self.verdict()
        return {"samples": self.samples, "start": "power-up" if self.power_up else "fitted",
                "suspended": self.suspended,
                "max_excess_m": self.worst_excess_m, "wrong_lives": self.wrong_lives,
                "judged_at_end": self.judged_at_end,
                "passed": self.wrong_lives == 0}


def lost_on_board(before: tuple[int, int], after: tuple[int, int], frames: int,
                   bus_gaps: int) -> bool:
    """Whether the firmware lost frames the bus carried between two ENC_E2E pages (ENC_E2E_LOST
    and ENC_E2E_OK at each; ``frames``: the host took between them, ``bus_gaps``: the sender's
    periods the bus lacked there): ``losses.lost_beyond_gaps``, its growth unwrapped by the
    frames the firmware did not take alone (LOST_FRAMES not followed here: looser, never
    tighter than ``analyze``)."""
    if frames <= 0:
        return False
    excess = lost_beyond_gaps(np.array(before[0]), np.array(after[0]), np.array(0),
                              np.array(frames + bus_gaps), np.array(frames),
                              ok_growth=np.array((after[1] - before[1]) & 0xFFFF),
                              total_growth=np.array(1 << 16))
    return bool(excess > 0)
