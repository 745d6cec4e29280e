"""Each robot's frames held a little before its live judge takes them (issue #13).

A fleet worker's bridge handed every robot's judge its frames every tick: 50 robots' judge
state touched between two ticks of one robot no longer fits the core's cache, and the same
bytecodes cost ~40 % more than at 10 robots (``bench/bridge_frames.py --group``). Held, a
robot's frames go to its judge in one go, its state hot across a publication period:
``bench/bridge_frames.py --batch-ticks 10`` 97 -> 67 us per robot-tick (docs/benchmarks.md).

What the judge publishes is what it makes of its frames, in their order: holding changes when,
never what. A robot's frames are judged (``FrameHold.take``) as soon as one of them may publish
its next pose (``RobotTelemetry.pose_waits`` false: the pose goes out in the very batch it went
out in before), while its command pacer waits for an ODOM_ACK, or once they span ``hold_s`` of
bus time (what else they publish, an event, a truth, at most that late); the bridge judges a
robot's held frames (``Bridge._flush``) before anything reads or changes its telemetry
outside them: a command, its ``status``, its ``rates``, the pacer's timeouts, the watch's end.
"""

from __future__ import annotations

from collections.abc import Callable

from odocan.sim.framebatch import Received

HOLD_S = 0.1  # a fleet's: one publication period at the default 10 Hz
Held = list[tuple[int, Received]]


def _t_s(frame: Received) -> float:
    return frame[0] if type(frame) is tuple else float(frame.timestamp)  # type: ignore[union-attr]


class FrameHold:
    """The frames each robot's judge has not taken yet, in bus order."""

    def __init__(self, robots: int, hold_s: float) -> None:
        self.hold_s = hold_s
        self.held: list[Held] = [[] for _ in range(robots)]

    def take(self, batch: Held, waits: Callable[[int, float], bool]) -> Held:
        """Hold ``batch``'s frames; the held frames of each robot it touched that may not wait
        any longer (``waits(robot, bus time of its latest frame)`` false, or ``hold_s`` held),
        robot by robot, each robot's in bus order."""
        held: list[Held] = self.held
        touched: dict[int, None] = {}
        for item in batch:
            held[item[0]].append(item)
            touched[item[0]] = None
        out: Held = []
        hold_s = self.hold_s
        for index in touched:
            frames = held[index]
            last_s = _t_s(frames[-1][1])
            if last_s - _t_s(frames[0][1]) >= hold_s or not waits(index, last_s):
                out += frames
                held[index] = []
        return out

    def take_robot(self, index: int) -> Held:
        """Robot ``index``'s held frames, in bus order (none held any more)."""
        frames, self.held[index] = self.held[index], []
        return frames
