"""The live judge's pose halves (``host.judge.tracking``): each ODOM_POSE_X and ODOM_POSE_Y half is
settled once bus time is half an encoder cycle past it or the next half of its message is heard
(then whether it queued is known: ``samples.queued_frames``), the encoder frame it names
resolved (``PoseTracker.named``); an X and a Y half naming one encoder frame make one on-board
sample (the first of each, as ``host.judge.samples.onboard_samples``: ``PoseTracker.on_pair``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from odocan.host.judge.livelatehalves import named_sent
from odocan.host.judge.livelone import judge_lone_live
from odocan.host.judge.liveresent import judge_resend
from odocan.host.judge.livewindow import HALF_WINDOW, QUEUED_GAP_S, Columns, Half

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

HALF_COLUMNS = ("pos", "enc_counter", "counter", "t_s")
END_SEQ = 1 << 62  # after every encoder frame: the watch's end (``HalfPairs.end``)


class HalfPairs:
    """``halves``: the latest halves heard of each message (``HALF_WINDOW``, the columns
    ``HALF_COLUMNS``: what names a frame); the latest half of each not settled yet (from bus
    time ``unsettled_from_s``, inf: none); the settled halves waiting for their other half, by
    the encoder frame they name; ``sampled``: the encoder frames a sample was made of."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        self.halves = {"x": Columns(HALF_COLUMNS, HALF_WINDOW),
                       "y": Columns(HALF_COLUMNS, HALF_WINDOW)}
        self._unsettled: dict[str, Half] = {}  # per message, the latest half heard
        self.unsettled_from_s = math.inf  # the earliest bus time among them (s)
        self._xs: dict[int, Half] = {}  # settled X halves by the encoder frame they name
        self._xs_waiting: dict[int, Half] = {}  # those of them not sampled yet (``_lone_before``)
        self._ys: dict[int, tuple[Half, bool]] = {}  # settled Y halves (and queued) waiting
        self.sampled: set[int] = set()  # encoder frames an on-board sample was made of
        self._late: dict[int, float] = {}  # halves held back on the bus: place, send time s

    def heard(self, name: str, half: Half, sent_s: float | None = None) -> None:
        """A half of message ``name`` ("x", "y"; its ``pos`` set) heard: the one before it of
        that message settled (its successor is heard: it is known whether it queued).
        ``sent_s``: held back on the bus, sent then (``livelatehalves``): kept among the
        halves (its neighbours' rules see it, as ``match_encoder`` sees every half), named
        where it was sent."""
        if sent_s is not None:
            self._late[half.pos] = sent_s
        self.halves[name].append(half.pos, half.enc_counter, half.counter, half.t_s)
        if name in self._unsettled:
            self._settle(name)
        self._unsettled[name] = half
        from_s = self.unsettled_from_s  # ``min`` written out (a C call per half; NaN: never due)
        self.unsettled_from_s = half.t_s if half.t_s < from_s else from_s

    def settle_due(self, t_s: float) -> None:
        """Bus time is ``t_s``: settle the halves heard ``QUEUED_GAP_S`` or more before, in the
        order heard."""
        due = []  # (a loop, not a generator sorted: per pose half)
        for name, half in self._unsettled.items():
            if t_s - half.t_s >= QUEUED_GAP_S:
                due.append((half.pos, name))
        if len(due) > 1:
            due.sort()
        for _, name in due:
            self._settle(name)

    def end(self) -> None:
        """The watch ends, no later frame comes (``watchend``): the halves not settled yet are
        settled (in the order heard), and every half still waiting for its partner is judged
        alone (``livelone``), as ``analyze`` judges a log's last lone half. Before, a half was
        settled only by a later half or bus time past it, and judged alone only when a later
        sample paired: a log ending on a pose (kobuki random seed 5, 8 s, cut after its last
        ODOM_POSE_X or ODOM_POSE_Y) had its last pose never judged live, X raised 100 m OK."""
        for _, name in sorted((half.pos, name) for name, half in self._unsettled.items()):
            self._settle(name)
        self._lone_before(END_SEQ)

    def forget(self, before: int) -> None:
        """Drop what is kept of the encoder frames before ``before`` (seq): bounded state."""
        self._xs = {seq: half for seq, half in self._xs.items() if seq >= before}
        self._xs_waiting = {seq: half for seq, half in self._xs_waiting.items() if seq >= before}
        self._ys = {seq: half for seq, half in self._ys.items() if seq >= before}
        self.sampled = {seq for seq in self.sampled if seq >= before}

    def _settle(self, name: str) -> None:
        """Resolve the encoder frame the unsettled half of ``name`` names, and pair it."""
        half = self._unsettled.pop(name)
        rest = self._unsettled  # x, y: one left at most (per pose half: no list, no min())
        self.unsettled_from_s = (math.inf if not rest else next(iter(rest.values())).t_s
                                 if len(rest) == 1 else min(h.t_s for h in rest.values()))
        tracker = self._tracker
        sent_s = self._late.pop(half.pos, None) if self._late else None
        if sent_s is None:
            seq, queued = tracker.named(self.halves[name], half.pos)
        else:  # held back on the bus: named where sent, in frame order (livelatehalves)
            seq, queued = named_sent(tracker.window.rows, half.enc_counter, sent_s), False
            seq = seq if seq > tracker.stall.last_compared else -1
        last = tracker.last_pair  # (``judge_resend`` judges only a frame sampled last)
        if seq < 0 or tracker.twins.twinned(seq) or (
                last is not None and last[0].seq == seq and judge_resend(name, seq, half, tracker)):
            if seq < 0 or tracker.twins.twinned(seq):  # a power-up pose's: livepowerpose
                tracker.powerpose.left_out(name, half, tracker)
            return  # left out, as analyze leaves it out (unmatched); a resend judged
        if name == "x":
            if seq not in self._xs:
                self._xs[seq] = half
                if seq not in self.sampled:
                    self._xs_waiting[seq] = half
            waiting = self._ys.pop(seq, None)
            if waiting is not None:
                self._pair(seq, half, *waiting)
        elif seq in self._xs:
            self._pair(seq, self._xs[seq], half, queued)
        else:
            self._ys.setdefault(seq, (half, queued))

    def _pair(self, seq: int, x: Half, y: Half, queued: bool) -> None:
        """The X and Y halves naming encoder frame ``seq``: one on-board sample (the first)."""
        self._ys.pop(seq, None)
        if seq in self.sampled:
            return
        self._tracker.queued.paired(seq, x.t_s, y.t_s)  # one held before judged (livequeuedfirst)
        self._lone_before(seq)
        self.sampled.add(seq)
        self._xs_waiting.pop(seq, None)
        self._tracker.on_pair(seq, x, y, queued)
        self._tracker.powerpose.judge(self._tracker)  # a power-up pose left out (livepowerpose)

    def _lone_before(self, seq: int) -> None:
        """The halves waiting for a partner naming frames before ``seq``, which is sampled
        now: their partners were lost; each judged alone (``livelone``), in frame order. The X
        halves looked at are those not sampled (``_xs_waiting``: a few, where ``_xs`` keeps up
        to two encoder windows' worth, which a scan per pair made a tenth of a bridge's CPU)."""
        lone: list[tuple[int, str, Half]] = []
        # plain loops over the keys (per pair: a comprehension is a call in CPython 3.11), the
        # usual pair's X alone waiting and no Y: none lone
        for s in list(self._xs_waiting):
            if s < seq:
                self._xs_waiting.pop(s)
                lone.append((s, "x", self._xs.pop(s)))
        if self._ys:
            for s in list(self._ys):
                if s < seq:
                    lone.append((s, "y", self._ys.pop(s)[0]))
        if len(lone) > 1:
            lone.sort(key=lambda item: (item[0], item[1]))
        for s, name, half in lone:
            judge_lone_live(name, s, half, self._tracker)
