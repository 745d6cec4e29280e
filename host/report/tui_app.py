"""The app behind ``odocan monitor``'s screen: the receive loop (the bus read and ``--log``
written on a reader thread, ``host.io.busreader``; the model, trace and live Foxglove fed), the
keys (pause, filter, quit) read in cbreak mode between frames, and the live screen on the
terminal. The screen itself is ``host.report.tui``; the trace ``host.report.trace``.
"""

from __future__ import annotations

import copy
import math
import os
import select
import sys
import termios
import time
import tty
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import can
from rich.console import Console
from rich.layout import Layout
from rich.live import Live

from odocan.host.io.busreader import BusReader, lost_here_text
from odocan.host.io.recording import stopped_after
from odocan.host.judge.monitor import BusMonitor
from odocan.host.report.trace import FrameFilter, Trace
from odocan.host.report.tui import View, screen
from odocan.host.stopped import signum_of
from odocan.sim.exceptions import ConfigurationError, OdocanError

if TYPE_CHECKING:
    from odocan.sim.realtime import StopRequest

REFRESH_S = 0.25  # screen redraws
LOST_CHECK_S = 1.0  # the kernel's drop count read at most this often (a /proc file)


class RecordingError(OdocanError):
    """``--log``: the recording could not be written (disk full, file gone, ...)."""


