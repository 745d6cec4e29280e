"""The samples across one of the fleet loop's halts, judged (``host.mqtt.haltstretch``).

At a halt (``sim.board``: a tick ``HALT_AFTER_S`` or more after the tick run before it) the
halted MCU's receive FIFO kept the first ``HW_RX_FIFO_FRAMES`` frames waiting, the encoder
samples of the first skipped releases (fewer of them when other frames waited first), and
overran the rest, the halted tick's own encoder frame among them. Every one of those frames is
on the bus (the motor controller sends the skipped releases' samples late, ``sim.fleet``), so
the halted firmware can have done few things with them, each a ``Path`` fixed by the bus:

- it stepped the frames one by one up to the last it took before the overrun: the frame of the
  tick run before the halt and the 0 to ``HW_RX_FIFO_FRAMES`` after it (``fifo``);
- then, from the first frame after the halted tick (``first``) on, it refused 0 to
  ``RESYNC_FRAMES - 1`` frames as implausible (``skip``: the periods it counts for a step after
  lost time are an estimate, ``EncoderInput._step_periods``) and took the next either as one
  step (MERGED: the counters are absolute), or re-primed on it, the motion between lost
  (PRIMED: a step too long to read, ``firmware.ambiguity``); or it refused ``RESYNC_FRAMES``
  frames that agreed among themselves (RESYNCED: re-primed on ``first``, then one step to the
  third, ``firmware.encoders``);
- and every later frame one by one.

Each path forks the stretch judged before the halt (its reference and the offsets its samples
allow, ``host.mqtt.haltpath``), and every sample from the halt up to the next stretch's base is
compared on the paths (in turn, the likeliest first, until one explains every sample so far): its
ENC_COUNTER must name the frame the path took last by the sample's tick, its pose must leave the
path's offsets non-empty. A sample no path explains is wrong (a firmware that added 3 LSB of X at
the first release after a halt PASSed before: the stretch re-started from whatever pose it reported
3 releases on). A crossing is lost, never wrong, when a frame it needs is not in the tracker's
window (missing, or beyond the per-period bound): that halt's re-start is then not judged, as
before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from odocan.firmware.encoders import RESYNC_FRAMES
from odocan.host.judge.livepose import Sample
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.haltpath import Frame, Stretch, frames_from, narrow_offsets, step_frames
from odocan.sim.board import HW_RX_FIFO_FRAMES, TICK_S, TX_LATENCY_S

MERGED, PRIMED, RESYNCED = "merged", "primed", "resynced"
ENC = "enc_counter"  # a path's death by the frame a sample names, not its pose
_HALF_TICK_S = 0.5 * TICK_S
_WAYS = (*((MERGED, skip) for skip in range(RESYNC_FRAMES)), (RESYNCED, 0),
         *((PRIMED, skip) for skip in range(RESYNC_FRAMES)))  # (mode, frames refused first):
# every path from one FIFO frame, the likeliest first


@dataclass
class Path:
    """One way the halted firmware took the frames (module docstring): the last frame (seq)
    it took before the overrun, what it did with the first after, how many frames it refused
    before, its fork of the stretch, whether it crossed yet, why it died (field, LSB beyond
    the rounding; None: alive)."""

    fifo: int
    mode: str
    skip: int
    stretch: Stretch
    crossed: bool = False
    died: tuple[str, float] | None = None
    done: int = 0  # the crossing's samples compared on it (from 1 on: its own stretch)

    def takes(self, seq: int, first: int | None) -> bool:
        """Whether this path's firmware took frame ``seq`` (``first``: the first after the
        halted tick, None while not heard)."""
        if seq <= self.fifo:
            return True
        if first is None:
            return False
        return seq >= first + (RESYNC_FRAMES - 1 if self.mode == RESYNCED else self.skip)


class Crossing:
    """The samples from one halt on, judged on every ``Path`` from the ``stretch`` before it
    (module docstring). ``halt_s``, ``last_run_s``: the bus times (s) of the halted tick and of
    the tick run before it; ``bound``: the robot's most counts a period per wheel."""

    def __init__(self, stretch: Stretch, tracker: PoseTracker, bound: tuple[int, int],
                 halt_s: float, last_run_s: float) -> None:
        self.halt_s = halt_s
        self._last_run_s = last_run_s
        self._stretch = stretch
        self._tracker, self._bound = tracker, bound
        self._paths: list[Path] = []  # the likeliest first (``_fork``)
        self._alive = 0  # the first path no sample so far refuted (all before it were)
        self._samples: list[Sample] = []
        self.wrong: tuple[str, float] | None = None  # no path explains a sample: field, LSB

    def judge(self, sample: Sample) -> bool:
        """Compare ``sample`` and those before on the paths in turn until one explains them
        all (``wrong`` when none does): the verdict of every path at once, for the CPU of
        about one (the likeliest path, the FIFO full and the first frame merged, is nearly
        always right). False when the crossing is lost (a frame it needs not in the window:
        not judged)."""
        rows = frames_from(self._tracker, self._stretch.seq + 1)
        if not self._paths and not self._fork(rows):
            return False
        self._samples.append(sample)
        first = self._first(rows)
        paths = self._paths
        while self._alive < len(paths):
            path = paths[self._alive]
            if not self._settle(path, rows, first):
                return False
            if path.died is None:
                return True
            self._alive += 1
        self.wrong = min((path.died for path in paths if path.died is not None),
                         key=lambda died: died[1])
        return True

    def survivors(self) -> list[Stretch] | None:
        """The stretches of every path that explains every sample so far, each stepped to the
        frame the latest sample names (all paths judged now, not only up to the first that
        explains them: the offsets carried on, ``host.mqtt.haltcarry``, must hold whichever
        the firmware took); None when the crossing is wrong, not started or lost."""
        if self.wrong is not None or not self._paths:
            return None
        rows = frames_from(self._tracker, self._stretch.seq + 1)
        first = self._first(rows)
        alive = []
        for path in self._paths[self._alive:]:
            if not self._settle(path, rows, first):
                return None
            if path.died is None:
                alive.append(path.stretch)
        return alive

    def _first(self, rows: list[Frame]) -> int | None:
        """The index in ``rows`` of the first frame after the halted tick (None: not heard)."""
        return next((i for i, row in enumerate(rows) if row[2] >= self.halt_s + _HALF_TICK_S),
                    None)

    def _settle(self, path: Path, rows: list[Frame], first: int | None) -> bool:
        """Compare the samples ``path`` has not seen on it until one refutes it; False when
        a frame it needs is missing (lost). A refuted path stays refuted: a later sample that
        fits it does not revive it (``survivors`` may settle the same paths again)."""
        if path.died is not None:
            return True
        if not path.done:  # its stretch was its FIFO frame's, shared: its own from now
            path.stretch = path.stretch.fork()
        for earlier in self._samples[path.done:]:
            path.done += 1
            tick_s = earlier.t_s - TX_LATENCY_S + 1e-6  # the tick that made the sample
            if not self._follow(path, rows, first, tick_s, earlier):
                return False
            if path.died is not None:
                break
        return True

    def _fork(self, rows: list[Frame]) -> bool:
        """The paths: the stretch stepped to the frame of the tick run before the halt, then
        to each of the FIFO's frames, each with every mode."""
        before = [row[0] for row in rows if row[2] <= self._last_run_s + _HALF_TICK_S]
        ran = before[-1] if before else self._stretch.seq
        stretch = self._stretch.fork()
        if not step_frames(stretch, rows, ran, self._bound, self._tracker.counter_bits):
            return False
        at = {row[0]: row[2] for row in rows}  # seq: bus time (s)
        for taken in range(HW_RX_FIFO_FRAMES + 1):
            fifo = ran + taken
            if taken and (at.get(fifo, math.inf) >= self.halt_s or not step_frames(
                    stretch, rows, fifo, self._bound, self._tracker.counter_bits)):
                break
            # the FIFO's most frames first (nothing else waited), each way in ``_WAYS``' order
            base = stretch.fork()  # forked again by each path it is judged on
            self._paths[:0] = [Path(fifo, mode, skip, base) for mode, skip in _WAYS]
        return True

    def _follow(self, path: Path, rows: list[Frame], first: int | None, tick_s: float,
                sample: Sample) -> bool:
        """Step ``path`` to the frame it took last by ``tick_s`` and compare ``sample`` there
        (its death noted); False when a frame it needs is missing."""
        first_seq = None if first is None else rows[first][0]
        target = next((row for row in reversed(rows)  # the latest first: found in 1-3
                       if row[2] <= tick_s and path.takes(row[0], first_seq)), None)
        if target is None:  # the frames before the window's: the path still at its FIFO's last
            return path.stretch.seq == path.fifo and self._compare(
                path, path.stretch.counter, sample)
        if target[0] > path.fifo and not path.crossed:
            assert first is not None
            if not self._cross(path, rows, first):
                return False
        if target[0] < path.stretch.seq or not step_frames(
                path.stretch, rows, target[0], self._bound, self._tracker.counter_bits):
            return False
        return self._compare(path, target[1], sample)

    def _cross(self, path: Path, rows: list[Frame], first: int) -> bool:
        """The path takes the first frame after the halt as its mode says."""
        stretch, ref = path.stretch, path.stretch.ref
        at = first + path.skip
        if at >= len(rows) or rows[at][0] != rows[first][0] + path.skip:
            return False
        seq, counter, _, left, right = rows[at]
        if path.mode == MERGED:
            ref.step_counts(left, right)
        else:
            ref._prev = (left, right)  # re-primed: the step to it never integrated
        if path.mode == RESYNCED:
            third = first + RESYNC_FRAMES - 1
            if third >= len(rows) or rows[third][0] != seq + RESYNC_FRAMES - 1:
                return False
            seq, counter, _, left, right = rows[third]
            ref.step_counts(left, right)
        stretch.seq, stretch.counter, stretch.steps = seq, counter, stretch.steps + 1
        path.crossed = True
        return True

    @staticmethod
    def _compare(path: Path, counter: int, sample: Sample) -> bool:
        """The sample on ``path`` at its last frame (its COUNTER ``counter``): its ENC_COUNTER
        must name it, its pose keep the offsets."""
        if counter != sample.enc_counter:
            path.died = (ENC, math.inf)
        else:
            path.died = narrow_offsets(path.stretch, sample.pose)
        return True
