"""What the firmware's own E2E counts prove it took (issue #11, rule 5: a PASS must never hide
a wrong pose): where ODOM_STATUS shows the firmware accepted exactly the encoder frames the log
holds (every one, and none the log lacks), it took the reference's steps there, so a gap of the
log (``host.judge.gapbound``'s allowance: frames the firmware saw and the log did not) or a
stall (``host.judge.breaks``' merge allowance: frames the log holds and the firmware missed)
there earns no re-placement allowance; the firmware's rounding stays the tolerance. Shared by
the whole-log and the streamed judge (``reference_path.build_reference``, ``stream_analysis``).

The evidence. Page 2 of ODOM_STATUS carries ENC_E2E_OK (u16) and ENC_E2E_LOST (u8): the encoder
frames the firmware's E2E check accepted, and those it saw skipped between them (plus whole
COUNTER cycles of frames its mailbox dropped); page 1 carries REJECTED_FRAMES and
OVERFLOWED_FRAMES (u16): every frame refused by a check (E2E CRC, REPEATED, WRONG_SEQUENCE,
length, plausibility) or dropped by a full mailbox. A page counts as evidence only when it came
in its tick, right after that tick's summary (CRC good, COUNTER one less, within half an
encoder cycle, the summary on time: not ``queued_frames``); it was made then. A page held back
or sent again carries older counts at a later place: no evidence. The host's E2E window may
refuse a good page after the bus lost a few status frames: its CRC suffices.

For two such pages p, q of one firmware life (at most ``PAIR_PAGES`` apart, or the pages
around a gap of the log however far apart: ``pagechain.long_pairs``), let S_p, S_q be the
sender's sequence numbers of the last encoder frames the firmware had accepted when it made
them, W the sender's frames in (S_p, S_q], F those the firmware accepted, L those the log holds.

* lo(p): the last encoder frame logged at or before p's summary (``losses._made_from``): the
  firmware had it, seq(lo(p)) <= S_p. hi(p): the first logged after p: it came on the bus after
  p was made, S_p < seq(hi(p)). So the log's frames hi(p) .. lo(q) are surely in W.
* Quiet: the last page 1 sent before frame lo(p) (made before the firmware took any frame of W)
  and the first sent at or after q count the same rejected and overflowed frames, and so does
  every page 1 between, each less than ``WRAP_SAFE_S`` after the one before (65536 frames
  cannot pass in that time on a 1 Mbit/s bus, so the u16 counts did not wrap: a chain,
  ``host.judge.pagechain``). A frame of L in W reached the firmware (CAN delivers every frame
  on the wire to every node; a fault takes a frame off the bus for all), was not dropped nor
  refused: L and W is within F. Every frame of W the firmware did not accept is missing from
  the log.
* By OK: g_ok, OK's growth from p to q summed over the pages kept between them, each less
  than ``WRAP_SAFE_S`` after the one before (one chain: each step's growth mod 65536 exact), is
  exact and equals |L and W| + a, a the frames of W the firmware accepted that the log lacks;
  |L and W| >= lo(q) - hi(p) + 1. If g_ok <= lo(q) - hi(p) + 1 then a = 0: on W the firmware
  accepted exactly L.
* By LOST: the true growth G of ENC_E2E_LOST counts frames of W not accepted, never more (a
  COUNTER skip of 16 or more counts short; the cycles term counts mailbox drops only: none
  here); g = G mod 256 <= G. M, the frames the log lacks between frames lo(p) and hi(q) (the
  gaps into frames lo(p) + 1 .. hi(q)), is at least those of W. If g >= M > 0: M <= g <= G <=
  |W - F| <= M, all equal: every missing frame between lo(p) and hi(q) is in W and was not
  accepted, and again on W the firmware accepted exactly L.
* By checked (``host.judge.gapchecked``): refusals allowed, when the firmware's E2E counts
  (accepted and refused) grew by exactly the log's encoder frames between the pages, nothing
  dropped and nothing refused but by the encoder's E2E check: on W it received exactly the
  log's frames (a delay's reordering refuses a frame every few: no window is quiet).
* By skips (``host.judge.gapskips``): as by checked, the firmware received exactly the log's
  frames, all of them the host's, but accepted m fewer than the host (a REPEATED after a
  bus-off): no frame a gap there lacks was taken, at most m of the log's were skipped
  (``Seen.skips``; not joined, each pair's m its own).
* Windows proven any way whose pages overlap or meet join (their W's are contiguous): on
  the union the firmware accepted exactly the log's frames, surely for the log's frames from
  hi of the first page to lo of the last (``Seen.same``); the gaps into frames lo(p) + 1 ..
  hi(q) of a window proven by LOST were missed whole (``Seen.missed``).
* At power-up (``host.judge.powerup``: the firmware primed on the log's first encoder frame) its
  boot is a page before the log: every count 0 (``with_boot``).

Then a gap whose frames are all in such a stretch was taken as one step from the frame before
it to the frame after it, the reference's merged step; a stall whose span (the frame before it
to the first frame a sample names after it) lies in one was taken frame by frame, the
reference's steps. A frame the firmware accepted that is not the sender's (a forgery whose CRC
holds) is the one thing the counts cannot tell; a forger's other frames fail the CRC, which
REJECTED counts (the window is not quiet). Every other way to blame a correct firmware keeps the
allowance: a page missing, held back or sent again (no evidence); a mailbox overflow or a
refusal (a stall's backlog, a late frame's WRONG_SEQUENCE, a forgery, an implausible step); a
counter restart re-primed in the stretch (a restarted COUNTER can make OKSOMELOST count frames
that never existed: ``Seen.gap_missed`` and ``took_all`` leave such stretches out, but for
stretches proven by counting the frames taken, by OK or by checked: ``took_across``); a gap
straddling a page (its frames before lo or after hi are not proven); a reboot (each life has
its own pages: ``host.judge.reboots``); a sender that stalled (the sender's sequence then
counts periods it did not send: M too large, never too small). The counts can only prove
frames missed and frames taken, never a split of a gap the firmware saw: such a gap keeps its
allowance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapchecked import (
    REFUSED,
    UNKNOWN,
    by_checked,
    by_received,
    packed_rows,
    skipped_frames,
)
from odocan.host.judge.gapfill import (
    ANCHOR_FRAMES,
    NO_ANCHORS,
    Anchors,
    Counts,
    LateFrames,
    late_in_chunk,
    recent_anchors,
)
from odocan.host.judge.holetaken import LONG_GAP_FRAMES, through_gaps
from odocan.host.judge.nearthreshold import ResetLog, Resets
from odocan.host.judge.pagechain import boot_breaks, boot_ok, long_pairs, quiet
from odocan.host.judge.pagekeeper import LOST_PAGE as LOST_PAGE
from odocan.host.judge.pagekeeper import TOTALS_PAGE as TOTALS_PAGE
from odocan.host.judge.pagekeeper import Page as Page
from odocan.host.judge.pagekeeper import PageKeeper as PageKeeper
from odocan.host.judge.pagekeeper import StatusRows, statuses
from odocan.host.judge.pagekeeper import Totals as Totals
from odocan.host.judge.samples import Encoders, FloatArray, IntArray
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e_rows import crc_right

PAIR_PAGES = 8  # pages paired up to this many apart (4 s of pages: a window per pair)
DARK_CYCLES = 3  # a log without any frame this many encoder cycles (the firmware sends a pose
# every 2): the recorder lost frames
Span = tuple[int, int]  # encoder frames (first, last), both included


@dataclass(frozen=True)
class LostPages:
    """The accepted ENC_E2E pages of a life, in log order (module docstring)."""

    lo: IntArray  # the earliest encoder frame the firmware had when it made the page
    lo_s: FloatArray  # that frame's bus time (s)
    hi: IntArray  # the first encoder frame logged after the page (n: none)
    ok: IntArray  # ENC_E2E_OK (u16)
    lost: IntArray  # ENC_E2E_LOST (u8)
    sent_s: FloatArray  # its bus time (s)
    ok_u: IntArray  # ENC_E2E_OK unwrapped along its chain (``pagechain.chained_ok``)
    chain: IntArray  # the chain's number
    raw_lo: IntArray  # lo and hi among every encoder frame logged, refused ones too
    raw_hi: IntArray
    refused: IntArray  # the E2E refusal counts packed (``gapchecked.packed``; -1: unknown)
    host_lost: IntArray | None = None  # the host's E2E LOST summed up to lo (``gapchecked``)


@dataclass(frozen=True)
class TotalsPages:
    """The accepted FRAME_TOTALS pages of a life, in log order."""

    sent_s: FloatArray
    rejected: IntArray  # REJECTED_FRAMES (u16)
    overflowed: IntArray  # OVERFLOWED_FRAMES (u16)
    breaks: IntArray  # the breaks before it (``pagechain.chained_breaks``)


@dataclass(frozen=True)
class Seen:
    """What the pages prove (module docstring): ``same``, runs of encoder frames over which the
    firmware accepted exactly the log's frames (every one, and no frame the log lacks);
    ``missed``, spans whose gaps (into frames first + 1 .. last) it missed whole."""

    same: list[Span]
    missed: list[Span]
    fills: dict[int, list[Counts]] = field(default_factory=dict)  # ``host.judge.gapfill``: per
    # gap (its frame after) the log fills with frames refused, their counts

    def filled(self, frame: int, reprimed: frozenset[int] = frozenset()) -> list[Counts] | None:
        """The counts of the frames the gap into encoder ``frame`` lacks, when the log holds
        every one (refused by E2E: held back on the bus) and no counter restart re-primed at
        it; else None."""
        return None if frame in reprimed else self.fills.get(frame)
    counted: list[Span] = field(default_factory=list)  # the runs of ``same`` proven by OK alone
    holes: frozenset[int] = frozenset()  # encoder frames after a hole of the log's encoder
    # frames (refused ones included): the sender silent or the recorder lost frames
    through: dict[int, int] = field(default_factory=dict)  # per long gap (its frame after) the
    # pages prove frames taken in: the firmware's longest step there (``host.judge.holetaken``)
    resets: Resets = field(default_factory=Resets)  # its COUNTER_RESET word (nearthreshold)
    skips: list[tuple[int, int, int]] = field(default_factory=list)  # (first, last, m): runs
    # of the log's frames over which it received exactly them and refused m (``gapchecked``)
    received: list[Span] = field(default_factory=list)  # runs of the log's frames over which
    # it received exactly them, whichever it accepted (``gapreceived``)
    known: dict[int, list[tuple[int, Counts]]] = field(default_factory=dict)  # per gap (its
    # frame after): the frames it lacks the log holds (``LateFrames.known``)

    def skipped(self, frame: int, reprimed: frozenset[int] = frozenset()) -> int | None:
        """The fewest frames the firmware refused over a run of ``skips`` holding the gap into
        encoder ``frame`` and the ``m`` frames either side of it (lo <= frame - 1 - m, frame + m
        <= hi; no counter restart re-primed in it): it took no frame the gap lacks, and of
        the log's frames it missed at most ``m``; None where no such run holds it."""
        fits = [m for lo, hi, m in self.skips
                if lo <= frame - 1 - m and frame + m <= hi and _clear(lo, hi, reprimed)]
        return min(fits, default=None)

    def took_across(self, frame: int) -> bool:
        """Whether ENC_E2E_OK alone proves the firmware took exactly the log's frames from
        ``frame - 1`` to ``frame`` (none the log lacks), a controller restart re-primed at
        ``frame`` or not: OK counts the frames it accepted, whatever their COUNTER (the LOST
        proof does not hold across a restarted COUNTER)."""
        return any(lo <= frame - 1 and frame <= hi for lo, hi in self.counted)

    def gap_missed(self, frame: int, reprimed: frozenset[int] = frozenset()) -> bool:
        """Whether the firmware missed every frame of the gap into encoder ``frame`` (no
        counter restart re-primed in the span that proves it, ``reprimed``, unless its count
        of the frames taken proves it: ``took_across``)."""
        return self.took_across(frame) or any(lo < frame <= hi and _clear(lo, hi, reprimed)
                                              for lo, hi in self.missed + self.same)

    def took_all(self, first: int, last: int, reprimed: frozenset[int] = frozenset()) -> bool:
        """Whether the firmware took exactly the log's frames ``first`` .. ``last``."""
        return any(lo <= first and last <= hi and _clear(lo, hi, reprimed)
                   for lo, hi in self.same)


