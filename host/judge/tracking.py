"""Live alignment of what a robot's bus says: the on-board pose against a float64 reference and
the ground truth, each paired at the very encoder frame it names (ENC_COUNTER), never by time.

Used by ``odocan monitor`` and the MQTT bridge; the offline version is ``host.judge.analysis``.
The encoder frame a pose half names is resolved with the same functions
(``samples.match_encoder``, its held and queued rules, ``sender_seq``) on a window of the latest
frames (``HALF_WINDOW`` halves, ``ENC_WINDOW`` encoder frames). A half is settled once bus time
is half an encoder cycle past it or the next half of its message is heard (then its burst is
known: ``samples.queued_frames``): a sample is judged <= half a cycle after its ODOM_POSE_Y.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from odocan.host.judge.bootnamed import LivePowerUp
from odocan.host.judge.liveadopted import (
    CONFIG_CHANGE,
    INTEGRATOR_CHANGE,
    INTEGRATOR_FIRST_HEARD,
    REBOOT_BEFORE_INTEGRATOR,
    AdoptedStarts,
)
from odocan.host.judge.livebootstall import left_out_waiting
from odocan.host.judge.liveboottick import BootTick
from odocan.host.judge.livechoice import LiveChoice
from odocan.host.judge.livecutreprime import CutHold
from odocan.host.judge.livedark import NO_FRAME_S
from odocan.host.judge.livefirst import FIRST_FRAMES, FirstStall, left_out_first
from odocan.host.judge.livefit import LiveFit
from odocan.host.judge.livefloodnames import LiveFloodNames
from odocan.host.judge.livehalves import HalfPairs
from odocan.host.judge.liveheldstart import held_counts
from odocan.host.judge.livelaphold import LapHold
from odocan.host.judge.livelatehalves import LateHalves
from odocan.host.judge.livelosses import LiveAllowance
from odocan.host.judge.livenewstart import NewStartHold
from odocan.host.judge.liveplace import StallPlacer
from odocan.host.judge.liveplacing import place_reference
from odocan.host.judge.livepose import ErrorStats, FramePose, RestartLog, Sample, StepGate
from odocan.host.judge.livepowerpose import PowerUpPose
from odocan.host.judge.livequeuedfirst import QueuedFirst
from odocan.host.judge.livereference import RawReference
from odocan.host.judge.livereprime import ReprimeHold
from odocan.host.judge.livereprimecount import PowerUpCount
from odocan.host.judge.livesnapshot import tracker_snapshot
from odocan.host.judge.livestall import StallRule
from odocan.host.judge.livestart import Lives
from odocan.host.judge.livetruth import LifeTruth, TruthJudge
from odocan.host.judge.livetwins import TwinWatch
from odocan.host.judge.livewindow import (
    ENC_COLUMNS,
    ENC_WINDOW,
    QUEUED_GAP_S,
    Columns,
    Half,
    counted,
    named_in_window,
    named_plain,
)
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import HEADING_LSB_RAD, WIRE_COUNTER_BITS
from odocan.sim.pose import TURN_RAD


class PoseTracker:
    """On-board pose vs the float64 reference (aligned by ENC_COUNTER) and vs SIM_TRUTH.

    Each pose half names the encoder frame it was made after, resolved as ``analyze`` resolves it
    (module docstring: the same functions on a window of recent frames, a half settled half a
    cycle after it is heard); an ODOM_POSE_X and an ODOM_POSE_Y naming one encoder frame make one
    on-board sample (the first of each, as ``host.judge.samples.onboard_samples``).

    The reference starts at the first on-board pose heard, primed with the counts of the frame
    it names, stepped with every accepted WHEEL_ENCODERS frame after it (``raw``:
    ``livereference``). Until the integrator is known (``integrator`` None: ODOM_STATUS's) the
    poses and frames heard are kept (``lives``: ``livestart.Lives``, up to ``BACKLOG_FRAMES``)
    and compared once it is, so the monitor and the bridge judge the samples ``analyze``
    judges; another integrator restarts it. Its start inherits the pose signals' rounding,
    narrowed sample by sample as ``analyze`` fits it (``host.judge.livefit``), until a power-up
    is proven (``on_enc_counts``): then exactly (0, 0, 0), as ``analyze`` starts it. The first
    life's samples wait for its first ENC_E2E_OK page (up to ``BOOT_COUNT_WAIT_S``), so that a
    power-up's are all judged from (0, 0, 0), as ``analyze`` judges them."""

    def __init__(
        self, geometry: Geometry, counter_bits: int, integrator: str | None = None
    ) -> None:
        """``counter_bits``: the robot's hardware counter width (16 wraps within the 24 on the
        bus); ``integrator`` None: the one ODOM_STATUS reports."""
        self.geometry = geometry
        self.counter_bits = min(counter_bits, WIRE_COUNTER_BITS)
        self.forced, self.integrator = integrator is not None, integrator
        self.enc_seq = -1
        self._pos = 0  # frames fed so far (the order of encoder frames, pose halves, twists)
        self.window = Columns(ENC_COLUMNS, ENC_WINDOW)  # the latest encoder frames heard
        self.twins = TwinWatch(self.window.rows)  # frames with a twin: their poses left out
        self.late_refused: list[int] = []  # a late frame refused: the next taken's (liveskip)
        self.boot_tick = BootTick()  # the latest refused since the last taken (liveboottick)
        self.pairs = HalfPairs(self)  # the pose halves heard, settled and paired (livehalves)
        self.late = LateHalves()  # ... those held back on the bus left out (livelatehalves)
        self.settled: list[Sample] = []  # samples settled since ``take_samples``
        self.fit = LiveFit(0.0, 0.0, exact=True)  # the start narrowed (host.judge.livefit)
        self.placer = StallPlacer()  # the placements after stalls (host.judge.liveplace)
        self.placer.halves = self.pairs.halves["x"]  # the holes of the log its gaps are told by
        self.restarts = RestartLog(self.placer.reprimed)  # counter restarts told (``events``)
        self.restarts.through, self.restarts.owe = self.placer.seen.through, self.placer.dark.owe
        self.restarts.heard_in = self.placer.seen.heard_in  # evidenceless: a choice held
        self.choice = LiveChoice(self)  # ... both candidates until the pages or the next pose
        self.restarts.choose = self.choice.open
        self.newstart = NewStartHold(self)  # a new start's samples wait for its fit
        self.reprime = ReprimeHold(self)  # a long stall's wait for the firmware's word
        self.queued = QueuedFirst(self)  # a queued sample after a silence (livequeuedfirst)
        self.cut = CutHold(self)  # ... a staged APPLY just after it (livecutreprime)
        self.adopted = AdoptedStarts()  # starts at the firmware's own pose, said (liveadopted)
        self.laps = LapHold(self)  # samples after a lap of the stamps wait for its evidence
        self.stall = StallRule(self.placer, self.window, self.pairs.halves["y"])  # livestall
        self.first = FirstStall()  # a stall before a life's first sample (livefirst)
        # raw: ``fit`` corrects its start (livereference); where it starts (livestart)
        self.raw = RawReference(StepGate(geometry, self.counter_bits, self.restarts))
        self.lives = Lives(self)
        self.status_heard: tuple[float, int] | None = None  # the latest ODOM_STATUS: t, COUNTER
        self.powerup = LivePowerUp()  # the latest power-up pose heard (bootnamed)
        self.powerpose = PowerUpPose()  # its halves left out, judged at the start (livepowerpose)
        self.truths = TruthJudge(self)  # SIM_TRUTH's parts, judged (livetruth)
        # the latest sample judged (``record``): on-board pose, corrected reference
        self.last_pair: tuple[FramePose, FramePose] | None = None
        self.losses = self.placer.losses = LiveAllowance()  # (livegapseen re-judges)
        self.wrongs = self.losses.wrongs  # POSE WRONG episodes latched (host.judge.posewrongs)
        self.now_s = 0.0  # the latest bus time (s; ``advance`` sets it)
        self.floods = LiveFloodNames()  # a flood's names resolved by HEADING (livefloodnames)
        self.pose: FramePose | None = None
        self.pose_t_s = 0.0  # bus time of the ODOM_POSE_Y of ``pose`` (s)
        self.reference: FramePose | None = None
        self.truth: FramePose | None = None
        self.reference_starts = 0
        self.vs_reference, self.vs_truth, self.reference_vs_truth = (ErrorStats(), ErrorStats(),
                                                                     ErrorStats())
        # a new life's origin in the truth's frame (``compare.life_origin``; None in the first)
        self.life_truth = LifeTruth()

    fast_path = True  # False: every half by ``match_encoder`` over the window (tests compare)

    def advance(self, t_s: float) -> None:
        """Bus time is now ``t_s`` (any frame heard): pose halves heard half an encoder cycle or
        more before are settled; a new life waiting ``BOOT_COUNT_WAIT_S`` starts without it."""
        dark = self.placer.dark  # ``DarkRestarts.heard`` in line (per frame of every robot):
        last_s = dark.last_s  # a gap beyond ``dark_s`` is a later frame (the first's: none)
        if t_s > last_s:
            if last_s == NO_FRAME_S:  # the first frame: the verdict's times count from it
                self.wrongs.origin_s = min(t_s, self.wrongs.origin_s or t_s)
            elif t_s - last_s > dark.dark_s:
                dark.dark = True  # the input went dark
            dark.last_s = t_s
        self.now_s = t_s
        if t_s > self.choice.until_s:  # the pages had their time: the choice is made
            self.choice.decide()
        if t_s > self.laps.until_s:  # ... and a lap's numbering is decided (livelaphold)
            self.laps.decide(t_s)
        if t_s > self.newstart.until_s:  # the new start's samples had their fit
            self.newstart.release()
        boot = self.lives.boot
        if boot is not None and t_s > boot[1]:  # no count page in time: started without it
            self.lives.expire()
        if t_s - self.pairs.unsettled_from_s < QUEUED_GAP_S:
            return  # none due (nor any later half: t_s - t is monotone in t); none heard: inf
        self.pairs.settle_due(t_s)  # due, in the order heard (livehalves)

    def on_encoders(self, counter: int, left: int, right: int, t_s: float, uptime: int = 0) -> None:
        """An accepted WHEEL_ENCODERS frame (raw 24-bit counts, CTRL_UPTIME) at bus time ``t_s``."""
        self.advance(t_s)
        self.enc_seq += 1
        self._pos += 1
        self.boot_tick.taken(counter, t_s)  # a frame taken after it (liveboottick)
        prev = self.window.rows[-1] if self.window.rows else None  # (no __len__ call)
        if self.choice.pending is not None and prev is not None:  # a hole: the choice first
            self.choice.ahead(counter, t_s, prev)
        if self.placer.on_encoders(self.enc_seq, (counter, left, right, t_s), prev,
                                   self.counter_bits):
            self._gap(t_s)
        row = (self.enc_seq, self._pos, counter, t_s, left, right, self.placer.periods, uptime)
        self.window.append_row(row)
        self.reprime.quiet.heard(self.window.rows)  # kept when the firmware fell silent
        if self.enc_seq % ENC_WINDOW == 0:
            self._forget(self.enc_seq - ENC_WINDOW)
        elif self.enc_seq == FIRST_FRAMES - 1:  # the watch's first frames' times (livefirst)
            self.first.keep_first(tuple(self.window.col("t_s").tolist()[:FIRST_FRAMES]),
                                  tuple(zip(self.window.col("left").tolist()[:FIRST_FRAMES],
                                            self.window.col("right").tolist()[:FIRST_FRAMES],
                                            strict=True)))
        self.truths.frame_heard(counter, self.enc_seq, left, right)
        self.floods.frame(self.enc_seq, counter, (left, right), t_s, self.counter_bits)
        ref = self.raw.odometry
        if ref is not None:
            step = self.raw.step(ref, (self.enc_seq, counter, left, right, self.placer.periods,
                                       uptime, t_s))  # ``counted(row)`` in line
            if self.choice.pending is not None:  # the twin steps along (livechoice)
                self.choice.stepped(self.enc_seq, step)
            if self.laps.pending:  # (none held: ``heard`` would release none)
                self.laps.heard()
        elif self.lives.pending is not None:
            self.lives.heard(counted(row))

    def _gap(self, t_s: float) -> None:
        """A gap of the sender's sequence before the latest encoder frame (at ``t_s``): the
        reference placed again, bounded (``liveplace``); no count of a re-prime taken
        (``livereprimecount``)."""
        self.reprime.count.holed = True
        if self.raw.odometry is not None:
            self.stall.place_at_next = True
            if self.placer.lapped:  # its lap the stamps' alone: the samples wait (livelaphold)
                self.laps.lapped(self.enc_seq, t_s, self.placer.periods)

    def _forget(self, before: int) -> None:
        """Drop what is kept of the encoder frames before ``before`` (seq): bounded state."""
        self.pairs.forget(before)
        self.raw.forget(before)

    def on_pose_x(self, enc_counter: int, x_m: float, heading_rad: float, counter: int,
                  t_s: float) -> None:
        """ODOM_POSE_X (X in m, HEADING in rad within the turn; its E2E COUNTER, bus time s)."""
        self.floods.pose_x(enc_counter, round(heading_rad / HEADING_LSB_RAD), t_s, self.geometry)
        self._on_half("x", Half(0, enc_counter, counter, t_s, x_m, heading_rad))

    def on_pose_y(self, enc_counter: int, y_m: float, turns: int, counter: int,
                  t_s: float) -> None:
        """ODOM_POSE_Y (Y in m, TURNS; its E2E COUNTER, bus time s): with the ODOM_POSE_X of
        the same encoder frame, one on-board sample once settled (``take_samples``)."""
        self._on_half("y", Half(0, enc_counter, counter, t_s, y_m, turns))

    def on_status(self, t_s: float, signals: dict[str, Any] | None = None) -> None:
        """An accepted ODOM_STATUS at bus time ``t_s``: the firmware alive (``livefirst``);
        its raw ``signals``: a summary's word on a re-prime after a stall (``livereprime``)."""
        self.first.on_status(t_s, signals)  # INIT at UPTIME 0 still (livefirst: stallpowerup)
        counter = None if signals is None or "COUNTER" not in signals else int(signals["COUNTER"])
        if self.lives.page is not None and counter is not None:  # a count page's send told
            self.lives.on_status(t_s, counter)
        self.status_heard = None if counter is None else (t_s, counter)  # (``Lives.on_counts``)
        self.first.talked(t_s, self.enc_seq + 1, counter)  # (a halted tick's: livefirst)
        self.reprime.quiet.since = 0  # the firmware talked (``reprimereplay.QuietFrames``)
        if signals is not None:
            self.reprime.on_status(signals, t_s)
            if "LOST_FRAMES" in signals:  # FRAME_TOTALS: the bound of a lost count's laps
                self.losses.lost_total = int(signals["LOST_FRAMES"])

    def take_samples(self) -> list[Sample]:
        """The on-board samples settled since the last call, in the order settled."""
        settled, self.settled = self.settled, []
        return settled

    def _on_half(self, name: str, half: Half) -> None:
        self.advance(half.t_s)
        if self.first.posed_s is None:  # the firmware primed by then (livefirst)
            self.first.posed_s = half.t_s
        self.reprime.quiet.since = 0  # the firmware talked (``reprimereplay.QuietFrames``)
        self._pos += 1
        half.pos = self._pos
        self.pairs.heard(name, half, self.late.heard(name, half.t_s, half.counter))

    def take_place(self) -> int:
        """The place of a frame heard besides the encoder frames and pose halves (an ODOM_TWIST:
        ``livedistance``) in the order of the frames heard, taken: ``named`` resolves by it."""
        self._pos += 1
        return self._pos

    def named(self, halves: Columns, pos: int) -> tuple[int, bool]:
        """The encoder frame (seq) the half at ``pos`` names, -1 when none, and whether it queued:
        ``host.judge.samples.match_encoder`` over the window (the held and queued rules, the age
        bound, the causal rule); a half neither queued nor repeating its predecessor's ENC_COUNTER
        by the plain rule alone, in plain Python (``named_plain``: the same result)."""
        if self.fast_path:
            plain = named_plain(halves.rows, self.window, pos)
            if plain is not None:  # (no rename of a flood: ``follow`` keeps it, not called)
                floods = self.floods
                return (plain if floods.renamed is None
                        else floods.follow(plain, halves.rows, pos)), False
        seq, queued = named_in_window(halves, self.window, pos)
        return self.floods.follow(seq, halves.rows, pos), queued  # (livefloodnames)

    def on_pair(self, seq: int, x: Half, y: Half, queued: bool) -> None:
        """The X and Y halves naming encoder frame ``seq`` (``livehalves``): a sample, judged."""
        pose = self.pose = FramePose(seq, x.value, y.value, y.extra * TURN_RAD + x.extra)
        self.pose_t_s = y.t_s
        self.placer.dark.due(seq, self.newstart.restart)  # after a dark restart: livedark
        ref = self.compare(pose, y, queued)
        self.settled.append(sample := Sample(pose, ref, y.enc_counter, x.counter, y.t_s))
        if self.lives.boot is not None:  # held: settled again once judged (``livestart``)
            self.lives.held[seq] = sample
        self.newstart.sampled(sample)  # ... or held after an unseen restart (livenewstart)
        self.reprime.sampled(sample)  # ... or after a long stall (livereprime)
        self.queued.sampled(sample)  # ... or queued after a silence (livequeuedfirst)
        self.cut.sampled(sample)  # ... or a staged APPLY just after it (livecutreprime)

    def compare(self, pose: FramePose, y: Half, queued: bool) -> FramePose | None:
        """Judge one on-board sample (its ODOM_POSE_Y half ``y``, whether it ``queued``) by the
        stall and hold rule (``livestall``), then against the reference; the reference at its
        encoder frame, None when unknown or held (``livelaphold`` compares a held one when its
        hold ends)."""
        if self.queued.holds(pose, y, queued) or self.laps.holds((pose, y, queued)):
            return None
        if self.cut.pending is not None and self.cut.holds(pose, y, queued):  # its re-prime
            return None
        if self.reprime.holds(pose, y, queued):  # the firmware's word after a long stall
            return None
        started, last_s = self.raw.odometry is not None, self.stall.last_t_s  # (before it)
        if (last_s is None and left_out_first(self, pose, y.t_s, queued)) or (
                self._left_out(pose.seq, y.t_s, queued, started)):  # livefirst, livestall
            if self.raw.odometry is not None or not self.reference_starts:  # (power-up too)
                self.reprime.stalled(pose.seq, y.t_s, self.first.made_before(y.t_s),
                                     self.raw.gate.least)
            return None
        if (started and self.reprime.unnamed_first(pose, y, queued, last_s)) or (
                left_out_waiting(self, y.t_s, queued, last_s)):  # livereprime, livebootstall
            return None
        lives = self.lives  # a life's start (a boot's frame, the integrator): livestart
        if (not started or lives.boot is not None) and lives.waits(pose, self.now_s):
            return None
        return None if self.choice.holds(pose) else self.judge(pose)  # held: livechoice

    def _left_out(self, seq: int, t_s: float, queued: bool, started: bool) -> bool:
        """``livestall``'s rule on a sample; a stall or hold it finds places the position
        again from the last sample compared, whose frames since no loss span may lose
        (``livelosses.LiveAllowance.stalled_at``)."""
        stalls = self.stall.stalls
        out = self.stall.left_out(seq, t_s, queued, started)
        if self.stall.stalls > stalls and self.stall.last_compared >= 0:
            self.losses.stalled_at(self.stall.last_compared)
        return out

    def judge(self, pose: FramePose) -> FramePose | None:
        """Judge ``pose`` against the reference at its frame, placed again first where owed."""
        ref = self.raw.at.get(pose.seq)
        if ref is None:
            return None
        if self.stall.place_at_next or self.placer.owed:  # owed: an allowance withdrawn
            self.newstart.release()  # judged by the fit before the placement
            ref = place_reference(self, pose, ref)
        elif self.newstart.holds(pose, ref):
            return None
        return self.record(pose, ref)

    def record(self, pose: FramePose, raw: FramePose, fed: bool = False,
               t_s: float | None = None) -> FramePose:
        """Judge ``pose`` (its ODOM_POSE_Y at bus time ``t_s``, default the latest's) against
        the raw reference ``raw`` at its frame, corrected by the start fit (which the sample
        narrows first, unless ``fed``); returns the corrected reference."""
        if not fed:
            self.fit.feed(pose, raw)
        ref = self.fit.correct(raw)
        self.placer.compared(pose)
        self.reference, self.last_pair = ref, (pose, ref)
        self.stall.last_compared = pose.seq
        self.stall.compared_t_s = self.pose_t_s if t_s is None else t_s
        self.vs_reference.add(pose, ref, self.pose_t_s if t_s is None else t_s)
        self.losses.spans += self.twins.resolve(self.geometry, self.counter_bits, self.integrator)
        self.losses.record(pose.seq, self.vs_reference.latest, self.fast_path,
                           self.pose_t_s if t_s is None else t_s)
        return ref

    # --- encoder frames the firmware lost that the bus carried (host.judge.livelosses) ---

    def on_enc_lost(self, lost: int, ok: int | None = None) -> None:
        """ODOM_STATUS page E2E_WHEEL_ENCODERS: the firmware's ENC_E2E_LOST (u8) and ENC_E2E_OK
        (u16, None: unknown); a span of allowance where it grew beyond the bus's gaps
        (``LiveAllowance.on_page``)."""
        window = self.window if self.raw.odometry is not None else None
        self.losses.on_page(lost, self.enc_seq, window, self.pairs.sampled,
                            (self.geometry, self.counter_bits, self.integrator), ok)
        self.losses.settle(self.enc_seq, self.fast_path)  # later spans start at this frame

    def allowance_m(self, seq: int | None = None) -> float:
        """The loss and twin allowance (m) at frame ``seq`` (default: the latest sample's)."""
        return self.losses.at_m(self.stall.last_compared if seq is None else seq)

    @property
    def max_beyond_allowance_m(self) -> float:
        """The largest position error past its loss allowance (m), analyze's ``max_position_*``."""
        return self.losses.max_beyond_m() if self.vs_reference.samples else 0.0

    # --- lives and restarts ---

    def on_integrator(self, name: str) -> None:
        """ODOM_STATUS reports the firmware's integrator; a change restarts the reference."""
        if self.forced or name == self.integrator:
            return
        before, self.integrator = self.integrator, name
        if before is None and self.lives.pending is not None:  # judge what was heard waiting
            self.lives.start_pending(self.lives.backlog_poses)
        else:
            cause = INTEGRATOR_CHANGE if before is not None else INTEGRATOR_FIRST_HEARD
            self.adopted.owe(cause.format(before=before, after=name))
            self.restart_reference()

    def restart_reference(self) -> None:
        """Start the reference again at the next on-board pose (after a set-pose or config)."""
        self.choice.decide()  # the samples held are judged by the reference they named
        self.laps.decide()
        self.newstart.release()
        self.raw.stop()
        self.stall.restart()
        self.placer.restart()
        self.losses.restart(self.enc_seq, self.fast_path)
        self.lives.drop_backlog()
        self.powerpose.restarted()

    def power_up(self, primed_now: bool, seq: int | None = None,
                 tick_s: float | None = None) -> None:
        """A reboot (``sources``): the new life starts at (0, 0, 0) at the encoder frame it primed
        on, as ``analyze`` starts it: the one its first ENC_E2E_OK page names (``on_enc_counts``),
        whatever the summary said; its samples wait for that page, or ``BOOT_COUNT_WAIT_S``; without
        it, the latest frame when the boot summary says UPTIME 0 and not INIT (``primed_now``:
        primed in its first tick; ``seq``: the latest at the summary, when the reboot was told after
        it), else the next. Above both: the frame its power-up pose named, heard up to 80 ms before
        the summary (``bootnamed``: the ODOM_STATUS frames may be stamped late). No pose is adopted,
        so a firmware that comes up wrong shows its error. A summary held past its tick
        (``tick_s``): at once on ``heldboot.held_start``'s frame (``liveheldstart``), unless its
        pose names a later one. Without a known integrator: ``restart_reference``."""
        self.new_life()
        self.losses.lost_page = None  # the new firmware counts from 0
        latest = self.enc_seq if seq is None else seq
        self.reprime.count = PowerUpCount(latest)  # its first count page (livereprimecount)
        if self.integrator is None:
            self.adopted.owe(REBOOT_BEFORE_INTEGRATOR)
            return
        named = self.powerup.named_seq(self.now_s)  # its power-up pose's word (bootnamed)
        held = None if tick_s is None else held_counts(self, tick_s, primed_now)
        if held is not None and (named is None or named <= held[0][0]):  # (liveheldstart)
            self.lives.finish_boot(held[0][0], counts=held)
            return
        unnamed = latest if primed_now else latest + 1
        if named is None:
            self.lives.await_boot(unnamed, self.now_s, init=not primed_now)
        else:  # its word once the next pose counts on from it (bootnamed)
            self.lives.await_boot(named, self.now_s, unnamed, not primed_now)

    def withdraw_from(self, t_s: float) -> None:
        """A reboot told late (its boot summary held back, or told by the first pose after it:
        ``bootticks``): the samples compared from bus time ``t_s`` on were the new firmware's
        against the old life's reference; their errors and the wrong episodes they latched are
        taken back (issue #11: a reset 30 ticks in, its first pose pair lost, its next poses
        latched an 84 mm episode that FAILed the correct firmware at the bridge's end; the largest
        error beyond the loss allowance with them, which the fleet's verdict reads)."""
        self.vs_reference.withdraw_from(t_s)
        self.wrongs.withdraw_from(t_s)
        self.losses.withdraw_from(t_s)

    def new_life(self) -> None:
        """A new firmware life (a reboot): the reference starts again at the next pose, and
        the truth is compared in the new life's frame, its origin taken at the life's first
        truth sample (``compare.life_origin``, as ``analyze``)."""
        self.restart_reference()
        self.reprime.count.reboot()  # the watch no longer from its power-up (livereprimecount)
        # the new firmware's first tick sends its pose frames before its summary: the truth
        # sample of the frame it primed on may have come before the reboot was told
        self.life_truth.new_life()

    @property
    def awaiting_boot(self) -> bool:
        """A new life waits for the frame it primed on (its samples are not judged yet)."""
        return self.lives.boot is not None

    def on_enc_counts(self, ok: int, lost: int, proven: bool = False) -> None:
        """ODOM_STATUS page E2E_WHEEL_ENCODERS: ENC_E2E_OK (u16) and ENC_E2E_LOST. A reboot's
        first page names the frame it primed on (``power_up``); the first life's first, after a
        first summary of UPTIME 0, counting exactly the frames heard when it was made
        (``proven``: ``SourceWatch.on_page``) proves a power-up: (0, 0, 0) on frame 0,
        whatever the first pose said (``analyze``'s rule); then ``on_enc_lost``."""
        self.lives.on_counts(ok, lost, proven)
        self.reprime.counted()  # a re-prime at power-up waited for the proof (livereprime)
        self.on_enc_lost(lost, ok)

    def set_geometry(self, geometry: Geometry, counter_bits: int) -> None:
        """New robot parameters (a config command); the reference restarts at the next pose."""
        self.geometry = geometry
        self.counter_bits = min(counter_bits, WIRE_COUNTER_BITS)
        self.adopted.owe(CONFIG_CHANGE)
        self.restart_reference()

    def take_speed_bound(self, max_wheel_speed_mm_s: int) -> None:
        """The firmware's plausibility bound (u16 mm/s, its PROFILE page): the step gate takes it
        from the next frame on, as the firmware's gate runs with it; the reference goes on."""
        self.geometry = replace(self.geometry, max_wheel_speed_mm_s=max_wheel_speed_mm_s)
        self.raw.gate.rebound(self.geometry)

    def on_truth(
        self, part: int, enc_counter: int, value: float
    ) -> tuple[FramePose, FramePose | None] | None:
        """A SIM_TRUTH part (0 X m, 1 Y m, 2 HEADING rad); three of one encoder frame: a sample,
        returned once complete as (truth, reference at that encoder frame or None)
        (``livetruth.TruthJudge``)."""
        return self.truths.judge(part, enc_counter, value)

    @property
    def counter_restarts(self) -> int:
        """Counter restarts the current reference re-primed on (as the firmware does)."""
        return self.raw.gate.counter_restarts

    def snapshot(self) -> dict[str, Any]:
        """``pose``, ``reference``, ``truth``, ``error`` (``livesnapshot.tracker_snapshot``)."""
        return tracker_snapshot(self)
