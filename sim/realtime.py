"""Real-time nodes: a periodic loop with deadline accounting, and the sim node it paces.

Each real-time node is its own process on any python-can bus (``odocan sim``, ``odocan firmware``).
``PeriodicLoop`` calls ``tick(k)`` at the release times ``start + k * period`` of a
``RealTimeClock``, sleeping in between, and counts:

* a **late tick**: one that starts more than ``late_after_s`` after its release (default: half a
  period). ``deadline_miss_ratio`` = late ticks / ticks run;
* a **skipped release**: when a tick starts a whole period or more after its release, the releases
  already passed are dropped (a timer interrupt that came while the CPU was busy is lost, not
  queued): the loop never runs a burst of ticks to catch up, so frames keep their spacing.

``stop_on_signals`` turns SIGINT (Ctrl-C) and SIGTERM into a request to stop after the current
tick, so a node closes its bus and exits cleanly; a second signal interrupts at once. It takes
anything ``Stoppable``: a ``PeriodicLoop``, or a bare ``StopRequest`` that a lockstep loop polls
between its ticks (``odocan run``), so a signal never lands in the middle of a log write.

``sim.motor_controller.SimNode``, the sim side of every rig, runs here on one bus handle:
the motor controller, the SIM truth and the scenario driver, one tick at a time.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import FrameType
from typing import Any, Protocol

from odocan.sim import interrupts
from odocan.sim.board import TICK_S
from odocan.sim.clock import RealTimeClock
from odocan.sim.contract import database
from odocan.sim.exceptions import Terminated

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Stoppable(Protocol):
    """What ``stop_on_signals`` asks to stop."""

    def request_stop(self, signum: int | None = None) -> None:
        """Stop at the next safe point (called from a signal handler, ``signum`` its signal)."""

    @property
    def stop_requested(self) -> bool:
        """True once a stop was requested."""


class StopRequest:
    """A stop flag for loops that poll it between steps (``Stoppable``); ``signum``: the
    signal that asked first (None: none, or asked by code)."""

    def __init__(self) -> None:
        self._requested = False
        self.signum: int | None = None

    def request_stop(self, signum: int | None = None) -> None:
        """Ask the loop to stop (safe from a signal handler); the first signal is kept."""
        self._requested = True
        if self.signum is None:
            self.signum = signum

    @property
    def stop_requested(self) -> bool:
        """True once a stop was requested."""
        return self._requested


@dataclass
class DeadlineStats:
    """Deadline accounting of a periodic loop (times in seconds)."""

    period_s: float
    late_after_s: float
    ticks: int = 0
    late_ticks: int = 0
    skipped_releases: int = 0
    max_lateness_s: float = 0.0

    def record(self, lateness_s: float) -> None:
        """Account one tick that started ``lateness_s`` after its release."""
        self.ticks += 1
        if lateness_s > self.late_after_s:
            self.late_ticks += 1
        self.max_lateness_s = max(self.max_lateness_s, lateness_s)

    @property
    def deadline_miss_ratio(self) -> float:
        """Late ticks / ticks run (0.0 before the first tick)."""
        return self.late_ticks / self.ticks if self.ticks else 0.0

    def summary(self) -> str:
        """One line: ticks, late ticks, the miss ratio, worst lateness (ms), skipped releases."""
        return (
            f"{self.ticks} ticks, {self.late_ticks} late "
            f"(deadline_miss_ratio {self.deadline_miss_ratio:.4f}, "
            f"worst {self.max_lateness_s * 1e3:.1f} ms), "
            f"{self.skipped_releases} releases skipped"
        )


class PeriodicLoop:
    """Runs ``tick(k)`` every ``period_s`` of a real-time clock until stopped or a duration ends."""

    def __init__(
        self,
        period_s: float = TICK_S,
        clock: RealTimeClock | None = None,
        *,
        late_after_s: float | None = None,
    ) -> None:
        """``late_after_s``: a tick starting later than this after its release is late
        (default: half a period)."""
        if period_s <= 0:
            raise ValueError(f"period must be positive, got {period_s} s")
        self.period_s = period_s
        self.clock = clock or RealTimeClock()
        self.stats = DeadlineStats(period_s, period_s / 2 if late_after_s is None else late_after_s)
        self._stop_requested = False
        self.signum: int | None = None  # the signal that asked it to stop first, if one did

    def request_stop(self, signum: int | None = None) -> None:
        """Stop after the tick under way (safe from a signal handler)."""
        self._stop_requested = True
        if self.signum is None:
            self.signum = signum

    @property
    def stop_requested(self) -> bool:
        """True once a stop was requested."""
        return self._stop_requested

    def run(self, tick: Callable[[int], None], duration_s: float | None = None) -> DeadlineStats:
        """Call ``tick(k)`` at each release ``k`` (k = 0, 1, ...; skipped releases skip k).

        Release 0 is the clock's time when ``run`` is called; releases run until ``duration_s``
        after it (None: until stopped).
        """
        period = self.period_s
        clock = self.clock
        stats = self.stats
        start = clock.now_s()
        k = 0
        while not self._stop_requested:
            if duration_s is not None and k * period >= duration_s - 1e-9:
                break
            release = start + k * period
            lateness = clock.sleep_until(release)
            if self._stop_requested:
                break
            lateness = max(lateness, clock.now_s() - release)
            if lateness >= period:
                missed = int(lateness / period)
                stats.skipped_releases += missed
                k += missed
            stats.record(lateness)
            tick(k)
            k += 1
        return stats


class ReleaseClock:
    """The release time of the tick under way (``Clock``): a real-time node that reads it samples
    its world at the instant its timer fired, as a hardware timer does, not when the OS let the
    process run. ``release_s`` is set by ``paced_sim_tick`` before each tick."""

    def __init__(self) -> None:
        self.release_s = 0.0

    def now_s(self) -> float:
        """The current tick's release time (s since the loop's first release)."""
        return self.release_s

    def advance_to(self, t_s: float) -> None:
        """The release under way is at ``t_s`` (``SettableClock``)."""
        self.release_s = t_s


class SettableClock(Protocol):
    """A clock a loop sets to each release: a ``ReleaseClock`` or a rig's ``LockstepClock``."""

    def advance_to(self, t_s: float) -> None:
        """Now is ``t_s``."""