NOTHING = Seen([], [])


def _clear(lo: int, hi: int, reprimed: frozenset[int]) -> bool:
    return not any(lo < r <= hi for r in reprimed)


def seen_by_pages(pages: LostPages, totals: TotalsPages, gap_frames: IntArray,
                  gap_missing: IntArray) -> Seen:
    """``Seen`` of a life's pages (module docstring), over every pair of pages up to
    ``PAIR_PAGES`` apart and, per gap, the pages around it however far apart
    (``pagechain.long_pairs``): ``gap_frames`` the frames after the log's gaps (sorted),
    ``gap_missing`` the frames each lacks (its sender-sequence step less one)."""
    n = len(pages.lo)
    if n < 2 or len(totals.sent_s) < 2:
        return NOTHING
    cum = np.concatenate(([0], np.cumsum(gap_missing, dtype=np.int64)))
    near = [(np.arange(n - d), np.arange(d, n)) for d in range(1, min(PAIR_PAGES, n - 1) + 1)]
    far = long_pairs(pages.lo, pages.hi, gap_frames, PAIR_PAGES)
    i = np.concatenate([a for a, _ in near] + [far[0]])
    j = np.concatenate([b for _, b in near] + [far[1]])
    lo, hi = pages.lo[i], pages.hi[j]
    missing = (cum[np.searchsorted(gap_frames, hi, side="right")]
               - cum[np.searchsorted(gap_frames, lo, side="right")])
    calm = quiet(totals.sent_s, totals.breaks, pages.lo_s[i], pages.sent_s[j])
    grew = (pages.lost[j] - pages.lost[i]) & 0xFF
    by_lost = calm & (missing > 0) & (grew >= missing)
    sure = pages.lo[j] - pages.hi[i] + 1  # the log's frames surely among those counted
    exact = pages.chain[i] == pages.chain[j]  # OK's growth exact (``pagechain``)
    by_ok = calm & exact & (sure > 0) & (pages.ok_u[j] - pages.ok_u[i] <= sure)
    by_ok |= by_checked(pages, totals, i, j)  # OK's growth counts the log's frames too
    missed = list(zip(lo[by_lost].tolist(), hi[by_lost].tolist(), strict=True))
    windows = list(zip(i[by_lost | by_ok].tolist(), j[by_lost | by_ok].tolist(), strict=True))
    counted = list(zip(i[by_ok].tolist(), j[by_ok].tolist(), strict=True))
    m = np.where(exact, skipped_frames(pages, totals, i, j), -1)
    skips = [(int(pages.hi[a]), int(pages.lo[b]), int(k))
             for a, b, k in zip(i[m > 0].tolist(), j[m > 0].tolist(), m[m > 0].tolist(),
                                strict=True)]
    got = by_received(pages, totals, i, j)
    return Seen(_runs(windows, pages), missed, counted=_runs(counted, pages), skips=skips,
                received=_runs(list(zip(i[got].tolist(), j[got].tolist(), strict=True)), pages))


