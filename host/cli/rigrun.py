"""``odocan run``'s rig under signals: the log opened, the rig built and stepped, the log finished.

From the moment the ``--log`` is opened to the moment it is finished, SIGINT and SIGTERM only ask
the rig to stop (``sim.realtime.stop_on_signals``): an exception raised at a random point of the
start-up left the log unfinished (a 0-byte ``.blf`` when it landed in python-can's writer, an
``.asc`` without its footer when it landed in the rig's construction), and one that landed in
numpy.random's import was swallowed there: the run went on to its end, exit 0. A signal that
comes before the first tick ends the command with no tick run: the log finished and holding no
frame (a ``.blf`` header counting 0 objects, an ``.asc`` with its footer; a signal heard before
the log is opened writes none), then ``not_started`` for the CLI's one line and its 143 (130).
One heard as the last tick ran or the log was finished is heard once the log is whole, as one
during the analysis would be (``stop_before_analysis``).
"""

from __future__ import annotations

import gc
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import can

from odocan.host.io.recording import Recording
from odocan.host.outputs import OutputError
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.report.progress import progress
from odocan.host.stopped import Stopped, interruption, signum_of
from odocan.sim.board import TICK_S
from odocan.sim.contract import read_as
from odocan.sim.realtime import StopRequest
from odocan.sim.rig import LockstepRig, RigConfig

PROGRESS_EVERY_TICKS = 100  # one simulated second


def start_rig(
    config: RigConfig, listeners: list[can.Listener], log: Path | None, stop: StopRequest
) -> LockstepRig:
    """The rig on ``listeners`` and, unless a stop was already asked, the ``log``'s writer.
    A rig that cannot be built (a refusal, a second signal) finishes the log it opened."""
    recording = None if log is None or stop.stop_requested else _open_log(log, config.channel)
    if recording is not None:
        listeners.append(recording)
    try:
        with read_as(default_plan()):  # the judge's plan of the DBC: no cantools to start
            return LockstepRig(config, listeners=listeners)
    except BaseException:
        if recording is not None:
            with suppress(OSError):  # the error that stopped the start-up is the one to tell
                recording.stop()
        raise


def _open_log(path: Path, channel: str) -> Recording:
    """python-can's writer for ``path`` (by extension), of the rig's ``channel``; an error names
    the path. A write that
    fails mid-run (a full disk) stops the recording, not the run: the summary is printed, then
    the error with the path (``rig.close()`` raises it, ``_run_and_analyze`` returns it)."""
    try:
        return Recording(can.Logger(path), channel)
    except OSError as exc:
        raise OutputError(f"--log {path}: {exc.strerror or exc}") from None


def stop_before_analysis(
    stopped: Stopped | None, stop: StopRequest, log: Path | None, listeners: list[can.Listener]
) -> KeyboardInterrupt | None:
    """What to raise, the rig closed, for a signal that leaves nothing to analyse: one before
    the first tick (``not_started``), or one heard as the last tick ran or the log was
    finished (as it would be in the analysis); None: analyse (``stopped``: ``run_rig``'s)."""
    if stopped is not None and stopped.done == 0:
        return not_started(stopped.signum, log, listeners)
    if stopped is None and stop.stop_requested:
        return interruption(stop.signum, "after its last tick, before the analysis")
    return None


def not_started(
    signum: int, log: Path | None, listeners: list[can.Listener]
) -> KeyboardInterrupt:
    """The interruption of a run stopped before its first tick (``listeners``: the rig's, its
    log's writer among them if ``start_rig`` opened one), saying what became of its log."""
    where = "before its first tick"
    if log is not None:
        opened = any(isinstance(li, Recording) for li in listeners)
        where += f"; --log {log}: " + ("finished, no frame" if opened else "not written")
    return interruption(signum, where)


def run_rig(
    rig: LockstepRig, stop: StopRequest, duration_s: float,
    on_tick: Callable[[], None] | None = None,
) -> Stopped | None:
    """Step the rig for ``duration_s`` simulated seconds until ``stop`` is asked (checked before
    the first tick, after it, then every simulated second; a second signal, or any
    KeyboardInterrupt, stops at once), a progress line on a terminal. Returns how far it got when
    a signal stopped it before the end (``done`` 0: before its first tick), else None."""
    total = round(duration_s / TICK_S)
    done = 0
    interrupt: KeyboardInterrupt | None = None
    with progress(f"simulating {duration_s:g} s", total) as bar:
        try:
            while done < total and not stop.stop_requested:
                ticks = min(PROGRESS_EVERY_TICKS if done else 1, total - done)
                _run_ticks(rig, ticks, on_tick)
                done += ticks
                bar.update(done - 1)
        except KeyboardInterrupt as exc:
            interrupt = exc
    if rig.ticks >= total:
        return None
    done_s = rig.ticks * TICK_S
    if rig.ticks:  # none: the caller's one line says so
        print(f"interrupted after {done_s:g} s simulated", file=sys.stderr)
    return Stopped(stop.signum or signum_of(interrupt), round(done_s, 6), duration_s)


# The cyclic collector's young-generation threshold during the run and its analysis (CPython's
# default: 700). A lockstep run allocates few cycles, yet at 700 the collector ran ~1500 times in
# a 3600 s run and its analysis (0.4 s of CPU); at 20 000 some 50 times. The bytes are the same:
# no cycle holds a frame.
_RUN_GC_THRESHOLD = 20_000


@contextmanager
def rare_collections() -> Iterator[None]:
    """The run and its analysis with the objects of the start-up frozen (``gc.freeze``: never
    scanned again) and the young generation collected every ``_RUN_GC_THRESHOLD`` net
    allocations; both undone after them."""
    threshold = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(_RUN_GC_THRESHOLD, *threshold[1:])
    try:
        yield
    finally:
        gc.set_threshold(*threshold)
        gc.unfreeze()


def _run_ticks(rig: LockstepRig, ticks: int, on_tick: Callable[[], None] | None) -> None:
    """``ticks`` ticks: ``on_tick()`` after each one, or, with none, in one ``TickLoop.run``
    (which hands passive listeners, the collector, the host's frames once, not every tick)."""
    if on_tick is None:
        rig.loop.run(ticks)
        return
    for _ in range(ticks):
        rig.step()
        on_tick()
