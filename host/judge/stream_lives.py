"""Where each firmware life of a log starts, chunk by chunk (issue #14.1): ``split_lives``.

A reboot is a summary (ODOM_STATUS page 0, CRC holding) that ``SourceWatch`` calls one, fed in
bus order as in the whole log. Its life starts at the summary, at the latest accepted encoder
frame before it (UPTIME 0, not INIT), or at the encoder frame its first page of WHEEL_ENCODERS
E2E counts names (``primed.counted_start``: ENC_E2E_OK + ENC_E2E_LOST - 1 COUNTER steps back
from the latest encoder frame before that page was sent, ``pagesent.StreamPages``: a page
waits for the next ODOM_STATUS frame, when the page comes before the next reboot), except when
the new firmware stalled before its first count page or its first pose (``reboots
.stalled_first``: its page misses the frames its halted MCU's FIFO overran; the firmware's signs
of life are carried for it, the last 2^16). Carried: the watch, the positions, COUNTERs and
bus times of the last 2^16 accepted encoder frames (ENC_E2E_OK is a wrapping u16: no page names one
further back), the reboot still waiting for its first count page, and per reboot whose first
pose is not told yet its last ODOM_STATUS (CRC holding) and that pose (``_track``). A reboot's
start is final at its first count page when its first pose came before it, else at that pose
(``_settle``), at the next reboot or at the end of the log; lives are contiguous ranges of
frames. A silence longer than the carried frames (2^16 cycles) is told on them: far more than
``SILENCE_CYCLES`` on time either way."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.frames import concat_frames, empty_frames
from odocan.host.io.logs import FrameArrays
from odocan.host.judge import bootnamed, heldboot
from odocan.host.judge.aheadticks import boot_ahead_heard
from odocan.host.judge.bootnamed import (
    PowerUpPoses,
    carried_on,
    first_after,
    heard_encoders,
    named_start,
    no_powerup_poses,
    pose_enc_rows,
    powerup_poses,
)
from odocan.host.judge.bootticks import (
    BOOT_WINDOW_S,
    TWIST_COUNTERS,
    continues_summary,
    fell_around,
    fell_in_run,
    pose_rows,
    poses_before,
    status_before,
)
from odocan.host.judge.distfall import Falls, joined, no_falls
from odocan.host.judge.gapseen import crc_holds
from odocan.host.judge.heldboot import summary_start
from odocan.host.judge.heldsummaries import heard_in_chunk
from odocan.host.judge.heldtick import tick_pages, tick_s, told_tick
from odocan.host.judge.latefall import continues_twice, fell_late
from odocan.host.judge.lifespan import LifeSpan as LifeSpan
from odocan.host.judge.livestreams import pose_told_first
from odocan.host.judge.navrestart import Carried, second_evidence
from odocan.host.judge.pagesent import Counts, StreamPages
from odocan.host.judge.primed import counted_start
from odocan.host.judge.reboots import SUMMARY_PAGE, mark_two_sources
from odocan.host.judge.samples import AnalysisError, contract_cycle_s
from odocan.host.judge.silentboot import fresh_counted_start, quiet_start
from odocan.host.judge.sources import SourceWatch, two_sources_text
from odocan.host.judge.stalls import silent_between, stalled_before
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError

ENCODERS_KEPT = 1 << 16  # accepted encoder frames remembered (ENC_E2E_OK is a u16)


@dataclass
class _Boot:
    position: int
    uptime_s: int
    t_s: float
    before_s: int
    start: int  # from the summary (``reboots.summary_start``)
    state: str = ""  # its STATE
    named: int | None = None  # named by its power-up pose (``bootnamed.named_start``)
    naming: tuple[int, int, int] | None = None  # ... and the ENC_COUNTER and COUNTER the first
    # pose after the summary counts on from, until it tells (``bootnamed.first_after``)
    paged: bool = False  # its first count page was heard (its start from it: ``counted``)
    counted: int | None = None  # ``primed.counted_start`` of that page
    talked_s: float | None = None  # its last ODOM_STATUS (CRC holding) before its first pose
    pose: tuple[int, float] | None = None  # its first ODOM_POSE_Y: log position, bus time
    stalled: bool | None = None  # stalled before its first pose (None: not told yet)
    page_at: int | None = None  # its first count page's position in the log
    by_count: bool = False  # its start is the one its first count page named (a power-up)
    silent: bool = False  # primed in a silence on a frame nothing names (``silentboot``)
    held: bool = False  # held back behind its tick's page: no count overrides (``heldboot``)


@dataclass
class StreamLives:
    """``split_lives`` chunk by chunk: ``feed`` each chunk with its E2E-accepted mask (of the
    whole log's check, ``host.judge.stream.StreamE2E``), then ``finish`` with the lives."""

    decoder: BulkDecoder
    _offset: int = 0
    _watch: SourceWatch = field(default_factory=SourceWatch)
    _encoders: npt.NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64))
    _counters: npt.NDArray[np.int64] = field(  # the COUNTER of each of ``_encoders``
        default_factory=lambda: np.zeros(0, dtype=np.int64))
    _enc_t: npt.NDArray[np.float64] = field(  # the bus time of each of ``_encoders``
        default_factory=lambda: np.zeros(0, dtype=np.float64))
    _every: tuple[FrameArrays, npt.NDArray[np.int64]] = field(  # every encoder frame (not
        default_factory=lambda: (empty_frames(), np.zeros(0, np.int64)))  # only accepted), its
    # position (``silentboot.fresh_counted_start``)
    _alive: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]] = field(  # positions, bus
        default_factory=lambda: (np.zeros(0, np.int64), np.zeros(0)))  # times of the frames
    # that say the firmware ran (``reboots.stalled_first``: ODOM_STATUS whose CRC holds, poses)
    _tracking: list[_Boot] = field(default_factory=list)  # reboots before their first pose
    _waiting: _Boot | None = None  # the last reboot, before its first count page
    _boots: list[tuple[_Boot, int]] = field(default_factory=list)  # with their final start
    _summaries: bool = True  # the DBC's ODOM_STATUS has UPTIME and STATE on its summary page
    _changed: tuple[int, float] = (0, 0.0)  # the summary of the last new UPTIME offset
    conflict: tuple[int, float] | None = None  # ``reboots.two_sources``: position, bus time
    _cut: int = 0  # where the lives were cut for it (``finish_one_source``)
    _detail: str = ""  # why (``two_sources_text``, ``posestreams.PoseStreams.told``)
    _pose: tuple[float, int, bool, float] | None = None  # the pose run so far, its latest's
    # bus time (``bootticks.poses_before``)
    _status: tuple[float, int] | None = None  # the latest ODOM_STATUS (``status_before``)
    _held_before: heldboot.Before = heldboot.NONE_BEFORE  # the latest two (``statuses_before``)
    _powerups: PowerUpPoses = field(default_factory=no_powerup_poses)  # the latest
    # power-up poses heard (``bootnamed``), their positions in the log
    _ahead: tuple[_Boot, bool, bool] | None = None  # the last summary, the first pose after it
    # (or the next summary, ``continues_summary``) not heard yet (``bootticks.boot_ahead``): its
    # reboot if that tells one, whether it broke the status sequence, whether its pose left it
    # to the next summary; the chunk's events after it wait with it (``_deferred``)
    _deferred: list[tuple[int, _Boot | Counts]] = field(default_factory=list)
    _naming: list[_Boot] = field(default_factory=list)  # reboots whose ``naming`` is not told
    _poses: bootnamed.PoseRows = field(default_factory=bootnamed.pose_rows_none)  # ran_on_to
    _ahead_fall: bool = False  # the ``_ahead`` posed needs a twist's DISTANCE fallen
    _late: bool = False  # ... continued with none yet: the next summary reads a late one
    _held: npt.NDArray[np.bool_] = field(  # per pose row of the chunk: held back (``aheadticks``)
        default_factory=lambda: np.zeros(0, bool))
    _pages: StreamPages = field(init=False)  # the count pages, each where it was sent
    _falls: tuple[Falls, Carried | None] = field(  # the twists whose DISTANCE fell, the
        default_factory=lambda: (no_falls(), None))  # NAV_STATUS restarts (all kept), carried

    def __post_init__(self) -> None:
        self._pages = StreamPages(self.decoder)

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> None:
        """Take the next chunk's accepted encoder frames, reboots and count pages."""
        rows = self.decoder.decode(chunk, "WHEEL_ENCODERS")
        keep = accepted[rows["index"]]
        self._encoders = np.concatenate(
            (self._encoders, rows["index"][keep].astype(np.int64) + self._offset))
        self._counters = np.concatenate((self._counters, rows["COUNTER"][keep].astype(np.int64)))
        self._enc_t = np.concatenate((self._enc_t, rows["timestamp_s"][keep].astype(np.float64)))
        self._every = (concat_frames([self._every[0], chunk.select(rows["index"])]),
                       np.concatenate((self._every[1], rows["index"] + self._offset)))
        self._powerups = carried_on(self._powerups,
                                    powerup_poses(chunk, self.decoder, self._offset))
        self._poses = bootnamed.carried_rows(self._poses, pose_enc_rows(chunk, self.decoder,
                                                                        self._offset))
        falls, twist = second_evidence(chunk, self.decoder, TWIST_COUNTERS, self._falls[1])
        self._falls = (joined(self._falls[0], falls), twist)  # rare: all kept
        pages = self._pages.feed(chunk, self._offset, (self._every[1], self._every[0].timestamp_s),
                                 (self._poses, (self._encoders, self._counters)))
        events = sorted(self._deferred + self._boot_events(chunk) + list(pages),
                        key=lambda event: event[0])
        self._corroborate(chunk)
        self._carry_alive(chunk)
        self._track(chunk)
        waits = self._ahead[0].position if self._ahead is not None else None
        self._deferred = [] if waits is None else [e for e in events if e[0] > waits]
        self._run(events if waits is None else [e for e in events if e[0] <= waits])
        self._settle()
        self._encoders = self._encoders[-ENCODERS_KEPT:]
        self._counters = self._counters[-ENCODERS_KEPT:]
        self._enc_t = self._enc_t[-ENCODERS_KEPT:]
        self._every = (self._every[0].select(slice(-ENCODERS_KEPT, None)),
                       self._every[1][-ENCODERS_KEPT:])
        self._alive = (self._alive[0][-ENCODERS_KEPT:], self._alive[1][-ENCODERS_KEPT:])
        self._offset += len(chunk)

    def _carry_alive(self, chunk: FrameArrays) -> None:
        """The chunk's ODOM_STATUS frames whose CRC holds and ODOM_POSE_Y frames, carried (the
        last 2^16: a page further on names no start, ``ENCODERS_KEPT``)."""
        status = self.decoder.select(chunk, "ODOM_STATUS")
        ys = self.decoder.select(chunk, "ODOM_POSE_Y")
        at = np.sort(np.concatenate((status[crc_holds(chunk, self.decoder, status)], ys)))
        self._alive = (np.concatenate((self._alive[0], at.astype(np.int64) + self._offset)),
                       np.concatenate((self._alive[1], chunk.timestamp_s[at])))

    def _corroborate(self, chunk: FrameArrays) -> None:
        """``_Boot.naming``'s reboots, the chunk's first pose after the summary: ``named`` when it
        counts on, else none, or none in ``BOOT_WINDOW_S`` (``bootnamed.first_after``)."""
        if not self._naming:
            return
        rows = pose_enc_rows(chunk, self.decoder, self._offset)
        end_s = float(chunk.timestamp_s[-1]) if len(chunk) else -np.inf
        for boot in self._naming:
            assert boot.naming is not None
            counted = first_after(rows, boot.position, boot.t_s, *boot.naming[1:])
            if counted is None and end_s - boot.t_s < BOOT_WINDOW_S:
                continue
            boot.named, boot.naming = (boot.naming[0] if counted else None), None
        self._naming = [b for b in self._naming if b.naming is not None]

    def _run(self, events: list[tuple[int, _Boot | Counts]]) -> None:
        """Reboots and count pages in log order."""
        for position, boot in events:
            if isinstance(boot, _Boot):
                self._decide(None, limit=position)
                self._waiting = boot
            else:
                self._decide((position, boot))

    def finish(self, n_frames: int | None = None) -> list[LifeSpan]:
        """The lives (``n_frames``: the log's frames, default all fed)."""
        self._run(sorted(self._deferred + list(self._pages.finish()),  # a last summary with no
                         key=lambda event: event[0]))  # pose after it: no reboot
        self._ahead, self._deferred = None, []
        self._decide(None)
        stop = self._offset if n_frames is None else n_frames
        if not self._boots or not self._summaries:
            return [LifeSpan(0, stop, boot=False)]
        starts = [start for _, start in self._boots]
        lives = [LifeSpan(0, starts[0], boot=False)]
        for k, (boot, start) in enumerate(self._boots):
            end = starts[k + 1] if k + 1 < len(starts) else stop
            lives.append(LifeSpan(start, end, boot=boot.uptime_s == 0 or boot.by_count,
                                  t_s=boot.t_s, uptime_before_s=boot.before_s,
                                  silent=boot.silent))
        return lives

    def finish_one_source(self, streams: tuple[int, float, str] | None = None
                          ) -> list[LifeSpan]:
        """``finish``, the lives cut where a second firmware came (``conflict``: at the start of
        the life its first summary was taken to begin, else that summary, as
        ``reboots.before_two_sources``), or where two pose streams began to interleave
        (``streams``: ``posestreams.PoseStreams.told``) where UPTIME tells none or well after
        (``livestreams.pose_told_first``), as ``posestreams.one_source_cut``. Raises
        ``AnalysisError`` when that is the log's start."""
        spans = self.finish()
        if self.conflict is not None:
            position, t_s = self.conflict
            self._cut = min([position, *(s.start for s in spans
                                         if s.t_s == t_s and s.stop > s.start)])
            self._detail = two_sources_text(t_s)
        if streams is not None and pose_told_first(
                streams[1], None if self.conflict is None else self.conflict[1]):
            self._cut, self.conflict, self._detail = streams[0], streams[:2], streams[2]
        if self.conflict is None:
            return spans
        kept = [s for s in spans if s.start < self._cut]
        if not kept:
            raise AnalysisError(f"{self._detail}, from the log's start")
        return [*kept[:-1], dataclasses.replace(kept[-1], stop=self._cut)]

    def marked(self, report: dict[str, Any], n_frames: int) -> dict[str, Any]:
        """``report`` with the FAIL of two firmwares (``reboots.mark_two_sources``) when the
        lives were cut for them (``n_frames``: the log's)."""
        if self.conflict is not None:
            mark_two_sources(report, self.conflict[1], n_frames - self._cut, self._detail)
        return report

    def _decide(self, page: tuple[int, Counts] | None, limit: int | None = None) -> None:
        """The waiting reboot's start, from its first count page (position, (ENC_E2E_OK,
        ENC_E2E_LOST, where it was sent: ``pagesent``)) or without one (``limit``: the next
        reboot's position, None: the log's end). A page heard before the reboot's first pose
        waits for it (``_settle``)."""
        boot = self._waiting
        if boot is None or (page is not None and boot.paged):  # its first page only
            return
        if page is not None:
            boot.paged, boot.page_at = True, page[0]
            sent, counts = page[1][2], page[1][:2]  # counted from where it was sent
            boot.counted = fresh_counted_start(self._every, self.decoder, sent, counts, (
                counted_start((self._encoders, self._counters), sent, *counts),
                summary_start(boot.position, boot.uptime_s, boot.state, self._every[1]),
                self._boots[-1][1] if self._boots else 0))
            if boot.pose is None or boot.pose[0] > page[0]:  # whether it stalled before
                return  # its first pose: told at that pose, unless a reboot comes first
        self._waiting = None
        previous = self._boots[-1][1] if self._boots else 0
        start = boot.start
        counting = boot.counted is not None and not self._stalled(boot, limit)
        if counting and not boot.held and boot.counted is not None and boot.counted > previous:
            start, boot.by_count = boot.counted, True
        if boot.named is not None and boot.named > previous:
            start = boot.named  # the power-up pose's word last (``reboots.split_lives``)
            boot.by_count = start == boot.counted
        quiet = None if counting or boot.named is not None else quiet_start(
            self._alive, (self._encoders, self._enc_t), boot.position, previous)
        boot.silent = quiet is not None  # primed in a silence (``silentboot``)
        self._boots.append((boot, start if quiet is None else quiet))
        self._tracking = [other for other in self._tracking if other is not boot]

    def _track(self, chunk: FrameArrays) -> None:
        """The chunk's part of ``reboots.stalled_first`` for each reboot before its first pose
        (``_tracking``): its last ODOM_STATUS whose CRC holds from its summary on, its first
        ODOM_POSE_Y; told once an accepted encoder frame after that pose is carried (the last
        frame of the silence is on time or not by the next one: ``stalls.frames_on_time``)."""
        if not self._tracking:
            return
        ys = self.decoder.select(chunk, "ODOM_POSE_Y").astype(np.int64) + self._offset
        status = self.decoder.select(chunk, "ODOM_STATUS")
        good = status[crc_holds(chunk, self.decoder, status)]
        good_at = good.astype(np.int64) + self._offset
        for boot in self._tracking:
            if boot.pose is None:
                after = ys[ys > boot.position]
                stop = int(after[0]) if len(after) else None
                talked = good[(good_at >= boot.position)
                              & (good_at < (np.iinfo(np.int64).max if stop is None else stop))]
                if len(talked):
                    boot.talked_s = float(chunk.timestamp_s[talked[-1]])
                if stop is not None:
                    boot.pose = (stop, float(chunk.timestamp_s[stop - self._offset]))
            if boot.pose is not None and boot.stalled is None and bool(
                    (self._enc_t >= boot.pose[1]).any()):
                boot.stalled = self._silent_before_pose(boot)
        self._tracking = [boot for boot in self._tracking if boot.stalled is None]

    def _stalled(self, boot: _Boot, limit: int | None) -> bool:
        """``reboots.stalled_first`` for ``boot`` (its life up to ``limit``), on the carried
        encoder frames and signs of life: silent before its first pose, or from its summary to
        the later of its first count page and that pose (``reboots.told_by``)."""
        if boot.pose is None or (limit is not None and boot.pose[0] >= limit):
            return False  # no pose in its life
        if boot.stalled:
            return True
        stop = (np.iinfo(np.int64).max if limit is None else limit) if boot.page_at is None \
            else max(boot.page_at, boot.pose[0])
        at, t_s = self._alive
        return silent_between(t_s[(at >= boot.position) & (at <= stop)], self._enc_t,
                              contract_cycle_s(self.decoder, "WHEEL_ENCODERS"))

    def _silent_before_pose(self, boot: _Boot) -> bool:
        """Whether ``boot`` stalled before its first pose (its last ODOM_STATUS before it)."""
        if boot.pose is None or boot.talked_s is None:
            return False
        return stalled_before(boot.pose[1], self._enc_t,
                              contract_cycle_s(self.decoder, "WHEEL_ENCODERS"),
                              np.array([boot.talked_s]))

    def _settle(self) -> None:
        """The waiting reboot whose first count page came before its first pose, decided once
        that pose is told and no summary before it is still waiting (``_ahead``: it may be a
        reboot, the life's limit)."""
        boot = self._waiting
        if (boot is not None and boot.paged and boot.pose is not None
                and boot.stalled is not None
                and (self._ahead is None or self._ahead[0].position > boot.pose[0])):
            self._decide(None, limit=None)

    def _boot_events(self, chunk: FrameArrays) -> list[tuple[int, _Boot | Counts]]:
        """The chunk's reboots (``reboots.boot_summaries``), at their positions in the log."""
        if not self._summaries:
            return []
        try:
            page = self.decoder.decode_page(chunk, "ODOM_STATUS", SUMMARY_PAGE)
            message = self.decoder.message("ODOM_STATUS")
        except (DecodeError, KeyError):
            self._summaries = False
            return []
        if len(page["index"]) == 0:  # the chunk's latest pose and status frame still count
            self._held = heard_in_chunk(self._watch, chunk, self.decoder, page["index"], [])[2]
            tick_pages(chunk, self.decoder, page["index"], self._watch.ticks)
            self._ahead_posed(pose_rows(chunk, self.decoder), self._pose, -1, None)
            self._pose = poses_before(chunk, self.decoder, page["index"], self._pose,
                                      self._status is not None)[1]
            self._status = status_before(chunk, self.decoder, page["index"], self._status)[1]
            self._held_before = heldboot.statuses_before(chunk, self.decoder, page["index"],
                                                         self._held_before)[1]
            return []
        if "UPTIME" not in page or "STATE" not in page:
            self._summaries = False
            return []
        index = page["index"]
        good = crc_holds(chunk, self.decoder, index)
        choices = dict(message.get_signal_by_name("STATE").choices or {})
        names = [str(choices.get(int(state), int(state))) for state in page["STATE"].tolist()]
        said = list(zip(page["UPTIME"].tolist(), names, strict=True))
        late, evidence, self._held = heard_in_chunk(self._watch, chunk, self.decoder, index, said,
                                                    good)
        ticks = tick_pages(chunk, self.decoder, index[good], self._watch.ticks)  # (``heldtick``)
        carried, rows = self._pose, pose_rows(chunk, self.decoder)
        (pose_t, pose_counter, pose_new), self._pose = poses_before(
            chunk, self.decoder, index[good], self._pose, self._status is not None)
        self._ahead_posed(rows, carried, -1, int(index[good][0]) if good.any() else None)
        events: list[tuple[int, _Boot | Counts]] = []
        (status_t, status_counter), self._status = status_before(
            chunk, self.decoder, index[good], self._status)
        befores, self._held_before = heldboot.statuses_before(
            chunk, self.decoder, index[good], self._held_before)
        following = [*index[good].tolist()[1:], None]
        for position, t_s, uptime_s, state, counter, after, pose, status, held, two, tick in zip(
            index[good].tolist(), page["timestamp_s"][good].tolist(),
            page["UPTIME"][good].tolist(), page["STATE"][good].tolist(),
            page["COUNTER"][good].tolist(), following,
            zip(pose_t.tolist(), pose_counter.tolist(), pose_new.tolist(), strict=True),
            zip(status_t.tolist(), status_counter.tolist(), strict=True),
            zip(late.tolist(), evidence.tolist(), strict=True), befores, ticks, strict=True,
        ):
            name = str(choices.get(int(state), int(state)))
            events += self._posed_told(float(t_s), int(uptime_s), int(counter))
            before = self._watch.last_uptime_s
            self._watch.pose = (pose[0], int(pose[1]), bool(pose[2])) if pose[1] >= 0 else None
            self._watch.status_before = (status[0], int(status[1])) if status[1] >= 0 else None
            tick = told_tick(tick, lambda page_s: fell_in_run(self._falls[0], page_s))
            self._watch.ticks.told, self._watch.ticks.fell = tick, tick is not None
            kind = self._watch.observe(float(t_s), int(uptime_s), name, int(counter),
                                       fell=fell_in_run(self._falls[0], float(t_s)),
                                       late=held[0], held=tuple(held[1]))
            at = int(position) + self._offset
            if self._watch.changed_at_s == float(t_s):
                self._changed = (at, float(t_s))
            if kind == "two sources" and self.conflict is None:
                self.conflict = self._changed
            if kind == "reboot":
                events.append((at, self._boot(at, int(uptime_s), float(t_s), name, int(before),
                                              tick_s(heldboot.held_tick_s(int(counter),
                                                                          float(t_s), two), tick))))
            elif self._watch.ahead is not None:  # the first pose after it may tell it
                self._ahead = (self._boot(at, int(uptime_s), float(t_s), name, int(before)),
                               self._watch.ahead[4], False)
                self._ahead_posed(rows, carried, int(position), after)
        return events

    def _boot(self, at: int, uptime_s: int, t_s: float, name: str, before: int,
              tick_s: float | None = None) -> _Boot:
        """The reboot of the summary at log position ``at`` (bus time ``t_s``, UPTIME, STATE
        ``name``; ``before``: the UPTIME before it; ``tick_s``: ``heldboot.held_tick_s``): where
        its life starts."""
        earlier = self._encoders[self._encoders < at]
        start = int(earlier[-1]) if uptime_s == 0 and name != "INIT" and len(earlier) else at
        if tick_s is not None:  # held back behind its tick's page
            every, mask = self._every[0], ENC_COUNTER_MASK
            start = heldboot.held_start(at, uptime_s, name, (self._every[1], every.timestamp_s),
                                        tick_s, every.data[:, 1].astype(np.int64) & mask)
        heard = heard_encoders(self._every, self.decoder) if uptime_s == 0 else None
        named = None if heard is None else named_start(
            self._powerups, (self._encoders, self._counters), at, t_s, heard=heard, run=self._poses)
        boot = _Boot(at, uptime_s, t_s, before, start, name, naming=named,
                     held=tick_s is not None)
        self._tracking.append(boot)
        self._naming += [boot] if named is not None else []
        return boot

    def _ahead_posed(self, rows: tuple[npt.NDArray[np.int64], npt.NDArray[np.float64],
                                       npt.NDArray[np.int64]],
                     carried: tuple[float, int, bool, float] | None, position: int,
                     after: int | None) -> None:
        """The waiting ``_ahead`` summary (at chunk ``position``; -1: a chunk before) and the
        first pose of the chunk's ``rows`` (``bootticks.pose_rows``) after it and before the
        next summary (chunk position ``after``; None: none in the chunk): left to the next
        summary when ``boot_ahead`` takes it, else dropped; it waits on when the chunk has no
        pose after it and no summary."""
        if self._ahead is None or self._ahead[2]:
            return
        where, t_pose, counter = rows
        j = int(np.searchsorted(where, position, side="right"))
        if j >= len(where) or (after is not None and int(where[j]) > after):
            self._ahead = self._ahead if j >= len(where) and after is None else None
            return
        boot, broke, _ = self._ahead
        self._ahead = None
        before = ((float(t_pose[j - 1]), int(counter[j - 1])) if j > 0 else
                  None if carried is None else (carried[3], carried[1]))
        pose, held = (float(t_pose[j]), int(counter[j])), bool(self._held[j])
        sure = boot_ahead_heard(boot.t_s, broke, *pose, before, held)
        if sure or boot_ahead_heard(boot.t_s, broke, *pose, before, held, True):
            self._ahead = (boot, broke, True)  # the next summary tells (``_posed_told``)
            self._ahead_fall = not sure  # ... its twists' DISTANCE fallen (``distfall``)

    def _posed_told(self, t_s: float, uptime_s: int, counter: int
                    ) -> list[tuple[int, _Boot | Counts]]:
        """The next summary (bus time ``t_s``, UPTIME, COUNTER) after an ``_ahead`` one its
        first pose left to it, before it is observed: that one's reboot when it continues its
        sequence (``SourceWatch.told_ahead``; one with no fall yet waits to the summary after,
        ``latefall``), else none."""
        ahead, self._ahead = self._ahead, None
        late, self._late = self._late, False
        if ahead is not None and late:
            if not (continues_twice(ahead[0].t_s, t_s, uptime_s, counter)
                    and fell_late(self._falls[0], ahead[0].t_s, t_s)):
                return []
        elif ahead is None or not ahead[2] or not continues_summary(ahead[0].t_s, t_s, uptime_s,
                                                                    counter):
            return []
        elif self._ahead_fall and not fell_around(self._falls[0], ahead[0].t_s):
            self._ahead, self._late = ahead, True  # its events wait on with it
            return []
        self._watch.take_ahead(ahead[0].t_s, ahead[0].uptime_s)
        return [(ahead[0].position, ahead[0])]