def _runs(windows: list[tuple[int, int]], pages: LostPages) -> list[Span]:
    """Proven windows (pairs of pages) whose counted frames meet or overlap joined (their
    union is counted frames too): from the first page's ``hi`` to the last page's ``lo``."""
    runs: list[Span] = []
    start, end = -1, -1
    for i, j in sorted(windows):
        if i > end:  # a counted stretch not proven lies between
            if end > start:
                runs.append((int(pages.hi[start]), int(pages.lo[end])))
            start, end = i, j
        else:
            end = max(end, j)
    if end > start:
        runs.append((int(pages.hi[start]), int(pages.lo[end])))
    return [(a, b) for a, b in runs if a <= b]


def with_boot(pages: LostPages, totals: TotalsPages, first_s: float, boot_s: float
              ) -> tuple[LostPages, TotalsPages]:
    """The pages with the firmware's power-up before them, at ``boot_s`` (before the log's first
    encoder frame, at ``first_s``, on which it primed, ``host.judge.powerup``): every count 0
    and no frame taken, so the first encoder frame logged after it is frame 0 (its ``lo``, 0,
    bounds no missing frame: none lies before frame 0); chained to the first pages
    (``pagechain.boot_ok``, ``boot_breaks``)."""
    zero, now = np.zeros(1, dtype=np.int64), np.array([boot_s])
    ok_u, chain = boot_ok((int(pages.ok[0]), int(pages.ok_u[0]), int(pages.chain[0]),
                           float(pages.sent_s[0])), boot_s)
    breaks = zero if not len(totals.sent_s) else [boot_breaks(
        (float(totals.sent_s[0]), int(totals.rejected[0]), int(totals.overflowed[0]),
         int(totals.breaks[0])), boot_s)]
    return (LostPages(np.r_[zero, pages.lo], np.r_[[first_s], pages.lo_s], np.r_[zero, pages.hi],
                      np.r_[zero, pages.ok], np.r_[zero, pages.lost], np.r_[now, pages.sent_s],
                      np.r_[[ok_u], pages.ok_u], np.r_[[chain], pages.chain],
                      np.r_[zero, pages.raw_lo], np.r_[zero, pages.raw_hi],
                      np.r_[[UNKNOWN], pages.refused],
                      None if pages.host_lost is None else np.r_[zero, pages.host_lost]),
            TotalsPages(np.r_[now, totals.sent_s], np.r_[zero, totals.rejected],
                        np.r_[zero, totals.overflowed], np.r_[breaks, totals.breaks]))


