"""The one tick loop of every rig: move the clock, run the nodes' tick, deliver what the host heard.

Every rig runs the same 10 ms cycle; only the nodes' work in it differs:

* ``sim.rig.LockstepRig``: the sim node (motor controller, truth, scenario) then the firmware's
  board, in simulated time from 0 s;
* ``host.judge.replay.LockstepReplay``: the firmware's board fed a log's frames, in simulated time
  from the log's first encoder frame;
* ``host.testkit.backends.ExternalBackend``: the HOST's queued frames then the sim node around an
  external firmware, in real time (``sim.realtime.PeriodicLoop`` calls ``tick(k)``; no clock
  to move: ``sim.realtime.paced_sim_tick`` sets the sim's release clock and sends the samples
  of skipped releases first).

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
_SECOND_TICKS = 100  # ticks between progress calls: a simulated second


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
        and once at the end. When every listener is passive (``FrameBatchListener.passive``)
        and the host's handle an instant ``odocan`` one, the host's frames go out once per
        simulated second (``_run_quietly``), else every tick (``step``)."""
        done = 0
        while done < total_ticks:
            ticks = min(_SECOND_TICKS, total_ticks - done)
            if self._all_passive():
                self._run_quietly(ticks)
            else:
                for _ in range(ticks):
                    self.step()
            done += ticks
            if progress is not None and ticks == _SECOND_TICKS:
                progress(done, total_ticks)
        if progress is not None:
            progress(total_ticks, total_ticks)

    def _all_passive(self) -> bool:
        """Every listener takes a run's frames late (``FrameBatchListener.passive``) and the
        host's handle queues them (an instant ``odocan`` one)."""
        bus = self.host_bus
        if type(bus) is not OdocanBus or bus.timing is not None:
            return False
        return all(getattr(type(li), "passive", False) is True for li in self.listeners)

    def _run_quietly(self, ticks: int) -> None:
        """``ticks`` ticks as ``step`` runs them, the host's frames delivered once after them.
        When a tick raises (e.g. Ctrl-C), the frames of the ticks before it are delivered and
        its own stay queued, as ``step`` leaves them."""
        clock, work, start_s = self.clock, self.work, self.start_s
        bus = cast("OdocanBus", self.host_bus)
        queue = bus._queue
        heard = len(queue)  # frames queued by the ticks done
        try:
            for k in range(self.ticks, self.ticks + ticks):
                if clock is not None:
                    clock.advance_to(start_s + k * TICK_S)
                work(k)
                self.ticks = k + 1
                heard = len(queue)
        except BaseException:
            unfinished = [queue.pop() for _ in range(len(queue) - heard)]
            deliver(bus, self.listeners)
            queue.extend(reversed(unfinished))
            raise
        deliver(bus, self.listeners)

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
