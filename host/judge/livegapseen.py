"""The live half of ``host.judge.gapseen`` (issue #11, one judge; rule 5: a PASS must never hide
a wrong pose): what the firmware's ODOM_STATUS pages prove it took, learnt frame by frame by the
live judge (``host.judge.tracking``: the monitor and the bridge), with the same core
(``gapseen.PageKeeper``: a page counts when made in its tick; ``gapseen.seen_of``: the pairs of
pages, ``seen_by_pages``) as the whole-log and the streamed judge.

A page proves frames taken only after the frames it counts: the live judge places its reference
after a gap at the next sample, with the gap's ``gapbound`` allowance (the firmware may have seen
frames the host missed), and holds the placements' parts (each gap with its allowance, a
stall's span with its merge allowance: ``liveplace.StallPlacer``) until the pages tell. When
they prove the firmware missed the gap too, or took exactly the log's frames over the stall, the
part's allowance is withdrawn: the placement is clamped again without it and the reference moved
back by the difference at the next sample (``StallPlacer.shift``), so the samples judged from
then show the error the allowance hid, as ``analyze`` shows it; a gap inside a run the pages
prove the firmware received exactly and refused ``m`` of (``Seen.skips``) is lowered to
``gapskips``' allowance (``livegapskips``). Bounded: the last ``KEPT_PAGES``
pages, the totals and gaps they reach, the spans proven over the last ``KEPT_FRAMES`` frames.

The samples judged since that placement are judged again then (``LiveAllowance.rejudge``): a
wrong pose is latched a page cycle or two (0.5 to 1 s) after its sample, as a lost frame's
allowance is settled (``host.judge.livelosses``). A proof that comes after later placements still
shrinks the budget (the allowances summed since the reference started, ``breaks``' rule) and
clamps the latest placement again. At the end of a watch (``end_of_watch``) the pages made with
the last summary are kept, as the whole-log judge keeps them at the end of a log.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from odocan.host.judge.gapchecked import REFUSED, packed
from odocan.host.judge.gapseen import (
    LOST_PAGE,
    NOTHING,
    PAIR_PAGES,
    TOTALS_PAGE,
    Page,
    PageKeeper,
    Seen,
    Span,
    seen_of,
)
from odocan.host.judge.holetaken import SENT, taken_through
from odocan.host.judge.livewindow import CYCLE_S
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.e2e import crc8h2f_p02_one

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

KEPT_PAGES = 4 * PAIR_PAGES  # ENC_E2E pages kept (16 s of pages): runs joined over them
KEPT_GAPS = 4_096  # gaps kept while no page comes (a firmware without them): bounded
KEPT_FRAMES = 4_096  # spans proven over the latest encoder frames kept (41 s at 100 Hz)
_VALUES = {LOST_PAGE: ("ENC_E2E_OK", "ENC_E2E_LOST"),
           TOTALS_PAGE: ("REJECTED_FRAMES", "OVERFLOWED_FRAMES")}


class LiveSeen:
    """The evidence of one firmware life heard frame by frame (``new_life`` at a reboot)."""

    def __init__(self, cycle_s: float = CYCLE_S) -> None:
        self.cycle_s = cycle_s
        self.seen = NOTHING  # what the pages kept prove, with the spans proven before
        self._enc_count = 0  # encoder frames of the life heard
        self._raw_count = 0  # every encoder frame heard before its E2E check (gapchecked)
        self._last_enc_s = -math.inf
        self._gaps: list[tuple[int, int]] = []  # frame after, frames missing
        self._boot: tuple[float, float] | None = None  # with_boot's times while its page is kept
        self._first: tuple[int, float] | None = None  # the life's first frame heard (seq, s)
        self.keeper = PageKeeper(cycle_s)
        self._kept = (0, 0)  # pages and totals kept when last looked at
        self._dirty = False  # a page kept since ``proven`` last ran

    def new_life(self) -> None:
        """A reboot: the new life's pages count from 0 (``host.judge.reboots``); the summary
        that told it (fed before) is the new life's first."""
        self.keeper, self._kept, self._gaps = self.keeper.new_life(), (0, 0), []
        self._boot, self._first, self._enc_count, self._raw_count = None, None, 0, 0

    def power_up(self, primed: int) -> None:
        """The firmware primed on encoder frame ``primed`` (seq): when it is the life's first
        heard, its boot is a page before it (``gapseen.with_boot``) while that page is kept."""
        if self._first is not None and self._first[0] == primed:
            self._boot = (self._first[1], self._first[1] - self.cycle_s)

    @property
    def first_seq(self) -> int | None:
        """The life's first encoder frame heard (the tracker's seq; the pages' frames count
        from it), None before it."""
        return None if self._first is None else self._first[0]

    def on_encoders(self, seq: int, t_s: float, periods: int) -> None:
        """Accepted encoder frame ``seq`` at bus time ``t_s``, ``periods`` of the sender's
        sequence after the frame before (``samples.sender_seq``); the life's frames are
        numbered from its first (``gapseen``'s frames of a life)."""
        if self._first is None:
            self._first = (seq, t_s)
        elif periods > 1:
            self._gaps.append((seq - self._first[0], periods - 1))
            del self._gaps[: max(len(self._gaps) - KEPT_GAPS, 0)]  # no page came for long
        self._enc_count, self._last_enc_s = seq - self._first[0] + 1, t_s

    def heard_encoder(self) -> None:
        """A WHEEL_ENCODERS frame of its length heard, before its E2E check, once, in bus order
        with the status frames (``gapchecked``'s frames logged, refused ones too)."""
        self._raw_count += 1

    def on_status(self, page: int, counter: int, t_s: float, crc_ok: bool,
                  value: tuple[int, ...] | None) -> bool:
        """An ODOM_STATUS frame (PAGE, COUNTER, bus time, its CRC holds, its page's two
        counts); True when a FRAME_TOTALS page was kept: ``proven`` may prove more (a window
        is proven only once the first FRAME_TOTALS page after its last page is kept)."""
        keeper = self.keeper
        keeper.status((page, counter, t_s, crc_ok, self._enc_count, self._last_enc_s,
                       self._raw_count), value)
        grew = len(keeper.totals) > self._kept[1]  # (a window ends in one)
        return self._kept_more() and grew

    def flush(self) -> bool:
        """The end of a watch: the pages made with the last summary kept (no summary after it:
        not let out in a burst, ``PageEvidence.seen``'s rule); True when one was."""
        self.keeper.keep_pending(True)
        return self._kept_more()

    def proven(self) -> Seen:
        """What the pages kept prove, with the spans proven before (``seen_of`` run only when
        asked after a page was kept: a clean drive asks nothing)."""
        if self._dirty:
            self._dirty = False
            new = seen_of(self.keeper.pages, self.keeper.totals, self._gaps, self._boot)
            base = self._first[0] if self._first is not None else 0
            horizon = base + self._enc_count - KEPT_FRAMES
            self.seen = Seen(_joined(self.seen.same, new.same, base, horizon),
                             _joined(self.seen.missed, new.missed, base, horizon),
                             counted=_joined(self.seen.counted, new.counted, base, horizon),
                             skips=_skips_joined(self.seen.skips, new.skips, base, horizon),
                             received=_joined(self.seen.received, new.received, base, horizon))
        return self.seen

    def through(self, a_s: float, b_s: float) -> int | None:
        """``holetaken.taken_through`` of the pages kept, for a hole of the encoder frames heard
        from bus time ``a_s`` to ``b_s`` (the live judge steps at ``b_s``, before the first
        FRAME_TOTALS page after it came: the totals heard so far must be quiet)."""
        return taken_through(self.keeper.pages, self.keeper.totals, self.cycle_s, a_s, b_s,
                             closed=False)

    def heard_in(self, a_s: float, b_s: float) -> bool:
        """Whether pages may yet tell what the firmware took in the hole of the encoder frames
        heard from bus time ``a_s`` to ``b_s`` (the live judge steps before the pages after it
        come): an ENC_E2E page kept sent inside it, or any FRAME_TOTALS page of this life (the
        proofs of frames taken or missed need them quiet: ``holetaken``, ``pagechain``).
        Either way both candidates are held until the pages had their time (with: until the
        pages after the hole come, ``told_after``) and decide, or the next pose chooses
        (``host.judge.livechoice``)."""
        return bool(self.keeper.totals) or any(a_s < page[SENT] < b_s
                                               for page in self.keeper.pages)

    def told_after(self, b_s: float) -> bool:
        """Whether the pages kept reach past a hole of the encoder frames heard that ends at bus
        time ``b_s``: an ENC_E2E page sent after it and a FRAME_TOTALS page after that one (the
        first window over the hole ``proven`` can close; ``host.judge.livechoice`` waits for
        it)."""
        after_s = next((page[SENT] for page in self.keeper.pages if page[SENT] > b_s), None)
        return after_s is not None and any(row[0] > after_s for row in self.keeper.totals)

    def _kept_more(self) -> bool:
        """Whether a page was kept since last asked; the oldest beyond ``KEPT_PAGES`` let go,
        and the totals and gaps only they reached (bounded memory)."""
        keeper = self.keeper
        if (len(keeper.pages), len(keeper.totals)) == self._kept:
            return False
        keeper.pages[:] = _unrepeated(keeper.pages)
        if len(keeper.pages) > KEPT_PAGES:
            del keeper.pages[: len(keeper.pages) - KEPT_PAGES]
            self._boot = None  # its page went with the oldest
            from_s = keeper.pages[0][1]
            before = sum(1 for sent_s, *_ in keeper.totals if sent_s < from_s)
            del keeper.totals[: max(before - 1, 0)]  # the last one before the first page kept
            self._gaps = [gap for gap in self._gaps if gap[0] > keeper.pages[0][0]]
        del keeper.totals[: max(len(keeper.totals) - 2 * KEPT_PAGES, 0)]  # no ENC page kept
        self._kept, self._dirty = (len(keeper.pages), len(keeper.totals)), True
        return True