def seen_of(pages: list[Page], totals: list[Totals], gaps: list[tuple[int, int]],
            boot: tuple[float, float] | None = None, lost_sums: IntArray | None = None) -> Seen:
    """``seen_by_pages`` of pages, totals and gaps (frame after, frames missing) kept as rows;
    ``boot``: the log's first encoder frame's time and the power-up's (``with_boot``);
    ``lost_sums``: per encoder frame of the life, the host's E2E LOST summed up to it
    (``host_lost_sums``; None: not known, ``gapchecked.by_checked`` does without)."""
    if not pages:
        return NOTHING
    col = list(zip(*pages, strict=True))
    ints = [np.array(col[k], dtype=np.int64) for k in (0, 2, 3, 4, 6, 7, 8, 9, 10)]
    lost = LostPages(ints[0], np.array(col[1], dtype=np.float64), ints[1], ints[2], ints[3],
                     np.array(col[5], dtype=np.float64), ints[4], ints[5], ints[6], ints[7],
                     ints[8], None if lost_sums is None else lost_sums[ints[0]])
    tcol = list(zip(*totals, strict=True)) if totals else [(), (), (), ()]
    counts = TotalsPages(np.array(tcol[0], dtype=np.float64), np.array(tcol[1], dtype=np.int64),
                         np.array(tcol[2], dtype=np.int64), np.array(tcol[3], dtype=np.int64))
    if boot is not None:
        lost, counts = with_boot(lost, counts, *boot)
    gcol = list(zip(*gaps, strict=True)) if gaps else [(), ()]
    return seen_by_pages(lost, counts, np.array(gcol[0], dtype=np.int64),
                         np.array(gcol[1], dtype=np.int64))


