"""Two sources on one ID told from the firmware's ODOM_POSE_X frames (issue #11: "two sources on
one ID are reported"): the rule, coded once (``TwinWatch``, one frame at a time), for the live
judges (monitor, bridge, fleet: ``hear_pose_frame``) and the log's (``host.judge.posestreams``
feeds it the CRC-right frames of a whole or streamed log), so all tell the same frames.

A *pair* is a CRC-right ODOM_POSE_X frame whose E2E COUNTER was heard, with other bytes, less
than ``PAIR_WINDOW_S`` of bus time before it (either way round in the log's order). From the
DBC (``busfacts``): the frame is sent every ``POSE_PERIOD_S`` (20 ms) and its 4-bit COUNTER laps
in ``LAP_S`` = 16 periods (320 ms); ``PAIR_WINDOW_S`` is 5/8 of a lap (200 ms, 10 periods).

* **Two senders at one rate always pair.** Each sends COUNTER c once a lap; if B's c comes δ
  after A's, the next A c comes ``LAP_S`` - δ after B's, and min(δ, ``LAP_S`` - δ) <= half a lap
  (160 ms) < ``PAIR_WINDOW_S``: every COUNTER value makes at least one pair a lap, at least one
  pair in every period while both send (40 ms, two periods, of margin for their clocks). Only
  frames of equal bytes do not pair: two robots standing at one pose send the same pose, which
  is then right for both.
* **One sender pairs only after a disruption.** It sends COUNTER c again one lap later; its two
  frames come within ``PAIR_WINDOW_S`` only when one of them was held back at least
  ``LAP_S`` - ``PAIR_WINDOW_S`` (120 ms, 6 periods) or its COUNTER restarted. Reordering by
  ``--faults delay=P:MS`` with MS < 120 (the tests use up to 55, and 100 for every frame alike)
  never pairs; a duplicate or a resend of the same bits is equal bytes and never pairs; a bus-off
  releasing its held frames at recovery, or a reboot restarting the COUNTER at 0, pairs only
  frames within ``PAIR_WINDOW_S`` after that instant: at most 11 periods for each (the sim gives
  each at most once a run); a delay of MS >= 120 pairs at most the frames delayed next to ones
  not delayed, P (1 - P) <= 1/4 of them; a babbler's random frames on the ID pass the CRC 1 in
  256 (at most ~16 a second on a full 500 kbit/s bus).

So two sources are told when the pairs fill ``PAIRED_PERIODS`` (32) of the ``SPAN_PERIODS``
(48: three laps, 0.96 s) pose periods of bus time up to the latest pair: two senders fill
nearly all 48 (up to a third of them lost), one sender at most 22 (a reboot and a bus-off within
one span) or about 12 (a delay of a lap, a babbler). They are told from the earlier frame of the
span's first pair (either may be the second sender's: the frames from there are not judged),
unless the UPTIME watch (``host.judge.sources``) tells the same second firmware, exactly, within
its 1 s LSB (``pose_told_first``). The span's pairs must also be of ``PAIRED_COUNTERS`` (12)
COUNTER values: two senders, each counting, pair every value a lap; one sender whose COUNTER
does not advance (a firmware bug: every frame one value, other bytes) pairs on that one value in
every period, and is an E2E fault of its own (``host.judge.verdictfacts``: most frames
REPEATED), not a second robot.
ODOM_POSE_Y is not watched (X and HEADING are enough to tell two robots apart). Per frame in
plain Python: a deque per COUNTER value, a few comparisons, for the bridge's fleets.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import (
    MS_PER_S,
    POSE_COUNTER_LAP,
    POSE_MESSAGE,
    POSE_PERIOD_S,
    UPTIME_LSB_MS,
)

if TYPE_CHECKING:
    from odocan.host.judge.sources import SourceWatch
    from odocan.host.judge.tracking import PoseTracker

WATCHED: Final = (POSE_MESSAGE,)  # ODOM_POSE_X: the pose message the judges watch
COUNTER_MASK: Final = POSE_COUNTER_LAP - 1  # the Profile 2 COUNTER (byte 1, low nibble)
LAP_S: Final = POSE_COUNTER_LAP * POSE_PERIOD_S  # 0.32 s: one sender's COUNTER comes back
PAIR_WINDOW_S: Final = LAP_S * 5 / 8  # 0.2 s: > half a lap (two senders), < a lap - 120 ms
SPAN_PERIODS: Final = 3 * POSE_COUNTER_LAP  # 48 pose periods (three laps) looked over
PAIRED_PERIODS: Final = 2 * POSE_COUNTER_LAP  # 32 of them with a pair: two sources
PAIRED_COUNTERS: Final = POSE_COUNTER_LAP * 3 // 4  # 12 COUNTER values paired among them
CONFLICT_HOLD_S: Final = 2.0  # CONFLICT shown this long after the last telling (sources')
TOLD_APART_S: Final = UPTIME_LSB_MS / MS_PER_S  # 1 s: UPTIME's LSB (``pose_told_first``)


def pose_told_first(pose_s: float, uptime_s: float | None) -> bool:
    """Whether the pose frames' telling (from ``pose_s``) stands before the UPTIME watch's (from
    ``uptime_s``, None: none): UPTIME's is exact (the second firmware's first frames) where the
    pose frames' may be a pair window early (its pair's earlier frame may be the first
    firmware's), so within UPTIME's LSB of each other they tell one second firmware, UPTIME's."""
    return uptime_s is None or pose_s < uptime_s - TOLD_APART_S


