"""The one tick loop of every rig: move the clock, run the nodes' tick, deliver what the host heard.

Every rig runs the same 10 ms cycle; only the nodes' work in it differs:

* ``sim.rig.LockstepRig``: the sim node (motor controller, truth, scenario) then the firmware's
  board, in simulated time from 0 s;
* ``host.judge.replay.LockstepReplay``: the firmware's board fed a log's frames, in simulated time
  from the log's first encoder frame;
* ``host.testkit.backends.ExternalBackend``: the HOST's queued frames then the sim node around an
  external firmware, in real time (``sim.realtime.PeriodicLoop`` calls ``tick(k)``; no clock
  to move).

Tick k (``TickLoop.tick``):

1. a lockstep clock moves to ``start_s + k * TICK_S`` (simulated time; none in real time);
2. ``work(k)``: the nodes' tick, in the order their rig documents;
3. every frame waiting on the host's bus handle goes to each listener, in bus order (``deliver``).

The loop adds nothing to the bytes on the bus: a rig built on it sends the same frames, stamped
the same, as its own loop did.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import cast

import can

from odocan.sim.board import TICK_S
from odocan.sim.clock import LockstepClock
from odocan.sim.framebatch import FrameBatchListener
from odocan.sim.transport import OdocanBus

Work = Callable[[int], None]  # the nodes' work in tick k


def deliver(bus: can.BusABC, listeners: Sequence[can.Listener]) -> int:
    """Hand every frame waiting on ``bus`` to each of ``listeners`` (in bus order, each frame to
    every listener before the next frame is read); returns how many frames were delivered.

    On an instant ``odocan`` handle the frames are drained a batch at a time
    (``OdocanBus.drain``, again until none is left: a frame a listener sends meanwhile comes
    after, as with ``recv``): when every listener is a ``FrameBatchListener`` they get the list
    (no ``Message`` built), else each frame goes out as the ``Message`` ``recv`` would give."""
    if type(bus) is OdocanBus and bus.timing is None:
        return _deliver_drained(bus, listeners)
    recv = bus.recv
    count = 0
    msg = recv(0)
    while msg is not None:
        for listener in listeners:
            listener.on_message_received(msg)
        count += 1
        msg = recv(0)
    return count


def _deliver_drained(bus: OdocanBus, listeners: Sequence[can.Listener]) -> int:
    """``deliver`` on an instant ``odocan`` handle (see there)."""
    count = 0
    frames = bus.drain()
    while frames:
        count += len(frames)
        # By class (not isinstance: can.Listener's ABCMeta check costs more than the rest).
        batch = [li for li in listeners if FrameBatchListener in type(li).__mro__]
        if len(batch) == len(listeners):
            for batch_listener in cast("list[FrameBatchListener]", batch):
                batch_listener.on_frames(frames)
        else:
            as_message = bus.as_message
            for frame in frames:
                message = as_message(frame)
                for listener in listeners:
                    listener.on_message_received(message)
        frames = bus.drain()
    return count


class TickLoop:
    """Ticks of ``TICK_S`` (10 ms): the clock, ``work(k)``, then ``deliver`` (module docstring).

    ``ticks`` counts the ticks run (the next one is ``ticks``); a caller may set it, e.g. a
    fleet whose robots start at staggered ticks. ``listeners`` is the list given, not a copy:
    a listener appended to it later hears the frames from then on.
    """

    def __init__(
        self,
        work: Work,
        host_bus: can.BusABC,
        listeners: list[can.Listener],
        clock: LockstepClock | None = None,
        *,
        start_s: float = 0.0,
    ) -> None:
        self.work = work
        self.host_bus = host_bus
        self.listeners = listeners
        self.clock = clock
        self.start_s = start_s  # the simulated time of tick 0 (s)
        self.ticks = 0

    def tick(self, k: int) -> None:
        """Tick ``k``: the lockstep clock to its start, the nodes' work, the host's frames out
        to the listeners (``ticks`` is left alone: ``step`` counts)."""
        if self.clock is not None:
            self.clock.advance_to(self.start_s + k * TICK_S)
        self.work(k)
        deliver(self.host_bus, self.listeners)

    def step(self) -> None:
        """The next tick (``ticks``), then count it."""
        k = self.ticks
        self.tick(k)
        self.ticks = k + 1

    def run(self, total_ticks: int, progress: Callable[[int, int], None] | None = None) -> None:
        """``total_ticks`` ticks; ``progress(done, total)`` every 100 ticks (a simulated second)
        and once at the end."""
        step = self.step
        for k in range(total_ticks):
            step()
            if progress is not None and k % 100 == 99:
                progress(k + 1, total_ticks)
        if progress is not None:
            progress(total_ticks, total_ticks)

    def run_to(self, stop_tick: int) -> None:
        """Tick until ``ticks`` is ``stop_tick`` (none when it already is, or is past it)."""
        while self.ticks < stop_tick:
            self.step()

    def run_until(self, done: Callable[[], bool], timeout_ticks: int) -> bool:
        """Step until ``done()`` (checked after every tick) or ``timeout_ticks`` ticks have run;
        True when ``done()`` was reached."""
        end = self.ticks + timeout_ticks
        while self.ticks < end:
            self.step()
            if done():
                return True
        return False