def _unrepeated(pages: list[Page]) -> list[Page]:
    """The pages with the middle of every run of pages alike left out (the same frames before
    and after, the same counts, one chain: a bus silence of the encoder sender, a page every
    0.5 s): the first and the last of a run prove all the middle ones could, their counts
    chained (``pagechain``), so a silence longer than ``KEPT_PAGES`` pages keeps the page
    before it, and the pages after it can prove it (issue #11)."""
    out: list[Page] = []
    for page in pages:
        if len(out) >= 2 and _alike(out[-2], page) and _alike(out[-1], page):
            out[-1] = page
        else:
            out.append(page)
    return out


def _alike(a: Page, b: Page) -> bool:
    """lo, hi, ENC_E2E_OK, LOST and the chain the same (``gapseen.Page``)."""
    return a[0] == b[0] and a[2:5] == b[2:5] and a[6:] == b[6:]


def _joined(old: list[Span], new: list[Span], base: int, horizon: int) -> list[Span]:
    """The spans of both (each proven; ``new``'s numbered from frame ``base``), those ending
    before frame ``horizon`` let go."""
    spans = old + [(first + base, last + base) for first, last in new]
    return sorted({span for span in spans if span[1] >= horizon})


def _skips_joined(old: list[tuple[int, int, int]], new: list[tuple[int, int, int]], base: int,
                  horizon: int) -> list[tuple[int, int, int]]:
    """``_joined`` of ``Seen.skips`` (first, last, m; each run its own m: ``gapskips``)."""
    runs = old + [(first + base, last + base, m) for first, last, m in new]
    return sorted({run for run in runs if run[1] >= horizon})