def detail_text(message: str, t_s: float, paired: int | None = None,
                heard: int | None = None) -> str:
    """The verdict's reason: two streams of ``message`` from bus time ``t_s`` (``paired`` of
    ``heard`` CRC-right frames repeating a COUNTER with other bytes, when counted)."""
    counts = "" if paired is None else (
        f" ({paired} of its {heard} CRC-right frames repeat a COUNTER heard within "
        f"{PAIR_WINDOW_S * 1e3:.0f} ms with other bytes)")
    return (f"two sources on one ID: two {message} streams interleave from t={t_s:.3f} s"
            f"{counts}: whose pose each frame is cannot be told, the pose cannot be judged")


class TwinWatch:
    """The rule over one message's CRC-right frames, in the log's (bus) order (module
    docstring): ``hear`` each; ``told`` once two sources were told."""

    def __init__(self) -> None:
        self._recent: list[deque[tuple[float, bytes, int]]] = [
            deque() for _ in range(POSE_COUNTER_LAP)]  # by COUNTER: (bus time, bytes, position)
        self._periods: deque[tuple[int, float, int, int]] = deque()  # paired periods in the
        # span: (period, the pair's earlier frame's bus time, its position, the COUNTER)
        self.heard = 0  # CRC-right frames heard
        self.paired = 0  # of them, pairs
        self.told: tuple[float, int] | None = None  # (bus time, position) two sources from
        self.last_paired = False  # whether the latest frame heard made a pair

    def hear(self, data: bytes, t_s: float, position: int = 0) -> tuple[float, int] | None:
        """A CRC-right frame (its 8 bytes) at bus time ``t_s`` (``position``: in the log):
        ``told`` when this frame tells two sources for the first time, else None."""
        self.heard += 1
        recent = self._recent[data[1] & COUNTER_MASK]
        while recent and t_s - recent[0][0] >= PAIR_WINDOW_S:
            recent.popleft()
        other: tuple[float, int] | None = None  # the first kept that pairs (no generator)
        for t, d, p in recent:
            if d != data and abs(t_s - t) < PAIR_WINDOW_S:
                other = (t, p)
                break
        recent.append((t_s, data, position))
        self.last_paired = other is not None
        if other is None:
            return None
        return self._paired(t_s, min(other, (t_s, position)), data[1] & COUNTER_MASK)

    def hear_block(self, data: npt.NDArray[np.uint8], t_s: npt.NDArray[np.float64],
                   positions: npt.NDArray[np.int64]) -> None:
        """``hear`` each row of ``data`` (CRC-right frames, 8 bytes each, in the log's order:
        bus times ``t_s`` never going back) at once where none can pair: no frame comes within
        ``PAIR_WINDOW_S`` after one of its COUNTER (this block's or one kept from before), the
        one sender's usual log; then each COUNTER keeps its latest frame, as ``hear`` leaves it.
        Else frame by frame."""
        counters = data[:, 1] & COUNTER_MASK
        order = np.argsort(counters, kind="stable")  # by COUNTER, the log's order within
        same = counters[order][1:] == counters[order][:-1]
        close = same & (np.diff(t_s[order]) < PAIR_WINDOW_S)
        firsts = order[np.r_[True, ~same]] if len(order) else order
        carried = any(self._recent[c] and t - self._recent[c][-1][0] < PAIR_WINDOW_S
                      for c, t in zip(counters[firsts].tolist(), t_s[firsts].tolist(),
                                      strict=True))
        if close.any() or carried:
            raw = data.tobytes()
            for i, (t, p) in enumerate(zip(t_s.tolist(), positions.tolist(), strict=True)):
                self.hear(raw[i * 8:(i + 1) * 8], t, p)
            return
        self.heard += len(data)
        self.last_paired = False
        lasts = order[np.r_[~same, True]] if len(order) else order
        for c, i in zip(counters[lasts].tolist(), lasts.tolist(), strict=True):
            self._recent[c] = deque([(float(t_s[i]), data[i].tobytes(), int(positions[i]))])

    def _paired(self, t_s: float, earlier: tuple[float, int], counter: int
                ) -> tuple[float, int] | None:
        """A pair of ``counter`` heard at ``t_s``, its earlier frame ``earlier``: ``told`` once
        the span fills with pairs of enough COUNTER values."""
        self.paired += 1
        period = int(t_s // POSE_PERIOD_S)
        periods = self._periods
        if not periods or periods[-1][0] != period:
            periods.append((period, *earlier, counter))
        while periods and periods[0][0] <= period - SPAN_PERIODS:
            periods.popleft()
        if self.told is not None or len(periods) < PAIRED_PERIODS:
            return None
        if len({entry[3] for entry in periods}) < PAIRED_COUNTERS:
            return None  # one COUNTER value paired over and over: a COUNTER that does not advance
        self.told = (periods[0][1], periods[0][2])
        return self.told


class LiveStreams:
    """The watches of the live judges, by message (``hear_pose_frame``)."""

    def __init__(self) -> None:
        self._watches: dict[str, TwinWatch] = {}

    def hear(self, message: str, data: bytes, t_s: float) -> float | None:
        """A CRC-right frame of ``message`` at bus time ``t_s``: once two sources were told,
        the bus time they are told from while their pairs go on (this frame one); else None."""
        if message not in WATCHED or len(data) < 2:
            return None
        watch = self._watches.get(message)
        if watch is None:  # (not setdefault: a TwinWatch is 16 deques, made for every frame)
            watch = self._watches[message] = TwinWatch()
        watch.hear(bytes(data), t_s)
        return watch.told[0] if watch.told is not None and watch.last_paired else None

    def detail(self, message: str, t_s: float) -> str:
        """The reason, with ``message``'s counts."""
        watch = self._watches.get(message)
        return detail_text(message, t_s, *(() if watch is None else (watch.paired, watch.heard)))


def hear_pose_frame(watch: SourceWatch, message: str, data: bytes, t_s: float,
                    tracker: PoseTracker | None = None, events: Any = None) -> None:
    """A CRC-right pose frame for ``watch``'s streams; when it tells two sources: the watch's
    conflict (from the pair the span began with, unless UPTIME tells it: ``pose_told_first``),
    CONFLICT held while the pairs go on, no pose judged from there
    (``tracker.wrongs.unjudgeable_from``), one ``two sources`` event in ``events`` while it
    lasts (the monitor's; default the tracker's)."""
    from_s = watch.streams.hear(message, data, t_s)
    if from_s is None:
        return
    if watch.conflict_from_s is None or (not watch.conflict_detail  # UPTIME's, unless before
                                         and pose_told_first(from_s, watch.conflict_from_s)):
        watch.conflict_from_s = from_s
        watch.conflict_detail = watch.streams.detail(message, from_s)
    watch.conflict_until_s = t_s + CONFLICT_HOLD_S
    if tracker is not None:
        tracker.wrongs.unjudgeable_from(watch.conflict_from_s)
        events = events if events is not None else tracker.restarts.events
    if events is None:
        return
    last = events[-1] if events else None
    if last and last["kind"] == "two sources" and t_s - last["t_s"] < CONFLICT_HOLD_S:
        last["t_s"] = t_s  # one event while the conflict lasts
        return
    events.append({"t_s": t_s, "kind": "two sources",
                   "detail": watch.conflict_detail or detail_text(message, t_s)})
