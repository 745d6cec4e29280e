"""Who sends ODOM_STATUS: one firmware, a rebooted one, or two on one ID -- told from UPTIME.

The one detection of a firmware reboot, shared by the live monitor (``host.judge.monitor``) and
the log analysis (``host.judge.analysis``): a source's UPTIME (whole seconds) minus bus time stays
constant within ``UPTIME_MATCH_S``; a reboot moves that offset once, or sends an UPTIME below the
last one (even within ``UPTIME_MATCH_S``: a reboot a second or two after power-up), or says INIT
after running, or (within its first second, UPTIME 0 again) its power-up tick's E2E COUNTERs
(``host.judge.bootticks``); two sources on one ID make two offsets interleave (two sources whose
offsets differ by less than ``UPTIME_MATCH_S`` look like reboots); a summary made before a halt
and sent after it is neither (``haltedsend``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from odocan.host.judge.aheadticks import boot_ahead_heard
from odocan.host.judge.bootticks import (
    POSE_MESSAGE,
    STATUS_MESSAGE,
    TWIST_COUNTERS,
    ahead_candidate,
    boot_tick,
    continues_summary,
    next_run,
    pose_heard,
    tied_to_boot,
    tied_to_run,
    told_run_s,
)
from odocan.host.judge.distfall import (
    RECENT_TWISTS,
    TWIST_MESSAGE,
    DistanceField,
    RecentTwists,
    distance_field,
    fell_within,
)
from odocan.host.judge.haltedsend import sent_after_halt
from odocan.host.judge.heldtick import TickPages, told_tick
from odocan.host.judge.latefall import continues_twice, tied_late
from odocan.host.judge.liveadopted import LATE_REBOOT
from odocan.host.judge.livefreshboot import powerup_heard
from odocan.host.judge.livegapseen import heard_status
from odocan.host.judge.liveheard import heard_before_live, pose_named_live
from odocan.host.judge.liveheldpose import PoseOrder
from odocan.host.judge.livelatestatus import StatusOrder
from odocan.host.judge.livesilentboot import started_after_silence
from odocan.host.judge.livestreams import LiveStreams, hear_pose_frame, pose_told_first
from odocan.host.judge.navrestart import NAV_MESSAGE, restarted_within
from odocan.host.judge.powerup import (
    holds_first_cycle,
    primed_by_count,
    same_tick,
    tick_bound_s,
)
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.e2e import crc8h2f_p02_one
from odocan.host.protocol.e2e_live import E2EMonitor

if TYPE_CHECKING:  # the live judges' (a log's analysis imports this module, not cantools, nor
    # the live judge: ``odocan run`` and ``analyze`` would compile and build it for nothing)
    from cantools.database.can import Database, Message

    from odocan.host.judge.tracking import PoseTracker

FIRMWARE_NODE = "ODOM_MCU"  # the DBC node that sends the firmware's frames (ODOM_STATUS, ...)
UPTIME_MATCH_S = 2.0  # one source's UPTIME (whole s) minus bus time stays within this
CONFLICT_HOLD_S = 2.0  # CONFLICT is shown this long after two sources last interleaved
STATUS_COUNTER_MODULO = busfacts.STATUS_COUNTER_LAP  # ODOM_STATUS's E2E COUNTER (4 bits: 16)
STATUS_CYCLE_MS = busfacts.STATUS_CYCLE_MS  # ODOM_STATUS's GenMsgCycleTime (100)
TIMES_KEPT = 8  # summaries kept for ``powerup.tick_bound_s`` (a wrap of STATUS_COUNTER_MODULO)


@dataclass
class SourceWatch:
    """One node's UPTIME against bus time, summary after summary: a single source keeps
    UPTIME - t constant (to the second), a reboot moves it once, two sources on one ID make two
    offsets interleave."""

    offset_s: float | None = None  # UPTIME - bus time of the source followed
    other_s: float | None = None  # the offset before the last change
    last_uptime_s: int = 0
    last_state: str = ""
    conflict_until_s: float = -math.inf
    first_uptime_s: int | None = None  # the first summary's UPTIME, even held back (analyze)
    page_pending: bool = True  # the first life's first ENC_E2E_OK page not heard yet
    changed_at_s: float | None = None  # when the offset followed last changed to a new one
    conflict_from_s: float | None = None  # two sources: when the second offset first came
    # (or the pose streams began to interleave: ``livestreams``)
    conflict_detail: str = ""  # the pose streams' reason (``livestreams.detail_text``)
    streams: LiveStreams = field(default_factory=LiveStreams)  # the pose streams' watch
    summary: tuple[int, int, int | None] | None = None  # the latest accepted one: COUNTER,
    # the encoder frames heard, those up to the frame the latest pose names (liveheard)
    first_counter: int | None = None  # the first accepted page's COUNTER, any page
    before_first: int = 0  # the encoder frames heard before it (``powerup.primed_after``)
    summary_times: list[tuple[int, float]] = field(default_factory=list)  # the latest
    # summaries' COUNTER and bus time (``powerup.tick_bound_s``)
    pose: tuple[float, int, bool] | None = None  # the ODOM_POSE_X frames' run (``next_run``)
    pose_s: float | None = None  # the bus time of the latest ODOM_POSE_X heard (``hear_pose``)
    status_before: tuple[float, int] | None = None  # bus time, COUNTER of the ODOM_STATUS
    status_last: tuple[float, int] | None = None  # frame before the latest, and the latest
    summary_s: float | None = None  # the bus time of the latest summary observed
    life_from_s: float = -math.inf  # where the latest reboot told began: its summary's bus
    # time, or its pose run's start when that was a power-up tick (``bootticks``: held back)
    ahead: tuple[float, int, str, int | None, bool] | None = None  # the latest summary, when
    # the first pose after it may tell it a power-up tick with no pose (``bootticks.boot_ahead``):
    # its bus time, UPTIME, STATE, the encoder frame latest heard, whether it broke the sequence
    ahead_posed: tuple[float, int, str, int | None] | None = None  # such a summary (its first
    # four) whose first pose after it leaves the next summary to tell (``told_ahead``)
    first: Any = None  # the live tracker's ``livefirst.FirstStall``: told, at ``take_ahead``,
    ahead_heard: list[float] = field(default_factory=list)  # the frames (bus times) heard since
    # the summary (poses, ODOM_STATUS, any sequence: the E2E check refused them till then)
    twist_field: DistanceField | None = None  # where ODOM_TWIST says DISTANCE (``distfall``)
    ahead_fall: bool = False  # ``ahead_posed`` needs the twists' DISTANCE fell (``told_ahead``)
    ahead_late: tuple[float, int, str, int | None] | None = None  # such a summary continued
    # with no fall yet: the second summary after it reads one (``latefall``, ``told_ahead``)
    twists: RecentTwists = field(  # the latest twists heard in order (bus time, bytes),
        default_factory=RecentTwists)  # read only at ``hear_pose``
    nav_ids: tuple[int, ...] | None = None  # NAV_STATUS's E2E DataIDs (``navrestart``)
    navs: deque[tuple[float, bytes]] = field(  # the latest NAV_STATUS heard (bus time, bytes)
        default_factory=lambda: deque(maxlen=RECENT_TWISTS))  # read as ``twists`` are
    order: StatusOrder = field(default_factory=StatusOrder)  # ODOM_STATUS frames held back,
    # live (``hear_status``; ``livelatestatus``)
    pose_order: PoseOrder = field(default_factory=PoseOrder)  # ODOM_POSE_X's (``hear_pose``)
    pose_late: bool = False  # the latest ODOM_POSE_X of COUNTER 0 heard was held back
    status_late: tuple[bool, bool] = (False, False)  # the ODOM_STATUS frame before the latest
    # and the latest were held back (``order``; as ``status_before`` and ``status_last``)
    held_tick_s: float | None = None  # the latest reboot's held summary's tick (heldtick)
    ticks: TickPages = field(default_factory=TickPages)  # a boot summary held past its tick's
    # page (``heldtick``): live, heard at ``hear_pose``, ``hear_status``; a log's: ``told`` set

    def on_page(self, page: str, signals: dict[str, Any], tracker: PoseTracker) -> bool:
        """An accepted ODOM_STATUS ``page`` (``"summary"``, ``"e2e_wheel_encoders"``, ...):
        whether it is the first life's first ENC_E2E_OK page, after a first summary of UPTIME
        0, and proves a power-up (``PoseTracker.on_enc_counts``, ``LiveDistance.on_counts``):
        its ENC_E2E_OK counts the encoder frames heard when the firmware made it, as
        ``powerup.counted_only_the_log`` counts them (before the summary of its tick when that
        is the latest heard, for the page may have been held back past frames it could not
        count, else before it; or up to the frame the latest pose before that names); or with
        its ENC_E2E_LOST added (``powerup.counted_only_the_log``). Once. Else, when it counts
        the frames heard less the first k, all before the first ODOM_STATUS frame heard, the
        firmware primed on frame k (``powerup.primed_after``): ``Lives.primed_late``. The tick
        bound's count is no evidence after a stall (``stallpowerup.stalled_before_page``: the
        halt held the page's tick past it; issue #11: 11 frames from the first met ENC_E2E_OK
        11 by chance, and the correct firmware, primed a frame later, was DISTANCE WRONG)."""
        if not self.page_pending:  # heard, or a reboot came first: nothing to count
            return False
        heard = (tracker.enc_seq + 1, pose_named_live(tracker))
        if self.first_counter is None:
            self.first_counter, self.before_first = int(signals["COUNTER"]), heard[0]
        if page == "summary":
            self.summary = (int(signals["COUNTER"]), *heard)
            self.summary_times = [*self.summary_times[-TIMES_KEPT + 1:],
                                  (int(signals["COUNTER"]), tracker.now_s)]
        if page != "e2e_wheel_encoders":
            return False
        self.page_pending = False
        if self.first_uptime_s != 0 or not holds_first_cycle(self.first_counter):
            return False
        if self.summary is not None and same_tick(int(signals["COUNTER"]), self.summary[0],
                                                  STATUS_COUNTER_MODULO):
            heard = self.summary[1:]
        ok = int(signals["ENC_E2E_OK"])
        bound_s = tick_bound_s(int(signals["COUNTER"]), self.summary_times, STATUS_COUNTER_MODULO,
                               STATUS_CYCLE_MS)
        stalled = tracker.stall.stalls and tracker.first.stalled_from is None  # after a pose
        by_tick = (None if bound_s is None or stalled  # a stall before the page: its tick came
                   else heard_before_live(tracker, bound_s, heard[0]))  # past the bound
        spanned = (ok + int(signals.get("ENC_E2E_LOST", 0))) & 0xFFFF  # accepted or lost
        if {ok, spanned} & {heard[0] & 0xFFFF, heard[1], by_tick}:
            return True
        # the count's k; taken unless the first pose names a frame before it (``Lives.on_counts``)
        tracker.lives.primed_late = primed_by_count(heard[0], (ok, spanned), by_tick,
                                                    self.before_first)
        return False

    def observe(self, t_s: float, uptime_s: int, state: str, counter: int | None = None,
                ahead: bool = False, seq: int | None = None, fell: bool | None = None,
                late: bool | None = None, held: tuple[bool, bool] | None = None) -> str | None:
        """One ODOM_STATUS summary (``counter``: its E2E COUNTER, None: not told; with the
        watch's ``pose``, the run of the ODOM_POSE_X frames heard before the summary, it tells
        a power-up tick: ``bootticks.boot_tick``; ``ahead``: the first pose after it told one,
        ``bootticks.boot_ahead``, a log's; ``seq``: the encoder frame latest heard, live;
        ``fell``: a twist of that run fell, ``bootticks.fell_in_run``, a log's; None: read from
        ``twists``, live; ``late``: the bus held it back behind later ODOM_STATUS frames and it
        says no reboot against the summary sent before it, ``livelatestatus``, a log's; None:
        ``order``'s, live; ``held``: whether the pose of COUNTER 0 that began ``pose`` was
        held back, and whether the summary or the ODOM_STATUS frame before it was, a log's,
        ``heldsummaries``; None: the watch's ``pose_late`` and ``status_late``, live); returns
        ``"reboot"``, ``"two sources"``, ``"uptime jump"`` or None. Such a summary is none of
        them: it says the UPTIME and state its firmware had when it sent it, and is passed over
        unless it is a power-up tick. A frame held back breaks no sequence of a life (it fills
        a hole of its sender's: ``livelatestatus``), so it is no power-up tick's evidence
        (``bootticks.boot_tick``'s ``held``); a new firmware's pose of COUNTER 0 repeats one
        heard in order, unless the bus lost that as well. Issue #11: kobuki random 696,
        ``delay=0.1:150``: the log's own power-up tick (pose and summary) held back to 0.151 s;
        690: the pose of COUNTER 0 of 0.641 s held back to 0.791 s, the summary of COUNTER 0 at
        0.801 s right after a summary of COUNTER 12 held back: each was told a reboot by every
        judge. A summary the first pose after it may tell is kept in ``ahead`` (live:
        ``hear_pose``, ``told_ahead``)."""
        offset, kind = uptime_s - t_s, None
        self.first_uptime_s = uptime_s if self.first_uptime_s is None else self.first_uptime_s
        pose_held, status_held = (self.pose_late, any(self.status_late)) if held is None else held
        pose = (self.pose[0], self.pose[1], False) if pose_held and self.pose else self.pose
        booted = counter is not None and boot_tick(uptime_s, counter, t_s, pose, self.summary_s,
                                                   self.status_before, held=status_held)
        if not booted and counter == 0 and uptime_s == 0 and self.pose is not None:
            fell = self._fell_in_run(t_s) if fell is None else fell
            booted = boot_tick(uptime_s, counter, t_s, pose, self.summary_s,
                               self.status_before, fell, held=status_held)
        held_tick = None if counter != 0 or uptime_s != 0 else told_tick(  # (``heldtick``)
            self.ticks.told, lambda s: self._fell_in_run(s) if self.ticks.fell is None else True)
        tick = None if booted else held_tick
        booted = booted or tick is not None  # held past its tick's page
        if not booted and self._passed_over((t_s, uptime_s, state, counter), late):
            return None  # held back, or made before a halt: no reboot, no second source
        broke = (None if booted or counter is None else
                 ahead_candidate(uptime_s, counter, t_s, self.summary_s, self.status_before))
        booted, ahead = booted or (ahead and broke is not None), ahead and not booted
        self.summary_s, self.ahead, self.ahead_posed = t_s, None, None
        if self.offset_s is None:
            self.offset_s = offset
        elif abs(offset - self.offset_s) <= UPTIME_MATCH_S:
            if booted or (state == "INIT" and self.last_state not in ("", "INIT")) or (
                uptime_s < self.last_uptime_s  # one source's UPTIME never goes back
            ):
                kind = "reboot"
                self.offset_s = offset
                self.life_from_s = self._told_from(t_s, booted and not ahead)
                self.life_from_s = self.life_from_s if tick is None else min(t_s, tick[1])
            elif broke is not None:  # the first pose after it may tell it (``hear_pose``)
                self.ahead, self.ahead_heard = (t_s, uptime_s, state, seq, broke), [t_s]
        elif self.other_s is not None and abs(offset - self.other_s) <= UPTIME_MATCH_S:
            kind = "two sources"
            self.conflict_until_s = t_s + CONFLICT_HOLD_S
            if self.conflict_from_s is None or (  # it began when the second offset first
                    self.changed_at_s is not None  # came, unless the poses told it well before
                    and not pose_told_first(self.conflict_from_s, self.changed_at_s)):
                self.conflict_from_s, self.conflict_detail = self.changed_at_s, ""
            self.offset_s, self.other_s = self.other_s, self.offset_s
        else:
            kind = "reboot" if uptime_s < self.last_uptime_s or state == "INIT" else "uptime jump"
            self.life_from_s = self._told_from(t_s, booted and not ahead and kind == "reboot")
            self.offset_s, self.other_s = offset, self.offset_s
            self.changed_at_s = t_s
        if kind == "reboot" and not booted and counter is not None and (
                run_s := told_run_s(uptime_s, counter, t_s, self.pose)) is not None:
            self.life_from_s = min(self.life_from_s, run_s)  # its poses heard before its summary
        self.last_uptime_s, self.last_state = uptime_s, state
        self.page_pending = self.page_pending and kind != "reboot"
        self.held_tick_s = (  # its life starts where ``heldboot.held_start`` says (liveheldstart)
            self.held_tick_s if kind != "reboot" else None if held_tick is None else held_tick[0])
        return kind

    def _passed_over(self, summary: tuple[float, int, str, int | None], late: bool | None
                     ) -> bool:
        """Whether the summary (bus time, UPTIME, STATE, COUNTER) says nothing of a reboot or
        a second source: the bus held it back behind later frames of its sender
        (``livelatestatus``; ``late``: a log's, None: ``order``'s, live), or its firmware made
        it before a halt and sent it after (``haltedsend``: told to the live tracker's
        ``first``, ``livefirst.FirstStall.halted_sent``)."""
        if self.order.passed_over(*summary[1:3]) if late is None else late:
            return True
        if self.offset_s is None or not sent_after_halt(
                summary, self.offset_s, UPTIME_MATCH_S, (self.last_uptime_s, self.last_state),
                self.status_before):
            return False
        if self.first is not None:
            self.first.halted_sent(summary[0], summary[3])
        return True

    def _told_from(self, t_s: float, power_up_tick: bool) -> float:
        """Where a reboot told by the summary at bus time ``t_s`` began: the pose run's pose of
        COUNTER 0 when the summary was that run's ``power_up_tick``, else ``t_s``, whether
        UPTIME's offset stayed within ``UPTIME_MATCH_S`` or not: figure8 673's boot summary,
        held back 55 ms behind its first three poses, 2.055 s after the old life's, began the
        new life at its own time (live 588.5 mm beyond on a correct firmware; issue #11)."""
        return min(t_s, self.pose[0]) if power_up_tick and self.pose else t_s

    def _fell_in_run(self, summary_s: float) -> bool:
        """Whether a twist kept live fell where it is the pose run's before the summary at
        ``summary_s`` (``bootticks.tied_to_run``)."""
        return self.evidence(lambda t_s, counter, _before_s: tied_to_run(t_s, counter, summary_s))

    def evidence(self, tied: Callable[[float, int, float], bool]) -> bool:
        """Whether a twist kept live fell (``distfall.fell_within``) or a NAV_STATUS kept live
        restarted its sequence (``navrestart.restarted_within``) where ``tied`` takes it."""
        return (fell_within(self.twist_field, self.twists, tied, TWIST_COUNTERS)
                or restarted_within(self.nav_ids, self.navs, tied))

    def hear_pose(self, t_s: float, counter: int) -> None:
        """An ODOM_POSE_X whose CRC holds, heard at bus time ``t_s`` with E2E ``counter``,
        whatever its sequence: on the pose run (``bootticks.next_run``). The first after an
        ``ahead`` summary may leave the next summary to tell that one a power-up tick
        (``bootticks.boot_ahead``, ``told_ahead``)."""
        before = None if self.pose is None or self.pose_s is None else (self.pose_s, self.pose[1])
        self.pose = next_run(self.pose, t_s, counter, self.pose_s, self.status_last is not None)
        self.pose_s = t_s
        held = self.pose_order.hear(counter, t_s)  # a hole of its sequence filled (liveheldpose)
        self.ticks.hear_pose(t_s, counter)
        self.pose_late = held if counter == 0 else self.pose_late
        if self.ahead is not None or self.ahead_posed is not None or self.ahead_late is not None:
            self.ahead_heard.append(t_s)
        ahead, self.ahead = self.ahead, None
        if ahead is None:
            return
        sure = boot_ahead_heard(ahead[0], ahead[4], t_s, counter, before, held)
        if sure or boot_ahead_heard(ahead[0], ahead[4], t_s, counter, before, held, True):
            self.ahead_posed, self.ahead_fall = ahead[:4], not sure  # fell: at ``told_ahead``

    def told_ahead(self, t_s: float, uptime_s: int, counter: int
                   ) -> tuple[float, int, str, int | None] | None:
        """The next summary (bus time ``t_s``, UPTIME, E2E ``counter``) after one left to it by
        ``hear_pose``, before it is observed: that one a power-up tick when this continues its
        sequence (``bootticks.continues_summary``): a reboot from it on (its bus time, UPTIME,
        STATE, the encoder frame latest heard then, returned); else None. One whose first pose
        told it only with DISTANCE fallen and no fall heard yet waits to the summary after
        (``latefall``: the first twist heard since it fell by then)."""
        late, self.ahead_late = self.ahead_late, None
        if late is not None and continues_twice(late[0], t_s, uptime_s, counter) and self.evidence(
                lambda t_s, counter, before_s: tied_late(t_s, counter, before_s, late[0])):
            self.take_ahead(late[0], late[1])
            return late
        posed, self.ahead_posed = self.ahead_posed, None
        if posed is None or not continues_summary(posed[0], t_s, uptime_s, counter):
            return None
        summary_s = posed[0]  # (``fell_around``)
        if self.ahead_fall and not self.evidence(
                lambda t_s, counter, _before_s: tied_to_boot(t_s, counter, summary_s)):
            self.ahead_late = posed  # no fall yet: the next summary reads a late one
            return None
        self.take_ahead(posed[0], posed[1])
        return posed

    def take_ahead(self, t_s: float, uptime_s: int) -> None:
        """The summary at bus time ``t_s`` (UPTIME ``uptime_s``) was a power-up tick, told by
        the first pose after it (``bootticks.boot_ahead``): a reboot there, as ``observe``'s.
        The frames its firmware sent since (refused by the E2E check until now) tell ``first``
        it talked then: no stall before its first sample (``livefirst.FirstStall.told``)."""
        self.offset_s, self.life_from_s, self.page_pending = uptime_s - t_s, t_s, False
        self.held_tick_s = None  # not held past its tick
        if self.first is not None:
            self.first.told(self.ahead_heard)

    def hear_status(self, t_s: float, counter: int) -> None:
        """An ODOM_STATUS frame (any page) whose CRC holds, heard at bus time ``t_s`` with E2E
        ``counter``, whatever its sequence, before it is observed: the one before a summary
        tells whether it breaks the sequence (``bootticks.status_breaks``)."""
        self.status_before, self.status_last = self.status_last, (t_s, counter)
        self.status_late = (self.status_late[1], self.order.hear(counter))
        self.ticks.hear_status(t_s, counter)
        if self.ahead_posed is not None or self.ahead_late is not None:
            self.ahead_heard.append(t_s)

    def conflict_text(self) -> str:
        """The verdict's reason once two sources were seen (``two_sources_text``); "" before."""
        if self.conflict_from_s is None:
            return ""
        return self.conflict_detail or two_sources_text(self.conflict_from_s)

    def observe_quiet(
        self, t_s: npt.NDArray[np.float64], uptime_s: npt.NDArray[np.int64],
        states: npt.NDArray[np.object_], booted: npt.NDArray[np.bool_] | None = None,
    ) -> int:
        """``observe`` of the summaries given (bus times, UPTIMEs, STATE names, in order) up to
        the first one that ``observe`` would return something for or follow another offset at,
        which is left unobserved; returns how many were observed (all: ``len(t_s)``). The
        same state as ``observe`` one by one, vectorised (a log's summaries are mostly quiet);
        ``booted``: which are a power-up tick (``bootticks.boot_ticks``; None: none).
        """
        if self.offset_s is None or len(t_s) == 0:
            return 0
        init = states == "INIT"
        idle = init | (states == "")  # a state after which INIT is no reboot
        before_uptime_s = np.concatenate(([self.last_uptime_s], uptime_s[:-1]))
        before_idle = np.concatenate(([self.last_state in ("", "INIT")], idle[:-1]))
        loud = (
            ~(np.abs((uptime_s - t_s) - self.offset_s) <= UPTIME_MATCH_S)
            | (init & ~before_idle)
            | (uptime_s < before_uptime_s)
        )
        if booted is not None:
            loud |= booted
        count = int(np.argmax(loud)) if loud.any() else len(t_s)
        if count:
            self.last_uptime_s, self.last_state = int(uptime_s[count - 1]), str(states[count - 1])
            self.summary_s = float(t_s[count - 1])
        return count


def two_sources_text(t_s: float) -> str:
    """Why a verdict FAILs when two firmwares answered on one node ID from bus time ``t_s``."""
    return f"two firmwares answered on one node ID from t={t_s:.3f} s: the pose cannot be judged"


def boot_summary(message: Message, data: bytes, data_ids: Any,
                 decode: Callable[[bytes], dict[str, Any]] | None = None) -> tuple[int, str] | None:
    """(UPTIME s, STATE) of an ODOM_STATUS summary whose CRC holds, whatever its E2E sequence
    (a rebooted firmware restarts it); ``data_ids``: the message's E2E DataIDs. None otherwise.
    ``decode``: ``message``'s ``decode(data, decode_choices=False)`` compiled (the bridge's
    ``LiveDecoder``, per summary of every robot); PAGE and STATE named by their DBC choices
    here, as cantools names them (a value without one as its number)."""
    if message.name != "ODOM_STATUS" or len(data) != 8:
        return None
    if not data_ids or data[0] != crc8h2f_p02_one(data, data_ids[data[1] & ENC_COUNTER_MASK]):
        return None
    try:
        signals = (decode or _plain_decoder(message))(data)
    except Exception:  # not decodable: the E2E check and the caller count it
        return None
    values: dict[str, Any] = dict(signals)
    if _choice_name(message, "PAGE", values.get("PAGE")) != "SUMMARY":
        return None
    return int(values["UPTIME"]), _choice_name(message, "STATE", values["STATE"])


def _plain_decoder(message: Message) -> Callable[[bytes], dict[str, Any]]:
    def decode(data: bytes) -> dict[str, Any]:
        signals = message.decode(data, decode_choices=False)
        assert isinstance(signals, dict)
        return signals
    return decode


def _choice_name(message: Message, signal: str, value: Any) -> str:
    """``str`` of ``value`` decoded with its choices, as cantools' ``decode_choices`` gives it."""
    choices = message.get_signal_by_name(signal).choices if value is not None else None
    return str(choices[value]) if choices and value in choices else str(value)


def status_frame(tracker: PoseTracker, message: Message, data: bytes, e2e: Any, t_s: float
                 ) -> tuple[int, str] | None:
    """Any ODOM_STATUS frame heard at bus time ``t_s``, whatever its E2E sequence (``e2e``: the
    message's ``E2EMessage`` or None): each page to the live gapseen
    (``livegapseen.heard_status``); a summary's ``boot_summary``."""
    data_ids = e2e.data_ids if e2e is not None else None
    heard_status(tracker, message, data, data_ids, t_s)
    return boot_summary(message, data, data_ids)


def pose_frame(watch: SourceWatch, message: Message, data: bytes, e2e: Any, t_s: float,
               tracker: PoseTracker | None = None) -> None:
    """Any frame heard at bus time ``t_s``: an ODOM_POSE_X whose CRC holds, whatever its E2E
    sequence (``e2e``: the message's ``E2EMessage`` or None), goes on ``watch``'s pose run (its
    COUNTERs tell a power-up tick: ``bootticks.next_run``), one of COUNTER 0 to ``tracker``'s
    power-up poses (``bootnamed.LivePowerUp``: the E2E check may refuse it, a new life's)."""
    if message.name in (POSE_MESSAGE, STATUS_MESSAGE):
        counter = pose_heard(data, e2e.data_ids if e2e is not None else None)
        if counter is not None and message.name == POSE_MESSAGE:
            watch.hear_pose(t_s, counter)
            hear_pose_frame(watch, message.name, data, t_s, tracker)  # two pose streams
            if tracker is not None:  # (bootnamed)
                powerup_heard(tracker, counter, lambda: _plain_decoder(message)(data), t_s)
        elif counter is not None:
            watch.hear_status(t_s, counter)
    elif message.name == TWIST_MESSAGE:  # its DISTANCE, read when a pose may tell a reboot
        if watch.twist_field is None:
            watch.twist_field = distance_field(message, e2e)
        watch.twists.hear(watch.twist_field, t_s, data)  # held back: left out (distfall)
    elif message.name == NAV_MESSAGE:  # its COUNTER, read as the twists are (``navrestart``)
        watch.nav_ids = e2e.data_ids if e2e is not None else None
        watch.navs.append((t_s, data))


def start_new_life(tracker: PoseTracker, e2e: E2EMonitor, db: Database,
                   uptime_s: int, state: str, seq: int | None = None,
                   watch: SourceWatch | None = None) -> str:
    """A reboot told by ``SourceWatch``: the reference starts at the power-up pose when the
    summary says UPTIME 0 (``PoseTracker.power_up``; ``host.judge.reboots``), else (more than a
    second after the boot: its page of encoder E2E counts may be gone too) at the next pose;
    the E2E sequences of the messages ``FIRMWARE_NODE`` sends in ``db`` start afresh (a reboot
    is not frames lost; ``seq``: the encoder frame latest heard at the summary, when told
    after it, ``bootticks.boot_ahead``; ``watch``: its ``held_tick_s``). Returns what was done."""
    tracker.placer.seen.new_life()  # its pages count from 0 (host.judge.livegapseen)
    tracker.placer.dark.new_life()  # no pose adopted before it carried (host.judge.livedark)
    tracker.adopted.new_life()  # ... nor at a start of the reference (host.judge.liveadopted)
    tracker.wrongs.new_life(tracker.now_s)  # an offset before it gone with its RAM
    for message in db.messages:
        if FIRMWARE_NODE in message.senders:  # the counts stay; the next frame starts afresh
            e2e.restart_sequence(message.frame_id, extended=message.is_extended_frame)
    if uptime_s == 0:
        tick_s = None if watch is None else watch.held_tick_s  # (liveheldstart)
        tracker.power_up(primed_now=state != "INIT", seq=seq, tick_s=tick_s)
        started_after_silence(tracker, watch, uptime_s)  # unnamed: after a silence
        return "reference restarted at the power-up pose"
    if started_after_silence(tracker, watch, uptime_s):  # rebooted in a silence
        return "reference restarted at the power-up pose on a frame after the silence"
    tracker.adopted.owe(LATE_REBOOT.format(uptime_s=uptime_s))  # its pose adopted
    tracker.new_life()
    return "reference restarted"