def status_values(message: Any, data: bytes, data_ids: Any, decode: Any = None
                  ) -> tuple[int, int, bool, tuple[int, ...] | None] | None:
    """PAGE, COUNTER, whether the CRC holds (whatever the E2E sequence: ``gapseen.crc_holds``)
    and the page's two counts (ENC_E2E_OK and ENC_E2E_LOST, or REJECTED_FRAMES and
    OVERFLOWED_FRAMES; None on the other pages) of an ODOM_STATUS frame, by the DBC
    (``message``: cantools'; ``decode``: its ``decode(data, decode_choices=False)`` compiled,
    the bridge's ``livedecode.LiveDecoder``); None when it does not decode."""
    try:
        signals = (message.decode(data, decode_choices=False) if decode is None
                   else decode(data))
    except Exception:  # not decodable: the E2E check and the caller count it
        return None
    if "PAGE" not in signals or "COUNTER" not in signals:
        return None  # a --dbc without them
    page, counter = int(signals["PAGE"]), int(signals["COUNTER"])
    crc_ok = not data_ids or data[0] == crc8h2f_p02_one(data, data_ids[data[1] & ENC_COUNTER_MASK])
    names = _VALUES.get(page)
    value: tuple[int, ...] | None = None if names is None or not set(names) <= signals.keys() \
        else (int(signals[names[0]]), int(signals[names[1]]))
    if value is not None and page == LOST_PAGE and set(REFUSED) <= signals.keys():
        value += (packed(*(int(signals[name]) for name in REFUSED)),)  # gapchecked
    return page, counter, crc_ok, value


