"""The live judges' start of a life whose firmware rebooted inside a silence (``silentboot``
live; issue #11: "a FAIL must never blame a correct firmware", "a PASS must never hide a wrong
pose").

The firmware reset while its frames were not heard (a bus-off); the first summary heard after
it tells the reboot, and nothing heard names the frame it primed on (its count pages and
first summaries missed, no power-up pose). The live judges placed the old life's reference
across the silence and judged the new firmware's poses against it until that summary, then,
the summary saying UPTIME 1 s, adopted the next pose as the new life's start: kobuki ``--seed
5 --faults busoff=4:1,reboot=4.3`` with its count pages and 8 first summaries missed, the
correct firmware 4.43 mm off, and the same log 10 mm off the same 4.43 mm (the adopted start
absorbed the offset).

``analyze`` starts such a life after the silence, judged from the power-up pose (0, 0, 0) on
each encoder frame it may have primed on (``silentboot.primed_in_silence``): those after the
old firmware's last frame (and after the encoder frames' own silence, the bus off), up to the
one the first pose after the silence names, the best agreeing with that pose first. Live, that
best one starts the life (``SilentBoot.primed``): the reference at (0, 0, 0) on it, stepped
over the window's frames since; the poses judged against the old life's reference since the
silence are withdrawn (``PoseTracker.withdraw_from``). A pose off by an offset cannot be
absorbed: the start is a power-up, never a fitted pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from odocan.host.judge.powerup import NAMED_SPAN
from odocan.host.judge.reference import integrate, wrap_delta
from odocan.host.judge.silentboot import SILENCE_S

if TYPE_CHECKING:
    from odocan.host.judge.sources import SourceWatch
    from odocan.host.judge.tracking import PoseTracker

FirstPose = tuple[int, float, float, float]  # the named frame's seq, X m, HEADING rad, bus s


class SilentBoot:
    """The firmware's latest silence of ODOM_POSE_X frames (``SILENCE_S`` or more) and the first
    pose heard after it (module docstring)."""

    def __init__(self) -> None:
        self.last_s: float | None = None  # the latest ODOM_POSE_X heard (its CRC right), s
        self.silence: tuple[float, float] | None = None  # its last before, first after (s)
        self.first: FirstPose | None = None  # the first pose after it

    def heard(self, t_s: float, signals: Callable[[], Any],
              rows: Sequence[Sequence[float]]) -> None:
        """An ODOM_POSE_X whose CRC holds heard at bus time ``t_s`` (``signals()``: its
        decoded signals, m and rad; ``rows``: the window's latest encoder frames,
        ``livewindow.ENC_COLUMNS``): after a silence, the frame its ENC_COUNTER names among
        the last ``NAMED_SPAN`` heard, its X and HEADING are kept."""
        last, self.last_s = self.last_s, t_s
        if last is None or t_s - last < SILENCE_S:
            return
        s = signals()
        counter = int(s["ENC_COUNTER"])
        tail = [row for row in list(rows)[-NAMED_SPAN:] if int(row[2]) == counter]
        self.silence = (last, t_s)
        self.first = None if not tail else (int(tail[-1][0]), float(s["X"]),
                                            float(s["HEADING"]), t_s)

    def primed(self, tracker: PoseTracker, uptime_s: int) -> tuple[int, float] | None:
        """The encoder frame (seq) a firmware whose boot summary, heard now, says UPTIME
        ``uptime_s`` primed on after the latest silence, and the bus time its life's frames
        begin at (the first pose after the silence); None when no silence ended after it could
        have booted (``uptime_s`` whole seconds ago), the pose named no frame, the window lost
        them, or the integrator is not known."""
        if self.silence is None or self.first is None or tracker.integrator is None:
            return None
        if self.silence[1] < tracker.now_s - uptime_s - 1.0:
            return None  # a silence of the old life: the boot came after it
        window = tracker.window
        seq, t = window.col("seq").astype(np.int64), window.col("t_s").astype(np.float64)
        mine = np.flatnonzero((t > self.silence[0]) & (seq <= self.first[0]))
        if not len(mine) or int(seq[mine[-1]]) != self.first[0]:
            return None
        went = np.flatnonzero(np.diff(t[mine]) > SILENCE_S)  # the bus was off: after it
        mine = mine[int(went[-1]) + 1:] if len(went) else mine
        left = window.col("left").astype(np.int64)[mine]
        right = window.col("right").astype(np.int64)[mine]
        return (self._best(tracker, seq[mine], (left, right)), self.silence[1])

    def _best(self, tracker: PoseTracker, seqs: npt.NDArray[np.int64],
              counts: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]) -> int:
        """The seq of the frame of ``seqs`` (the candidates, up to the named one; ``counts``:
        their LEFT_COUNT, RIGHT_COUNT) whose reference from (0, 0, 0) to the named frame agrees
        best with the first pose (``silentboot.primed_in_silence``'s order: its X, and its
        heading's reach)."""
        assert self.first is not None and tracker.integrator is not None
        left, right = counts
        bits = tracker.counter_bits
        worst: list[tuple[float, int]] = []
        for k, at in enumerate(seqs.tolist()):
            moved = integrate(wrap_delta(np.diff(left[k:]), bits),
                              wrap_delta(np.diff(right[k:]), bits), tracker.geometry,
                              tracker.integrator)
            x, h = ((float(moved.x_m[-1]), float(moved.heading_rad[-1])) if len(moved.x_m)
                    else (0.0, 0.0))
            turn = math.remainder(h - self.first[2], math.tau)
            worst.append((abs(x - self.first[1]) + abs(turn) * tracker.geometry.wheelbase_m, at))
        return min(worst)[1]


def started_after_silence(tracker: PoseTracker, watch: SourceWatch | None, uptime_s: int
                          ) -> bool:
    """A reboot told by a boot summary of UPTIME ``uptime_s`` (``sources.start_new_life``),
    after a silence it may have rebooted in (``SilentBoot.primed``): above 0 (the next pose
    was to be adopted), the new life starts now at (0, 0, 0) on the frame chosen; 0, with
    ``PoseTracker.power_up`` waiting for its count page and no power-up pose naming the frame,
    that frame is the guess the wait ends on (the summary's, the latest frame heard at it, came
    after the new firmware's first poses: kobuki ``--seed 5 --faults busoff=4:1,reboot=4.3``,
    its count pages missed, 45.67 mm off). Its life's poses are withdrawn from the old life
    from the first pose after the silence (``watch.life_from_s``). Whether it applied."""
    lives = tracker.lives
    if uptime_s == 0 and (lives.boot is None or lives.boot_named):
        return False
    primed = lives.silent.primed(tracker, uptime_s)
    if primed is None:
        return False
    if uptime_s == 0:
        assert lives.boot is not None
        lives.boot, lives.boot_unnamed = (primed[0], lives.boot[1]), primed[0]
    else:
        tracker.new_life()
        lives.finish_boot(primed[0])
    if watch is not None:
        watch.life_from_s = min(watch.life_from_s, primed[1])
    return True