class FrameLog:
    """``--log PATH``: every frame heard to python-can's ``can.Logger`` (.log/.asc/.blf).

    A write error stops the recording (the keys line says so) but never the monitor; ``close()``
    then raises ``RecordingError`` naming the path and the frames written, so the command ends
    with one ``error:`` line and exit code 2 rather than a recording silently cut short.

    The recorded stamps never go back: a frame read with a stamp earlier than the frame
    recorded before it (the receive stamps of a socket's frames can be 1 us out of order, and
    ``analyze`` then warned that the log's times went back) is written with that frame's stamp
    (``stamps_raised`` counts them; the judge keeps the frame's own stamp).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.count = 0
        self.stamps_raised = 0  # frames written with the stamp before theirs (theirs was earlier)
        self._last_s = -math.inf
        self.failure: Exception | None = None
        try:
            self._logger = can.Logger(path)
        except (OSError, ValueError) as exc:
            raise ConfigurationError(f"--log {path}: {exc}") from exc

    def record(self, msg: can.Message) -> None:
        """Write one frame (counted when written); after a failure, nothing more."""
        if self.failure is not None:
            return
        if msg.timestamp < self._last_s:
            msg = copy.copy(msg)  # the judge's frame keeps its own stamp
            msg.timestamp = self._last_s
            self.stamps_raised += 1
        self._last_s = msg.timestamp
        try:
            self._logger.on_message_received(msg)
        except Exception as exc:  # any writer's error stops the recording, not the monitor
            self.failure = exc
            return
        self.count += 1

    @property
    def error(self) -> str:
        """The write error that stopped the recording ("" while recording)."""
        exc = self.failure
        return "" if exc is None else f"{type(exc).__name__}: {exc}"

    def close(self) -> None:
        """Finalise the file (a .blf's header and index are written here)."""
        try:
            self._logger.stop()
        except Exception as exc:
            self.failure = self.failure or exc
        if self.failure is not None:
            stopped = stopped_after(self.path, self.count)  # whole frames in the file
            raise RecordingError(f"--log {self.path}: {stopped}: {self.error}")


class MonitorApp:
    """The receive loop behind the screen: the log written as frames are read, the model and
    the trace fed; keys read."""

    def __init__(self, bus: can.BusABC, model: BusMonitor, trace: Trace, view: View,
                 recorder: FrameLog | None = None,
                 publish: Callable[[can.Message], None] | None = None,
                 stop: StopRequest | None = None) -> None:
        """``publish``: called with every frame after the model took it (live Foxglove);
        ``stop``: a signal's request to end the watch (``sim.realtime.stop_on_signals``), seen
        within ``REFRESH_S``; without one a signal ends it as a ``KeyboardInterrupt``."""
        self.bus, self.model, self.trace, self.view = bus, model, trace, view
        self.recorder = recorder
        self.publish = publish
        if publish is not None:  # the frames held for the robot's PROFILE page, once judged
            model.replayed = publish
        self.stop = stop
        self.quit = False
        self.stopped_by: int | None = None  # the signal (Ctrl-C, SIGTERM) that ended it
        self.reader: BusReader | None = None  # the bus's reader, once ``receive`` ran
        self._lost_checked_s = -LOST_CHECK_S

    def receive(self, deadline_s: float, redraw: Any | None = None) -> None:
        """Until ``deadline_s`` (monotonic), ``q`` or Ctrl-C/SIGTERM (``stopped_by``);
        ``redraw()`` every ``REFRESH_S``. The bus is read and ``--log`` written on the reader's
        own thread (``host.io.busreader``), so neither waits for the judge or the screen; the
        frames read before the end are judged before it returns (not after a signal: those
        are ``reader.pending``)."""
        reader = self.reader = BusReader(
            self.bus, None if self.recorder is None else self.recorder.record).start()
        try:
            self._judge(reader, deadline_s, redraw)
            if self.stop is not None and self.stop.stop_requested:  # a signal: frames pending
                self.stopped_by = self.stop.signum
                return
            reader.stop()
            for msg in reader.drain():
                self.on_frame(msg)
        except KeyboardInterrupt as exc:  # a second signal, or one with no ``stop`` to ask
            self.stopped_by = (self.stop and self.stop.signum) or signum_of(exc)
        finally:
            reader.stop()

    def _judge(self, reader: BusReader, deadline_s: float, redraw: Any | None) -> None:
        next_draw = 0.0
        while not (self.quit or self._stop_asked()) and (now := time.monotonic()) < deadline_s:
            if redraw is not None and now >= next_draw:
                redraw()
                next_draw = now + REFRESH_S
            msg = reader.get(max(0.0, min(REFRESH_S, deadline_s - now)))
            if msg is not None:
                self.on_frame(msg)
            if redraw is not None:
                self.on_keys(_read_keys())

    def _stop_asked(self) -> bool:
        return self.stop is not None and self.stop.stop_requested

    def on_frame(self, msg: can.Message) -> None:
        """One frame to judge (already in ``--log``): feed the model and the trace."""
        self.view.last_frame_s = time.monotonic()
        waiting = self.model.robot_wait is not None  # held: published once judged (replayed)
        self.model.feed(msg)
        self.trace.feed(msg)
        if self.publish is not None and not waiting:
            self.publish(msg)

    def on_keys(self, keys: str) -> None:
        """space/p: pause; f: edit the filter (Enter applies, Esc cancels); q: quit."""
        for key in keys:
            if self.view.editing is not None:
                self._edit(key)
            elif key in " p":
                self.trace.toggle_pause()
            elif key == "f":
                self.view.editing, self.view.note = self.trace.filter.text, ""
            elif key == "q":
                self.quit = True

    def _edit(self, key: str) -> None:
        text = self.view.editing or ""
        if key in "\r\n":
            try:
                self.trace.filter = FrameFilter.parse([text], self.trace.db)
                self.trace.lines.clear()
            except ConfigurationError as exc:
                self.view.note = str(exc)
            self.view.editing = None
        elif key == "\x1b":
            self.view.editing = None
        elif key in "\x7f\b":
            self.view.editing = text[:-1]
        elif key.isprintable():
            self.view.editing = text + key

    def refresh_view(self) -> None:
        """Bring the view's clock, ages and log count up to now."""
        now = time.monotonic()
        self.view.now_s = now
        self.view.heard_s = {n: now - s.heard_monotonic_s for n, s in self.model.messages.items()}
        if self.recorder is not None:
            self.view.logged, self.view.log_error = self.recorder.count, self.recorder.error
        if self.reader is not None and now >= self._lost_checked_s + LOST_CHECK_S:
            self.view.lost_here = lost_here_text(self.reader.stats(), short=True)
            self._lost_checked_s = now


def run_screen(app: MonitorApp, deadline_s: float, console: Console | None = None) -> None:
    """Show the screen until the deadline, ``q`` or Ctrl-C.

    On a terminal it takes the whole (alternate) screen, and its last state is printed once more
    after it closes, so it stays in the scrollback; elsewhere only the last state is printed."""
    console = console or Console(file=sys.stdout)

    def current(spare_rows: int = 0) -> Layout:
        app.refresh_view()
        width, height = console.size
        return screen(app.model.snapshot(), app.trace, app.view, width=width,
                      height=height - spare_rows)

    with _cbreak(), Live(console=console, auto_refresh=False, screen=console.is_terminal,
                         redirect_stderr=False) as live:
        app.receive(deadline_s, lambda: live.update(current(), refresh=True))
        app.model.release_held()  # the watch ended: frames held (the robot's page) judged
        live.update(current(), refresh=True)
    if console.is_terminal:
        console.print(current(spare_rows=1), height=console.size.height - 1)  # + the prompt


@contextmanager
def _cbreak() -> Iterator[None]:
    """Keys arrive one by one without echo while the screen is up (no-op without a tty)."""
    try:
        fd = sys.stdin.fileno()
        saved = termios.tcgetattr(fd) if os.isatty(fd) else None
    except (OSError, ValueError, termios.error):
        saved = None
    if saved is None:
        yield
        return
    tty.setcbreak(fd)
    try:
        yield
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)


def _read_keys() -> str:
    """Whatever keys are waiting on a terminal's stdin ("" otherwise; never blocks)."""
    try:
        fd = sys.stdin.fileno()
        if not os.isatty(fd) or not select.select([fd], [], [], 0)[0]:
            return ""
        return os.read(fd, 64).decode("utf-8", "replace")
    except (OSError, ValueError):
        return ""