@dataclass
class PageEvidence:
    """The evidence of a life's frames fed in chunks (the whole log: one chunk), the same for
    the whole-log and the streamed judge: the pages made with their tick's summary
    (``PageKeeper``) and the log's gaps; ``seen`` then."""

    decoder: BulkDecoder
    first_s: float | None = None  # the first encoder frame's time
    keeper: PageKeeper = field(default_factory=PageKeeper)
    _enc_count: int = 0  # encoder frames fed
    _lost_sums: list[IntArray] = field(default_factory=list)  # ``host_lost_sums``, by chunk
    _last_counter: int | None = None  # the last accepted encoder frame's COUNTER
    _lost_sum: int = 0  # the host's E2E LOST summed over the encoder frames fed
    _raw_count: int = 0  # encoder frames fed, those the host's E2E check refused too
    _offset: int = 0  # frames fed
    _last_seq: int | None = None
    _last_enc_s: float = -math.inf
    _gaps: list[tuple[int, int]] = field(default_factory=list)  # frame after, frames missing
    _gap_seq: dict[int, int] = field(default_factory=dict)  # per gap: the sequence number before
    _gap_s: dict[int, tuple[float, float, int]] = field(default_factory=dict)  # per long gap: the
    # bus times of its frames before and after, its sequence step (``holetaken``)
    resets: ResetLog = field(default_factory=ResetLog)  # the summaries' ERROR_MASK
    late: LateFrames = field(default_factory=LateFrames)  # encoder frames refused (gapfill)
    _anchors: Anchors = NO_ANCHORS  # the last accepted encoder frames (gapfill's anchors)
    _usable: bool = True  # the DBC has the signals
    _holes: list[int] = field(default_factory=list)  # ``Seen.holes``
    _last_raw_s: float | None = None  # the last frame's time
    _dark: int = 0  # dark gaps of the log since its last encoder frame (refused ones too)

    def feed(self, chunk: FrameArrays, enc: Encoders) -> None:
        """The next chunk and its accepted encoder frames (``index``: in the frames fed)."""
        self.keeper.cycle_s = enc.cycle_s
        if self.first_s is None and len(enc.seq):
            self.first_s = float(enc.timestamp_s[0])
        self.late.add(*late_in_chunk(chunk, self.decoder, enc, self._offset, self._anchors))
        self._anchors = recent_anchors(self._anchors, enc, ANCHOR_FRAMES + 1)  # lap_less_one
        self._add_gaps(enc)
        self._add_holes(chunk, enc)
        raw = self._raw_rows(chunk)
        if self._usable:
            self._add_status(chunk, enc, raw)
        sums = host_lost_sums(enc.counter, self._last_counter, self._lost_sum)
        self._lost_sums.append(sums)
        self._enc_count += len(enc.seq)
        if len(enc.seq):
            self._last_counter, self._lost_sum = int(enc.counter[-1]), int(sums[-1])
        self._raw_count += len(raw)
        self._offset += len(chunk)
        if len(enc.seq):
            self._last_enc_s = float(enc.timestamp_s[-1])

    def seen(self, power_up: bool) -> Seen:
        """``seen_by_pages`` of what was fed; ``power_up``: the firmware primed on the first
        encoder frame fed (``with_boot``)."""
        keeper = self.keeper
        keeper.keep_pending(True)  # no summary after the last: not let out in a burst
        fills = {b: f for b, missing in self._gaps
                 if (f := self.late.fill(self._gap_seq[b], missing + 1)) is not None}
        known = {b: k for b, missing in self._gaps
                 if (k := self.late.known(self._gap_seq[b], missing + 1)) is not None}
        holes = frozenset(self._holes)
        if not self._usable or keeper.cycle_s is None:
            return Seen([], [], fills, holes=holes)
        boot = (None if not power_up or self.first_s is None
                else (self.first_s, self.first_s - keeper.cycle_s))
        sums = np.concatenate(self._lost_sums) if self._lost_sums else None
        return replace(seen_of(keeper.pages, keeper.totals, self._gaps, boot, sums), fills=fills,
                       holes=holes, through=through_gaps(keeper.pages, keeper.totals,
                                                         keeper.cycle_s, self._gap_s),
                       resets=self.resets.resets(self._gap_s, keeper.cycle_s, holes),
                       known=known)

    def _add_holes(self, chunk: FrameArrays, enc: Encoders) -> None:
        """``Seen.holes``: the accepted encoder frames at or after an encoder frame of the chunk
        (refused or not) since which, after the encoder frame before it, the log went dark
        (no frame of any message for ``DARK_CYCLES`` encoder cycles: the recorder lost them)."""
        try:
            rows = self.decoder.select(chunk, "WHEEL_ENCODERS")
        except (DecodeError, KeyError):
            return
        cycle_s = self.keeper.cycle_s
        if cycle_s is None or len(chunk) == 0:
            return
        prior = np.concatenate(([chunk.timestamp_s[0] if self._last_raw_s is None
                                 else self._last_raw_s], chunk.timestamp_s))
        dark = np.cumsum(np.diff(prior) > DARK_CYCLES * cycle_s)  # dark gaps up to a row
        since = np.diff(np.concatenate(([0], dark[rows])))  # since the encoder frame before
        since[:1] += self._dark
        after = rows[since > 0] + self._offset
        self._holes += (self._enc_count + np.searchsorted(enc.index, after)).tolist()
        self._dark = int(dark[-1] - dark[rows[-1]]) if len(rows) else self._dark + int(dark[-1])
        self._last_raw_s = float(chunk.timestamp_s[-1])

    def _add_gaps(self, enc: Encoders) -> None:
        if len(enc.seq) == 0:
            return
        prior = np.concatenate(([enc.seq[0] if self._last_seq is None else self._last_seq],
                                enc.seq))
        step = np.diff(prior)
        k = np.flatnonzero(step > 1)
        self._gaps += zip((self._enc_count + k).tolist(), (step[k] - 1).tolist(), strict=True)
        self._gap_seq.update(zip((self._enc_count + k).tolist(), prior[k].tolist(), strict=True))
        t = np.concatenate(([self._last_enc_s], enc.timestamp_s))
        self._gap_s.update((self._enc_count + i, (float(t[i]), float(t[i + 1]), int(step[i])))
                           for i in k[step[k] > LONG_GAP_FRAMES].tolist())
        self._last_seq = int(enc.seq[-1])

    def _raw_rows(self, chunk: FrameArrays) -> IntArray:
        """The chunk's WHEEL_ENCODERS frames (8 bytes), refused ones too (``gapchecked``)."""
        try:
            return np.asarray(self.decoder.select(chunk, "WHEEL_ENCODERS"), dtype=np.int64)
        except (DecodeError, KeyError):
            return np.zeros(0, dtype=np.int64)

    def _add_status(self, chunk: FrameArrays, enc: Encoders, raw: IntArray) -> None:
        """The chunk's status frames, each to the ``PageKeeper`` with its page's counts."""
        try:
            lost = self.decoder.decode_page(chunk, "ODOM_STATUS", LOST_PAGE)
            totals = self.decoder.decode_page(chunk, "ODOM_STATUS", TOTALS_PAGE)
        except DecodeError:
            self._usable = False
            return
        if "ENC_E2E_LOST" not in lost or "OVERFLOWED_FRAMES" not in totals:
            self._usable = False
            return
        head = self.decoder.decode(chunk, "ODOM_STATUS")  # PAGE and COUNTER by the DBC
        rows = np.asarray(head["index"], dtype=np.int64)
        crc = crc_holds(chunk, self.decoder, rows)
        self.resets.feed(chunk, self.decoder, rows[crc])  # ``nearthreshold``
        before = np.searchsorted(enc.index, rows + self._offset)  # enc.index: in the log
        last_s = np.where(before > 0, enc.timestamp_s[np.maximum(before - 1, 0)]
                          if len(enc.seq) else 0.0, self._last_enc_s)
        counts = np.zeros((2, len(rows)), dtype=np.int64)
        counted = np.zeros(len(rows), dtype=bool)
        refused = np.full(len(rows), UNKNOWN, dtype=np.int64)
        if set(REFUSED) <= lost.keys():
            at = np.searchsorted(rows, np.asarray(lost["index"], dtype=np.int64))
            refused[at] = packed_rows(*(np.asarray(lost[name]).astype(np.int64)
                                        for name in REFUSED))
        for page, names in ((lost, ("ENC_E2E_OK", "ENC_E2E_LOST")),
                            (totals, ("REJECTED_FRAMES", "OVERFLOWED_FRAMES"))):
            at = np.searchsorted(rows, np.asarray(page["index"], dtype=np.int64))  # status rows
            counted[at] = True
            for k, name in enumerate(names):
                counts[k, at] = np.asarray(page[name]).astype(np.int64)
        statuses(self.keeper, StatusRows(
            np.asarray(head["PAGE"], dtype=np.int64), np.asarray(head["COUNTER"], dtype=np.int64),
            chunk.timestamp_s[rows], crc, self._enc_count + before, last_s, counts[0], counts[1],
            counted, self._raw_count + np.searchsorted(raw, rows), refused))


