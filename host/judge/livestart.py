"""The live reference's starts (``host.judge.tracking``): a ``ReferenceOdometry`` at a pose, primed
on the encoder frame it names, caught up over the frames heard since and the poses heard since
compared (``start_reference``); and the lives it starts in (``Lives``): the first life's
backlog (what was heard before the integrator was known), a new life's wait for the frame it
primed on after a reboot and the samples held meanwhile."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.judge.liveadopted import UNHEARD_BOOT
from odocan.host.judge.livebootbound import (
    BootWord,
    bounded_start,
    held_tick_word,
    old_life_floor,
    power_up_pose,
)
from odocan.host.judge.livefit import LiveFit
from odocan.host.judge.liveplacing import place_reference
from odocan.host.judge.livepose import FramePose, Sample
from odocan.host.judge.liveprimed import UNTOLD_PRIME, choose_primed
from odocan.host.judge.livesilentboot import SilentBoot
from odocan.host.judge.livewindow import Counted, window_counts
from odocan.host.judge.pagesent import counted_from, sent_s
from odocan.host.judge.pagetick import TICK_GAP_S, page_after, page_held_back
from odocan.host.judge.primed import counted_start
from odocan.host.judge.reference import ReferenceOdometry

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

BACKLOG_FRAMES = 6_000  # encoder frames kept while waiting for the integrator (60 s at 100 Hz)
BOOT_COUNT_WAIT_S = 1.0  # after a reboot, how long the count page is waited for (s of bus time)


def start_reference(tracker: PoseTracker, pose: FramePose, counts: list[Counted],
                    poses: list[FramePose], stalled_from: int | None = None) -> None:
    """Start ``tracker``'s reference at ``pose``, primed on the first of ``counts`` (the frame
    ``pose`` names on, stepped as heard: ``Counted``), catch up, compare the ``poses`` heard
    since; ``stalled_from``: a stall before the life's first sample was told (``livefirst``)
    before its power-up was proven, the frame the firmware could first have primed on: the
    position is placed at the first of ``poses`` from there, as ``livefirst`` owes it when the
    power-up was proven first (``analyze``: ``stalls.first_placement``)."""
    assert tracker.integrator is not None
    tracker.choice.decide()  # the samples held are judged by the reference they named
    ref = ReferenceOdometry(
        tracker.geometry, tracker.integrator, tracker.counter_bits,
        x_m=pose.x_m, y_m=pose.y_m, heading_rad=pose.heading_rad,
    )
    tracker.reference_starts += 1
    tracker.fit = LiveFit.start(pose)
    tracker.newstart.started(tracker.fit.exact)  # after an unseen restart: held (livenewstart)
    tracker.adopted.started(pose, tracker.fit.exact, tracker.pose_t_s)  # said (liveadopted)
    raw = tracker.raw
    raw.start(ref, tracker.geometry, tracker.counter_bits, tracker.restarts)
    raw.started = pose._replace(seq=counts[0][0]) if counts else None
    tracker.placer.restart()
    for frame in counts:
        step = raw.step(ref, frame)  # the first primes: stays at pose
        if tracker.choice.pending is not None:  # the twin steps along (livechoice)
            tracker.choice.stepped(frame[0], step)
    if stalled_from is not None:
        tracker.stall.owe_from(stalled_from)
        tracker.losses.stalled_first(stalled_from)  # the frames between: the placement's
    held_samples = tracker.lives.held
    for heard in poses:
        at = raw.at.get(heard.seq)
        if at is not None and stalled_from is not None and not (
                heard.seq == stalled_from and power_up_pose(heard)):  # (livebootstall)
            at, stalled_from = place_reference(tracker, heard, at), None
        held = held_samples.pop(heard.seq, None)
        if at is not None and held is not None:  # settled again, judged now
            tracker.settled.append(held._replace(reference=tracker.record(heard, at)))
        elif at is not None:
            tracker.record(heard, at)


class Lives:
    """Where ``tracker``'s reference starts: at the first pose heard (its frames kept until the
    integrator is known: ``pending``, ``backlog_counts``, ``backlog_poses``), at (0, 0, 0) on
    the frame a new life primed on (``boot``: that frame's guess (seq, -1 for the first life's)
    and the bus time it is waited until; ``boot_poses`` and ``held``: its samples meanwhile)."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        self.boot: tuple[int, float] | None = None  # after a reboot: primed guess, wait until
        self.boot_poses: list[FramePose] = []  # the new life's samples while it waits
        self.stalled_waiting = False  # ... a stall before the first of them (livebootstall)
        self.boot_named = False  # ``boot``'s frame named by its power-up pose (``bootnamed``)
        self.boot_unnamed = -1  # ... the guess without it (its first pose after not counting on)
        self.boot_tick_named = False  # ... that pose heard in the boot summary's tick
        self.boot_floor = -1  # ... the old life's latest sampled frame (``livebootbound``)
        self.boot_init = False  # ... its boot summary said INIT (``livebootbound``)
        self.held: dict[int, Sample] = {}  # ... as settled (unjudged), by encoder frame
        self.pending: FramePose | None = None  # the first pose, heard before the integrator
        self.backlog_counts: list[Counted] = []  # the frames since the pending pose's
        self.backlog_poses: list[FramePose] = []
        self.silent = SilentBoot()  # the firmware's latest silence (livesilentboot)
        self.power_up_proven = False  # the first life's first page proved a power-up at 0
        self.primed_late: int | None = None  # ... or at this frame by its count, or before
        # (``powerup.primed_after``; a recorder stamping ODOM_STATUS late: ``liveprimed``)
        self.primed_from: tuple[int | None, list[int]] | None = None  # the frame chosen, those
        # it may have primed on (``finish_primed``)
        self.page: tuple[int, int, tuple[float, int] | None, int, int | None] | None = None
        # a reboot's first count page, waiting for the next ODOM_STATUS (``on_status``):
        # ENC_E2E_OK, ENC_E2E_LOST, its bus time and COUNTER, the seq after the latest frame
        # heard before it and after the one its tick's pose names (``pagetick``; None: none)

    def waits(self, pose: FramePose, now_s: float) -> bool:
        """Whether the on-board ``pose`` waits for its life's start (a boot's frame, the
        integrator); the reference started at it when it is the first pose (then False)."""
        tracker = self._tracker
        started = tracker.raw.odometry is not None
        if not started and self.pending is None and not tracker.reference_starts:
            self.boot = self.boot or (-1, now_s + BOOT_COUNT_WAIT_S)  # the first life's
        if self.boot is not None:  # a new life waiting for the frame it primed on
            self.boot_poses.append(pose)
            return True
        if started:
            return False
        if self.pending is None:
            self.pending = pose
            self.backlog_counts = window_counts(tracker.window, pose.seq)
        if tracker.integrator is None:
            self.backlog_poses.append(pose)
            return True
        self.start_pending([])
        return False

    def heard(self, frame: Counted) -> None:
        """An encoder frame heard while a pose waits for the integrator (``pending``)."""
        self.backlog_counts.append(frame)
        if len(self.backlog_counts) > BACKLOG_FRAMES:  # too long: start at a later pose
            self.drop_backlog()

    def start_pending(self, poses: list[FramePose]) -> None:
        """Start at the pending pose over the frames kept, comparing ``poses``."""
        assert self.pending is not None
        start_reference(self._tracker, self.pending, self.backlog_counts, poses)
        self.drop_backlog()

    def drop_backlog(self) -> None:
        self.pending, self.backlog_counts, self.backlog_poses = None, [], []

    def await_boot(self, guess: int, now_s: float, unnamed: int | None = None,
                   init: bool = False) -> None:
        """A reboot: the new life's samples wait for the frame it primed on (``guess`` until
        its first count page names it) up to ``BOOT_COUNT_WAIT_S`` after ``now_s``;
        ``unnamed``: its power-up pose named ``guess`` (``bootnamed``), the page's word not
        taken over it once the first pose after the summary counted on from it, else this;
        ``init``: its boot summary said INIT (``livebootbound.after_init``)."""
        self.boot = (guess, now_s + BOOT_COUNT_WAIT_S)
        self.boot_init = init
        self.boot_named = unnamed is not None
        pose = self._tracker.powerup.latest  # the named pose in the summary's tick: the boot's
        self.boot_tick_named = self.boot_named and pose is not None and \
            0.0 <= now_s - pose[0] < TICK_GAP_S
        self.boot_unnamed = guess if unnamed is None else unnamed
        self.boot_floor = old_life_floor(self._tracker.pairs.sampled, guess)
        self.boot_poses, self.held, self.page = [], {}, None
        self.stalled_waiting = False

    def expire(self) -> None:
        """The wait for the count page is over: start without it (a page heard with no
        ODOM_STATUS frame after it: from where it was heard)."""
        assert self.boot is not None
        if self.page is not None:
            ok, lost, _, heard_after, named = self.page
            after = heard_after if named is None else named
            self.page = None
            window = self._tracker.window
            encoders = (window.col("seq").astype(np.int64), window.col("counter").astype(np.int64))
            at = self._halted_named(counted_start(encoders, after, ok, lost))
            if at is not None:
                self.finish_boot(self._within_named(encoders, at))
                return
        if self.boot[0] < 0:
            self.finish_first(False)
        else:
            self.finish_boot(self.boot[0] if self._named() else self._held_or_unnamed())

    def _halted_named(self, at: int | None) -> int | None:
        """A count page's frame ``at``, or the frame the waiting boot's power-up pose named when
        its first pose after the summary, late, counted on from it by its COUNTER alone: the MCU
        halted right after its first tick (``bootnamed.counts_on_after``), its page counting
        over frames its mailbox overran. Its life waited on (its halt told, ``livebootstall``)."""
        boot = self.boot
        return boot[0] if boot is not None and self.boot_named and \
            self._tracker.powerup.halted else at

    def _held_or_unnamed(self) -> int:
        """A boot whose wait ended with no count page: its power-up pose's frame after a halt
        (``_halted_named``); the frame that pose, held back just past the summary, names when it
        came in the summary's tick (``livebootbound.held_tick_word``); else the summary's own
        rule's."""
        assert self.boot is not None
        halted = self._halted_named(None)
        if halted is not None:
            return halted
        window = self._tracker.window
        word = BootWord(None, self.boot_unnamed, self.boot[1] - BOOT_COUNT_WAIT_S,
                        self.boot_floor, self.boot_init)
        held = held_tick_word(self._tracker.powerup, word, (
            window.col("seq").astype(np.int64), window.col("t_s").astype(np.float64)))
        return self.boot_unnamed if held is None else held

    def on_counts(self, ok: int, lost: int, proven: bool) -> None:
        """``PoseTracker.on_enc_counts``' start: the page ends a wait, or proves a power-up; the
        first life's samples start from (0, 0, 0) on the frame its first count page says it
        primed on, that page's frame or one before it that its first pose allows
        (``finish_primed``: a recorder stamping ODOM_STATUS late overcounts the page). A new
        life's page waits for the next ODOM_STATUS frame, which tells its send (``on_status``),
        also when the window cannot count it from where it was heard: held back 55 ms in order,
        figure8 680's (OK 3, LOST 3) was dropped, and its second page (read as a first) started
        the life 2 frames late, 20 mm beyond (issue #11)."""
        boot, tracker = self.boot, self._tracker
        started = self.power_up_proven  # by the stall (``livefirst``): not started again
        self.power_up_proven |= proven  # (``livefirst``: also when no frame was heard yet)
        if boot is not None and boot[0] < 0 and self.primed_late is not None \
                and tracker.integrator is not None:
            self.finish_primed(self.primed_late)
        elif boot is not None and boot[0] < 0:  # the first life's samples wait
            self.finish_first(proven)
        elif boot is not None and self._named():
            self.finish_boot(boot[0])
        elif boot is not None and len(tracker.window):  # counted from its send (on_status)
            after, named = page_after(tracker)  # its tick's pose's word (``pagetick``)
            self.page = (ok, lost, tracker.status_heard, after, named)
        elif proven and not started and tracker.integrator is not None:
            self.finish_boot(0, first_life=True)  # the samples judged before keep their errors

    def on_status(self, t_s: float, counter: int) -> None:
        """The ODOM_STATUS frame heard after a reboot's first count page (``page``): it tells
        when that page was sent (``pagesent``); the new life starts on the frame the page
        counts back to from the frame its tick's pose names unless it was held back, else from
        its send (``pagetick``)."""
        if self.page is None or self.boot is None:
            self.page = None
            return
        ok, lost, heard, after, named = self.page
        self.page = None
        window = self._tracker.window
        seqs = window.col("seq").astype(np.int64)
        if heard is None:
            sent = after if named is None else named
        elif named is not None and not page_held_back(heard[0], sent_s(heard, (t_s, counter))):
            sent = named  # (``pagetick``)
        else:
            sent = counted_from(after, sent_s(heard, (t_s, counter)),
                                (seqs, window.col("t_s").astype(np.float64)))
        encoders = (seqs, window.col("counter").astype(np.int64))
        at = counted_start(encoders, sent, ok, lost)
        if at is None:  # the window lacks it from there: where the page was heard
            at = counted_start(encoders, after, ok, lost)
        at = self._halted_named(at)
        if at is not None:
            self.finish_boot(self._within_named(encoders, at))

    def finish_primed(self, k: int) -> None:
        """The first life's samples from (0, 0, 0) on the frame it primed on, one of 0 .. k
        its first pose allows (``liveprimed.choose_primed``; ``primed_from``: that frame and
        them); when not told, from its first pose, fitted, the start said adopted."""
        primed, frames = choose_primed(self._tracker, k, self.boot_poses)
        self.primed_from = (primed, frames)
        if primed is not None:
            self.finish_boot(primed, first_life=True)
            return
        self._tracker.adopted.owe(UNTOLD_PRIME.format(lo=min(frames), hi=max(frames)))
        self.finish_first(False)

    def _within_named(self, encoders: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]],
                      at: int) -> int:
        """A count page's frame ``at`` bounded by the waiting boot's power-up pose's word
        (``livebootbound``: no later than it, ``primed.within_named``), when that pose came in
        the boot summary's tick (one heard 20..60 ms before it may be the old firmware's, the
        new one's lost on the bus, and the count right: ``tests/test_reboot_lost_powerup.py``)
        or held back just after it."""
        if self.boot is None:
            return at
        word = BootWord(self.boot[0] if self.boot_tick_named else None, self.boot_unnamed,
                        self.boot[1] - BOOT_COUNT_WAIT_S, self.boot_floor, self.boot_init)
        return bounded_start(encoders, at, word, self._tracker.powerup)

    def _named(self) -> bool:
        """Whether the waiting boot's frame is its power-up pose's word (``await_boot``)."""
        return self.boot_named and self._tracker.powerup.corroborated

    def finish_boot(self, primed: int, first_life: bool = False,
                    counts: list[Counted] | None = None) -> None:
        """Start the new life's reference at (0, 0, 0) at encoder frame ``primed`` (seq), judge
        the samples heard since the reboot; adopt the next pose when that frame is not known (not
        heard yet, or left the window). ``first_life``: the log's first (one start)."""
        tracker = self._tracker
        poses, self.boot, self.boot_poses = self.boot_poses, None, []
        counts = window_counts(tracker.window, primed) if counts is None else counts
        if not counts or counts[0][0] != primed:
            if not first_life:  # a first life keeps its fitted start
                tracker.adopted.owe(UNHEARD_BOOT)
                tracker.restart_reference()
            return
        tracker.reference_starts -= first_life and tracker.reference_starts > 0
        if first_life:  # (a stall before its first pose left it unproven: livefirst)
            tracker.first.proven_after_all(tracker)
        tracker.placer.seen.power_up(primed)  # its boot a page before (gapseen.with_boot)
        page = tracker.losses.primed(primed, not first_life)  # ENC_E2E_LOST from 0 there
        stalled = tracker.first.stalled_from if first_life and poses else None  # told before
        if self.stalled_waiting and poses and not first_life:  # halted after its first tick
            stalled = primed  # (``livebootstall``)
        self.stalled_waiting = False
        start_reference(tracker, FramePose(primed, 0.0, 0.0, 0.0), counts, poses, stalled)
        if page is not None:  # the life's page heard before its frame was known, from it
            tracker.losses.on_page(page[0], page[1], tracker.window, tracker.pairs.sampled,
                                   (tracker.geometry, tracker.counter_bits, tracker.integrator),
                                   page[2])
        tracker.powerpose.booted(counts)  # its power-up pose left out (livepowerpose)
        if not first_life:
            tracker.life_truth.booted(primed, tracker.raw.at)

    def finish_first(self, proven: bool) -> None:
        """The first life's samples waited for its first ENC_E2E_OK page (``powerup``'s
        evidence): ``proven``, judged from (0, 0, 0) on frame 0 as ``analyze`` judges them (once
        the integrator is known); else (a cut log, no page within ``BOOT_COUNT_WAIT_S``) from
        the first of them, fitted."""
        tracker = self._tracker
        if proven and tracker.integrator is not None:
            self.finish_boot(0, first_life=True)
            return
        poses, self.boot, self.boot_poses = self.boot_poses, None, []
        counts = window_counts(tracker.window, 0) if proven else []
        zero = bool(counts) and counts[0][0] == 0  # frame 0 still in the window
        self.pending = FramePose(0, 0.0, 0.0, 0.0) if zero else poses[0]
        self.backlog_poses = poses
        self.backlog_counts = counts if zero else window_counts(tracker.window, poses[0].seq)
        if tracker.integrator is not None:
            self.start_pending(poses)