class SkippedSampler(Protocol):
    """What ``send_skipped_samples`` drives: the sim node (``sim.motor_controller.SimNode``)."""

    def sample_skipped(self) -> None:
        """The encoder sample of a skipped release, at the clock's time, sent late."""


class SampledNode(SkippedSampler, Protocol):
    """What ``paced_sim_tick`` drives: the sim node (``sim.motor_controller.SimNode``)."""

    def tick(self, k: int) -> None:
        """Tick ``k``."""


def send_skipped_samples(
    node: SkippedSampler, clock: SettableClock, releases: range, period_s: float = TICK_S
) -> None:
    """The encoder samples of the skipped ``releases`` (k = ``releases``, at ``k * period_s`` on
    ``clock``), each taken at its own release and sent now, back to back, in order: the rule of
    ``paced_sim_tick``, shared by every real-time loop that drives a sim node (``odocan sim``,
    the fleet's robots: ``sim.fleet.Fleet.step``). The caller then runs the tick it got to,
    which sets the clock to its own release."""
    for j in releases:
        clock.advance_to(j * period_s)
        node.sample_skipped()


def paced_sim_tick(
    node: SampledNode, clock: ReleaseClock, period_s: float = TICK_S
) -> Callable[[int], None]:
    """``PeriodicLoop.run``'s tick for the real-time sim node built on ``clock``.

    The motor controller samples its encoders every period in hardware, whatever the process
    does: a late tick samples at its release time (not up to a period of motion later), and the
    samples of releases the loop skipped are sent first, each taken at its own release, back to
    back as a CAN controller sends a queue that waited (their COUNTERs +1 each, as the DBC
    says: no jump, no step beyond a period's motion). Sampling when the process got the CPU put
    up to several periods of motion under one COUNTER step, which the firmware rightly refused
    as faster than the robot can go (kobuki on a loaded machine: hundreds of frames refused,
    DEGRADED COUNTER_RESET, the pose 0.3 m off, every judge FAILing a correct firmware). Only
    the encoder samples are made up: the skipped ticks' commands and truth are not sent."""
    last = [-1]

    def tick(k: int) -> None:
        send_skipped_samples(node, clock, range(last[0] + 1, k), period_s)
        last[0] = k
        clock.release_s = k * period_s
        node.tick(k)

    return tick


@contextmanager
def stop_on_signals(loop: Stoppable) -> Iterator[None]:
    """While inside: SIGINT and SIGTERM ask ``loop`` to stop; a second one raises
    ``KeyboardInterrupt`` (``Terminated`` for SIGTERM). A signal already ``latched`` (one whose
    exception a library swallowed: ``sim.interrupts``) asks at once. The previous handlers are
    restored on exit, even when a signal comes between two installs. Off the main thread
    (where Python allows no handler) it does nothing."""

    def handler(signum: int, frame: FrameType | None) -> None:
        if loop.stop_requested:
            raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt
        loop.request_stop(signum)

    if threading.current_thread() is not threading.main_thread():
        yield  # only the main thread may install handlers: the caller's own stay in force
        return
    previous: dict[int, Any] = {}
    try:
        for sig in _STOP_SIGNALS:
            previous[sig] = signal.signal(sig, handler)
        if (latched := interrupts.latched()) is not None:
            loop.request_stop(latched)
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old)


def accepted_ids(node: str) -> frozenset[int]:
    """IDs of the frames ``node`` receives in the DBC: what its CAN controller's acceptance
    filter would pass (``sim.board.FirmwareBoard``'s ``accept_ids``).

    Not python-can's ``can_filters``: where they are applied in software (``udp_multicast``,
    ``virtual``), ``recv(0)`` returns None at the first frame they reject, so a node draining
    its bus with ``recv(0)`` would leave frames queued."""
    return frozenset(
        msg.frame_id
        for msg in database().messages
        if any(node in sig.receivers for sig in msg.signals)
    )