def host_lost_sums(counter: IntArray, last: int | None, start: int) -> IntArray:
    """Per accepted encoder frame (``counter``: their COUNTERs, ``last``: the one accepted
    before them, None: none), ``start`` plus the frames the host's E2E check counted lost up to
    it: (COUNTER - previous - 1) mod 16 each, as the firmware's ENC_E2E_LOST counts them
    (``gapchecked.by_checked``)."""
    first = last if last is not None else (int(counter[0]) - 1 if len(counter) else 0)
    lost = (np.diff(np.concatenate(([first], counter))) - 1) & ENC_COUNTER_MASK
    sums: IntArray = start + np.cumsum(lost, dtype=np.int64)
    return sums


def crc_holds(frames: FrameArrays, decoder: BulkDecoder, rows: IntArray,
              name: str = "ODOM_STATUS") -> npt.NDArray[np.bool_]:
    """Which frames of message ``name`` at ``rows`` carry a right CRC, whatever their sequence
    (a page the host's E2E window refused after the bus lost a few is as good evidence)."""
    return crc_right(frames, decoder, rows, name, unprotected=True)


def seen_in_log(frames: FrameArrays, decoder: BulkDecoder, enc: Encoders, *,
                power_up: bool = False) -> Seen:
    """``PageEvidence.seen`` of a whole log (one life); ``power_up``: the log starts at the
    firmware's power-up, it primed on the log's first encoder frame (``with_boot``)."""
    evidence = PageEvidence(decoder)
    evidence.feed(frames, enc)
    return evidence.seen(power_up)