def heard_status(tracker: PoseTracker, message: Any, data: bytes, data_ids: Any,
                 t_s: float, decode: Any = None) -> None:
    """An ODOM_STATUS frame heard (before its E2E check: a page the host's window refused
    after the bus lost a few is as good evidence) at bus time ``t_s``: to the tracker's
    ``LiveSeen``; a placement part the pages now prove loses its allowance (module
    docstring; ``decode``: ``status_values``')."""
    if message.name != "ODOM_STATUS" or len(data) != message.length:
        return
    values = status_values(message, data, data_ids, decode)
    if values is None:
        return
    page, counter, crc_ok, value = values
    placer = tracker.placer
    if placer.seen.on_status(page, counter, t_s, crc_ok, value):  # a FRAME_TOTALS page kept
        if placer.waiting:
            placer.withdraw(placer.seen.proven())  # the reference moves at the next sample
        tracker.choice.paged(t_s)  # a held choice the pages may now decide (livechoice)
        tracker.laps.heard()  # ... and samples after a lap of the stamps (livelaphold)


def heard_encoder(tracker: PoseTracker, message: Any, data: bytes) -> None:
    """A frame heard before its E2E check, once (a frame held and judged again is not heard
    again): a WHEEL_ENCODERS one of its length to the tracker's ``LiveSeen``."""
    if message.name == "WHEEL_ENCODERS" and len(data) == message.length:
        tracker.placer.seen.heard_encoder()


def end_of_watch(tracker: PoseTracker) -> None:
    """The watch ends (no later frame comes): ``LiveSeen.flush`` and what it proves withdrawn,
    an ambiguous hole's choice made (``livechoice``), the samples after a lap of the stamps
    (``livelaphold``) and a new start's samples held judged (``livenewstart``), before the
    samples still waiting are judged
    (``posewrongs.PoseWrongs.finish``)."""
    placer = tracker.placer
    if placer.seen.flush() and placer.waiting:
        placer.withdraw(placer.seen.proven())
    tracker.choice.decide()  # no page comes now: an ambiguous hole's choice is made
    tracker.laps.decide()  # ... and the samples after a lap of the stamps are judged
    tracker.newstart.release()  # a new start's samples held: judged by its fit so far
