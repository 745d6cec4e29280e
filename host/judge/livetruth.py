"""The live judge's truth in the current firmware life's frame (``host.judge.tracking``): after a
reboot the new life's origin, in the truth's frame, is taken at its first truth sample
(``compare.life_origin``, as ``analyze``), and every truth sample is re-based into it
(``compare.rebase_truth``). ``TruthJudge``: the SIM_TRUTH parts heard by the tracker; three of
one encoder frame are judged against the reference there."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from odocan.host.judge.compare import life_origin
from odocan.host.judge.livepose import RING, FramePose, recent, truth_heading

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker

TruthSample = tuple[int, float, float, float]  # seq, x m, y m, SIM_TRUTH's heading rad


class LifeTruth:
    """The current life's origin (None in the first life: it came up with the simulator)."""

    def __init__(self) -> None:
        self.origin: tuple[float, float, float] | None = None
        self._pending = False  # after a reboot: the next truth sample sets the origin
        self._boot: list[TruthSample] = []  # heard while the new life waits for its frame
        self._last: TruthSample | None = None  # the latest heard (its encoder frame known)

    def new_life(self) -> None:
        """A reboot: the new firmware's first tick sends its pose frames before its summary,
        so the truth sample of the frame it primed on may have come before it was told."""
        self.origin, self._pending = None, True
        self._boot = [self._last] if self._last is not None else []

    def heard(self, seq: int | None, x_m: float, y_m: float, wrapped_rad: float,
              ref: FramePose | None, booting: bool) -> tuple[float, float, float]:
        """A truth sample (of encoder frame ``seq``, None: not known; ``ref``: the reference
        there, ``booting``: the new life waits for its frame), in the life's frame."""
        if seq is not None:
            self._last = (seq, x_m, y_m, wrapped_rad)
        if self._pending and ref is not None:
            self._set((x_m, y_m, wrapped_rad), ref)
        elif self._pending and booting and self._last is not None:
            self._boot.append(self._last)
        if self.origin is None:
            return x_m, y_m, wrapped_rad
        return rebased(x_m, y_m, wrapped_rad, self.origin)

    def booted(self, primed: int, ref_at: dict[int, FramePose]) -> None:
        """The new life started at encoder frame ``primed``: its first truth sample heard
        meanwhile sets its origin (``ref_at``: the reference by encoder frame)."""
        truths, self._boot = self._boot, []
        for seq, x_m, y_m, wrapped_rad in truths:
            ref = ref_at.get(seq)
            if seq >= primed and ref is not None and self._pending:
                self._set((x_m, y_m, wrapped_rad), ref)

    def _set(self, truth: tuple[float, float, float], ref: FramePose) -> None:
        self.origin = life_origin(truth, (ref.x_m, ref.y_m, ref.heading_rad))
        self._pending = False

    def as_dict(self) -> dict[str, float] | None:
        """The origin in the truth's frame (None: the truth's own frame)."""
        if self.origin is None:
            return None
        x_m, y_m, heading_rad = self.origin
        return {"x_m": x_m, "y_m": y_m, "heading_rad": heading_rad}


class TruthParts:
    """SIM_TRUTH's parts (0 X m, 1 Y m, 2 HEADING rad) gathered until three name one frame."""

    def __init__(self) -> None:
        self._parts: dict[int, tuple[int, float]] = {}

    def add(self, part: int, enc_counter: int, value: float) -> tuple[float, float, float] | None:
        """One part of the encoder frame ``enc_counter``; (x m, y m, heading rad) once the three
        parts name one frame."""
        parts = self._parts
        parts[part] = (enc_counter, value)
        if len(parts) < 3 or len({p[0] for p in parts.values()}) != 1:
            return None
        self._parts = {}
        return parts[0][1], parts[1][1], parts[2][1]


def rebased(x_m: float, y_m: float, heading_rad: float,
            origin: tuple[float, float, float]) -> tuple[float, float, float]:
    """``compare.rebase_truth`` of one truth sample, in plain floats (it runs per sample of a
    rebooted life; numpy on one element cost more than the sums): the same operations in the
    same order, so the same bits (tests/test_livetruth_scalar.py)."""
    x0, y0, h0 = origin
    c, s = math.cos(h0), math.sin(h0)
    dx, dy = x_m - x0, y_m - y0
    return c * dx + s * dy, c * dy - s * dx, heading_rad - h0


def carried_to(pose: FramePose, at: FramePose, ref: FramePose) -> FramePose:
    """The on-board ``pose``, judged against the reference ``at``, carried to the reference
    ``ref`` of a later frame (by the reference's own motion since, turned into the on-board
    pose's frame): ``compare.carried`` in plain floats (it runs per truth sample; numpy's
    float64 cos and sin are libm's, its scalar sums IEEE's: the same bits,
    tests/test_livetruth_scalar.py)."""
    turn = pose.heading_rad - at.heading_rad
    c, s = math.cos(turn), math.sin(turn)
    dx, dy = ref.x_m - at.x_m, ref.y_m - at.y_m
    return FramePose(ref.seq, pose.x_m + c * dx - s * dy, pose.y_m + s * dx + c * dy,
                     pose.heading_rad - at.heading_rad + ref.heading_rad)


class TruthJudge:
    """SIM_TRUTH judged live (``PoseTracker.on_truth``), owned by the tracker: the parts heard
    (``TruthParts``), the latest encoder frame of each ENC_COUNTER (a ring: SIM_TRUTH names its
    frame by counter), each truth sample judged against the reference at its frame and against
    the on-board pose carried to it."""

    def __init__(self, tracker: PoseTracker) -> None:
        self._tracker = tracker
        self._parts = TruthParts()
        self._by_counter: list[tuple[int, int, int] | None] = [None] * RING  # seq, left, right

    def frame_heard(self, counter: int, seq: int, left: int, right: int) -> None:
        """An accepted WHEEL_ENCODERS frame: ``seq`` is the latest frame of ENC_COUNTER
        ``counter`` (raw counts ``left``, ``right``)."""
        self._by_counter[counter] = (seq, left, right)

    def judge(
        self, part: int, enc_counter: int, value: float
    ) -> tuple[FramePose, FramePose | None] | None:
        """A SIM_TRUTH part (0 X m, 1 Y m, 2 HEADING rad); three of one encoder frame make a truth
        sample in the life's frame, judged against the reference at that frame and against the
        on-board pose carried to it; returned once complete as (truth, reference at that encoder
        frame or None)."""
        heard = self._parts.add(part, enc_counter, value)
        if heard is None:
            return None
        tracker = self._tracker
        named = recent(self._by_counter[enc_counter], tracker.enc_seq)
        raw = tracker.raw.at.get(named[0]) if named is not None else None
        ref = None if raw is None else tracker.fit.correct(raw)
        x_m, y_m, wrapped_rad = tracker.life_truth.heard(
            None if named is None else int(named[0]), *heard, ref, tracker.awaiting_boot)
        heading = truth_heading(wrapped_rad, ref if ref is not None else tracker.truth)
        truth = tracker.truth = FramePose(ref.seq if ref else -1, x_m, y_m, heading)
        if ref is None:
            return truth, None
        tracker.reference_vs_truth.add(ref, truth)
        if tracker.last_pair is not None:  # the on-board pose carried to this frame
            tracker.vs_truth.add(carried_to(*tracker.last_pair, ref), truth)
        return truth, ref
