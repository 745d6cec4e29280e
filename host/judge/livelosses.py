"""The live judge's loss allowance (``host.judge.tracking``): ``losses.loss_allowance``'s rule on
the window of the latest encoder frames. Where the firmware's ENC_E2E_LOST grew by more than the
bus's own gaps since its previous page, it lost frames the bus carried (``losses.firmware_losses``):
the position may leave the fine reference by the worst error that many frames lost in runs make
there (``losses.worst_runs_m``), from the frame of the previous page on, as ``analyze`` allows
it. A sample's error beyond its allowance is settled once no later page can reach its frame;
then ``wrongs`` (``host.judge.posewrongs``) latches it when it was beyond the limit.

The window's frames are numbered here without the pose halves (``window_encoders(window)``):
a recorder's chunk read in a burst is numbered a lap short, so a span holding such a chunk and
frames the firmware lost counts 16 more frames lost per lap than ``analyze`` does (its
numbering tells the chunk, ``senderseq.pose_skips``). Left so, not aligned: ``lost_beyond_gaps``
subtracts every gap of the log as frames the firmware lost too, which a recorder's chunk need
not be, so ``analyze``'s count is the lower bound of the firmware's losses there and this one
nearer the upper; the pages cannot tell which frames it lost.

After a stall before a life's first sample (``livefirst``: the position placed again at the next
sample, bounded from the frame the firmware could first have primed on), the frames between those
two are the placement's, no span's (``losses.placement_accounted``, ``analyze``'s rule): told by
``stalled_first``, the placed sample's frame taken at the next ``record``; a span opened before
the stall was told (a page before the first sample, from the primed frame on) held only such
frames and is withdrawn. The same after a stall or hold mid-life (``livestall``: the position
placed again at the next sample compared, bounded from the last one compared before it): told by
``stalled_at``, the frames between are the placement's (``analyze``'s ``losses.life_placements``)
at every page after it was told. A page that came before (the firmware's first ODOM_STATUS after
the stall sent before its first pose) keeps its span whole: looser, never tighter.

A reboot told late (``Tracker.withdraw_from``) takes back the samples from its life's start: they
were the new firmware's poses against the old life's reference, settled when that reference
ended (issue #11: a correct firmware's 1.78 m beyond its allowance FAILed the fleet's verdict).
The largest settled error is marked only where it grew (bus time of the sample that raised it,
before, after: ``MARKS_KEPT`` of them), not per sample: the bridge's per-frame path stays as it
was. Going back to before the first raise withdrawn is exact while the raises were settled in
bus time order; beyond the marks kept it keeps the larger value (a FAIL kept, never a wrong pose
hidden)."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from itertools import pairwise

import numpy as np
import numpy.typing as npt

from odocan.host.judge.livepose import MARKS_KEPT
from odocan.host.judge.livewindow import ENC_WINDOW, Columns, window_encoders
from odocan.host.judge.losses import (
    OneSteps,
    lost_beyond_gaps,
    placement_accounted,
    worst_runs_m,
)
from odocan.host.judge.posewrongs import PoseWrongs
from odocan.host.judge.reference import Geometry

LostPage = tuple[int, int, int | None, int | None]  # ENC_E2E_LOST, latest frame, OK, LOST_FRAMES


class LiveAllowance:
    """The allowance per lossy span and every sample's error beyond it."""

    def __init__(self) -> None:
        # ENC_E2E_LOST, the latest frame then, ENC_E2E_OK and the latest LOST_FRAMES (None:
        # unknown)
        self.lost_page: LostPage | None = None
        self.lost_total: int | None = None  # LOST_FRAMES of the latest FRAME_TOTALS page
        self.spans: list[tuple[int, float]] = []  # (first frame, m) per lossy span or twin
        self._revisable: deque[tuple[int, float, float]] = deque()  # (frame, m, t s) since
        self._in_order = True  # ``_revisable`` by frame (then settled from its head)
        self._beyond_settled_m = 0.0  # largest error beyond its allowance of the other samples
        # where it grew: (the raising sample's bus time s, m before, m after), ``withdraw_from``
        self._raises: deque[tuple[float, float, float]] = deque(maxlen=MARKS_KEPT)
        self.wrongs = PoseWrongs()  # the samples beyond the limit, latched once settled
        # the latest samples' errors (frame, dx, dy m, dheading rad, t s): ``rejudge``
        self._errors: deque[tuple[int, float, float, float, float]] = deque(maxlen=ENC_WINDOW)
        # a stall placement before the life's first sample: (primed, placed frame; None until
        # the next ``record``), and the spans opened since the power-up before it was told
        self.placed: tuple[int, int | None] | None = None
        self._first_spans: list[tuple[int, float]] | None = None
        self._placed_before: list[tuple[int, int]] = []  # earlier placements (``stalled_at``)
        # the latest sample recorded: its frame, and its allowance (m) kept when its reference
        # ended (``restart``; None: that reference still runs, ``at_m`` tells it)
        self._latest: tuple[int, float | None] | None = None

    def record(self, seq: int, error: dict[str, float], fast: bool, t_s: float,
               shown: bool = True) -> None:
        """A sample at encoder frame ``seq`` (its ODOM_POSE_Y at bus time ``t_s``), ``error``
        from the reference (``dpos_m``, ``dheading_rad``); ``shown``: it is the tracker's latest
        (``vs_reference.latest``, ``latest_m``), not a resend, a lone half or one judged again."""
        dpos_m = error["dpos_m"]
        if shown:
            self._latest = (seq, None)
        if self._first_spans is not None or (self.placed and self.placed[1] is None):
            self._sampled(seq)
        self._errors.append((seq, error["dx_m"], error["dy_m"], error["dheading_rad"], t_s))
        self.wrongs.sample(seq, t_s, dpos_m, error["dheading_rad"])
        revisable = self._revisable
        if revisable and seq < revisable[-1][0]:
            self._in_order = False
        revisable.append((seq, dpos_m, t_s))
        if revisable[0][0] < seq - ENC_WINDOW:  # beyond any span's reach
            self.settle(seq - ENC_WINDOW, fast)

    def _sampled(self, seq: int) -> None:
        """The life's first sample compared, at encoder frame ``seq``: the one a stall's
        placement is made at, if one was told (``stalled_first``)."""
        self._first_spans = None
        if self.placed is not None and self.placed[1] is None:
            self.placed = (self.placed[0], seq)

    def stalled_first(self, primed: int) -> None:
        """A stall before the life's first sample (``livefirst``), the position placed again
        at the next sample, from encoder frame ``primed`` (module docstring)."""
        self.placed = (primed, None)
        opened, self._first_spans = self._first_spans or [], None
        self.spans = [span for span in self.spans if span not in opened or span[0] < primed]

    def stalled_at(self, last: int) -> None:
        """A stall or hold mid-life (``livestall``), the position placed again at the next
        sample compared, its allowance from encoder frame ``last`` (the last sample compared
        before it; module docstring)."""
        if self.placed is not None and self.placed[1] is not None:
            self._placed_before = [*self._placed_before, (self.placed[0], self.placed[1])][-8:]
        self.placed = (last, None)

    def rejudge(self, from_seq: int, until: int | None, shift: tuple[float, float]) -> None:
        """The reference was wrong by ``shift`` (dx, dy m) from encoder frame ``from_seq`` on
        (before ``until``, None: to the latest; a placement's allowance withdrawn:
        ``host.judge.livegapseen``): the latest samples there are judged again with the
        reference moved by it (a sample already judged right may now be latched wrong)."""
        errors = list(self._errors)
        self._errors.clear()
        for seq, dx, dy, dheading, t_s in errors:
            if from_seq <= seq and (until is None or seq < until):
                dx, dy = dx - shift[0], dy - shift[1]
                self.record(seq, {"dx_m": dx, "dy_m": dy, "dpos_m": math.hypot(dx, dy),
                                  "dheading_rad": dheading}, False, t_s, shown=False)
            else:
                self._errors.append((seq, dx, dy, dheading, t_s))

    def settle(self, upto: int, fast: bool) -> None:
        """The samples up to encoder frame ``upto`` can get no more allowance."""
        revisable = self._revisable
        if self._in_order and fast:  # those up to ``upto`` lead
            settled = []
            while revisable and revisable[0][0] <= upto:
                settled.append(revisable.popleft())
        else:
            settled = [s for s in revisable if s[0] <= upto]
            self._kept_revisable(s for s in revisable if s[0] > upto)
        if settled:
            beyond = [(f, e - self.at_m(f)) for f, e, _ in settled]
            if max(b for _, b in beyond) > self._beyond_settled_m:  # rare: marked
                self._raised(settled, beyond)
            self.wrongs.judged(beyond)

    def _kept_revisable(self, kept: Iterable[tuple[int, float, float]]) -> None:
        self._revisable = deque(kept)
        frames = [f for f, _, _ in self._revisable]
        self._in_order = frames == sorted(frames)

    def _raised(self, settled: list[tuple[int, float, float]],
                beyond: list[tuple[int, float]]) -> None:
        """The largest settled error grew: each sample that raised it marked (module
        docstring)."""
        for (_, _, t_s), (_, beyond_m) in zip(settled, beyond, strict=True):
            if beyond_m > self._beyond_settled_m:
                self._raises.append((t_s, self._beyond_settled_m, beyond_m))
                self._beyond_settled_m = beyond_m

    def withdraw_from(self, t_s: float) -> None:
        """The samples compared from bus time ``t_s`` on were not this reference's (a reboot
        told late: ``Tracker.withdraw_from``): their errors are taken back, settled or not
        (module docstring); ``wrongs`` are the tracker's to withdraw."""
        if any(s[2] >= t_s for s in self._revisable):
            self._kept_revisable(s for s in self._revisable if s[2] < t_s)
        self._errors = deque((e for e in self._errors if e[4] < t_s), maxlen=ENC_WINDOW)
        raises = list(self._raises)
        first = next((i for i, r in enumerate(raises) if r[0] >= t_s), None)
        if first is None:
            return
        kept, top_m = raises[:first], raises[first][1]
        for raised_s, _, after_m in raises[first + 1:]:  # settled out of bus time order
            if raised_s < t_s and after_m > top_m:
                kept.append((raised_s, top_m, after_m))
                top_m = after_m
        self._raises = deque(kept, maxlen=MARKS_KEPT)
        self._beyond_settled_m = top_m

    def restart(self, upto: int, fast: bool) -> None:
        """A new reference: the samples so far are settled, no span reaches past it."""
        self.settle(upto, fast)
        if self._latest is not None and self._latest[1] is None:
            self._latest = (self._latest[0], self.at_m(self._latest[0]))
        self.wrongs.close()  # an episode does not run on into another reference
        self.spans, self._placed_before = [], []
        self.placed = self._first_spans = None

    def primed(self, seq: int, reboot: bool = False) -> LostPage | None:
        """A life proven to start at its power-up, primed on encoder frame ``seq``: its
        ENC_E2E_LOST counted from 0 there, so its first page's growth beyond the gaps since
        that frame is a lossy span too (``losses.firmware_losses``' power-up page). A
        ``reboot``'s pages may come before the frame is known (its samples wait for the page
        that names it, ``livestart``): the latest of them is returned, to be taken again from
        ``seq`` (``on_page``). Its count was read as the new life's baseline: a correct
        firmware that lost 35 frames from its mailbox while it started under load was judged
        with no allowance, 0.85 mm past the limit (issue #11, ``tests/test_trial38``)."""
        before = self.lost_page
        if before is None or (reboot and before[1] >= seq):
            self.lost_page = (0, seq, 1, 0)
            self.placed, self._first_spans = None, []
            return before
        return None

    def at_m(self, seq: int) -> float:
        """The allowance (m) at encoder frame ``seq``."""
        if not self.spans:  # the usual case (per sample settled): ``sum`` of nothing
            return 0
        return sum(a for first, a in self.spans if seq > first)

    def latest_m(self) -> float:
        """The allowance (m) of the latest sample recorded, under the reference it was judged
        against: after a restart (``restart``: its spans dropped) the one it had when that
        reference ended, not the new reference's (issue #11: the monitor's latest sample, of
        the reference before an unseen restart while the new life's samples are held, was
        judged with no allowance: POSE WRONG 1 s for 0.1985 mm within its 1.456 mm for the 26
        frames the firmware lost, ``tests/test_ctrl_restart_captures.py``); 0 before any."""
        if self._latest is None:
            return 0.0
        seq, ended_m = self._latest
        return self.at_m(seq) if ended_m is None else ended_m

    def max_beyond_m(self) -> float:
        """The largest position error beyond its allowance (m) of every sample recorded."""
        recent = (e - self.at_m(f) for f, e, _ in self._revisable)
        return max([self._beyond_settled_m, *recent])

    def on_page(self, lost: int, upto: int, window: Columns | None, sampled: set[int],
                steps_of: tuple[Geometry, int, str | None], ok: int | None = None) -> None:
        """ODOM_STATUS's ENC_E2E_LOST ``lost`` with encoder frame ``upto`` the latest; with a
        ``window`` (a reference running): a span from the previous page's frame where it grew
        beyond the gaps (``sampled``: frames a sample names, which the firmware had); ``ok``:
        its ENC_E2E_OK (u16) then, which unwraps a growth of 256 or more up to the growth of
        LOST_FRAMES (``lost_total``) since the previous page (``losses.unwrapped_lost``; the
        latest FRAME_TOTALS page heard, not the first after this one: a bound never above
        the whole log's)."""
        before, self.lost_page = self.lost_page, (lost, upto, ok, self.lost_total)
        if before is None or window is None or not len(window):
            return
        if (lost - before[0]) & 0xFF == 0 and _quiet(window, before[1]):
            return  # the common page, told from the rows not copied yet (no numpy)
        seqs = window.col("seq")
        i0, i1 = int(np.searchsorted(seqs, before[1])), len(seqs) - 1
        if i0 >= len(seqs) or seqs[i0] != before[1]:
            return  # the previous page's frame left the window: not judged
        counters = window.col("counter")[i0:]
        if (lost - before[0]) & 0xFF == 0 and bool(np.all(counters[1:] != counters[:-1])):
            return  # no loss told, and no sender step of 0 (each >= 1: no negative gap)
        enc = window_encoders(window)
        sent = enc.seq
        n = int(lost_beyond_gaps(np.array(before[0]), np.array(lost), sent[i0], sent[i1],
                                 np.array(i1 - i0), ok_growth=_growth(ok, before[2]),
                                 total_growth=_growth(self.lost_total, before[3])))
        geometry, bits, integrator = steps_of
        if n > 0 and integrator is not None:
            steps = OneSteps.of_firmware(enc, geometry, bits, integrator)
            lost_ok = ~np.isin(seqs.astype(np.int64), list(sampled))  # named: not lost
            lost_ok &= ~placement_accounted(seqs, self._placed_by(upto))
            self.spans.append(span := (before[1], worst_runs_m(steps, lost_ok, i0, i1, n)))
            if self._first_spans is not None:
                self._first_spans.append(span)

    def _placed_by(self, upto: int) -> list[tuple[int, int]]:
        """The placements at a page whose latest encoder frame is ``upto``: the latest one's
        frames after its first all the placement's while its sample is not compared yet."""
        if self.placed is None:
            return self._placed_before
        latest = self.placed[0], upto + 1 if self.placed[1] is None else self.placed[1]
        return [*self._placed_before, latest]


def _growth(now: int | None, then: int | None) -> npt.NDArray[np.int64] | None:
    """A u16 count's growth from ``then`` to ``now`` (None: either unknown)."""
    return None if now is None or then is None else np.array((now - then) & 0xFFFF)


def _quiet(window: Columns, first: int) -> bool:
    """The window's frames from seq ``first`` on, read as plain rows (``Columns.latest_from``:
    seq, pos, COUNTER, ...), give ``on_page`` nothing to judge: the frame ``first`` left the
    window (or none is that late), or no sender step of 0 follows it; False when they do, or
    when they reach too far back among the rows copied (``on_page`` reads the columns)."""
    rows = window.latest_from(first)
    if rows is None:
        return False
    if not rows or rows[0][0] != first:
        return True  # the previous page's frame left the window: not judged
    return all(a[2] != b[2] for a, b in pairwise(rows))
