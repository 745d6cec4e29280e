"""One progress line with an ETA on stderr, for commands that can run longer than ~2 s.

``Progress("simulating 3600 s", total=360000)`` redraws one line in place (``\\r``), at most
5 times a second, from ``delay_s`` (1 s) after it starts so a short run shows nothing. It is
silent when stderr is not a terminal (pipes, CI logs, tests): what is written there stays a
clean record. ``total=None`` shows only the elapsed time (work of unknown length).
``wall_clock_progress`` drives a line from a background thread for work measured in wall-clock
seconds (``fleet --duration``), where the work itself has no hook.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TextIO

REDRAW_S = 0.2  # at most five redraws a second
DELAY_S = 1.0  # nothing for work that ends sooner


def _clock(seconds: float) -> str:
    """``seconds`` as m:ss (h:mm:ss from an hour)."""
    whole = max(0, round(seconds))
    hours, rest = divmod(whole, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


class Progress:
    """A progress line on ``stream`` (default stderr), drawn only when it is a terminal."""

    def __init__(
        self,
        label: str,
        total: float | None,
        *,
        stream: TextIO | None = None,
        enabled: bool | None = None,
        delay_s: float = DELAY_S,
    ) -> None:
        """``total``: units of work (None: unknown); ``enabled`` None: when ``stream`` is a tty."""
        self.label, self.total = label, total
        self.stream = sys.stderr if stream is None else stream
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.started = time.monotonic()
        self._next_draw = self.started + delay_s
        self._drawn = False

    def line(self, done: float, now: float) -> str:
        """The text shown after ``done`` units at monotonic time ``now``."""
        elapsed = now - self.started
        if not self.total:
            return f"{self.label}: {_clock(elapsed)} elapsed"
        share = min(1.0, max(0.0, done / self.total))
        eta = "--:--" if share <= 0 else _clock(elapsed * (1 - share) / share)
        return f"{self.label}: {share * 100:5.1f}%  {_clock(elapsed)} elapsed, ETA {eta}"

    def update(self, done: float) -> None:
        """Record ``done`` units; redraw when it is time to."""
        if not self.enabled:
            return
        now = time.monotonic()
        if now < self._next_draw:
            return
        self._next_draw = now + REDRAW_S
        self.stream.write("\r" + self.line(done, now) + "\x1b[K")
        self.stream.flush()
        self._drawn = True

    def close(self) -> None:
        """Erase the line (the command's own output follows)."""
        if self._drawn:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self._drawn = False


@contextmanager
def progress(label: str, total: float | None, **kwargs: object) -> Iterator[Progress]:
    """A ``Progress`` erased on exit, whatever happens."""
    bar = Progress(label, total, **kwargs)  # type: ignore[arg-type]
    try:
        yield bar
    finally:
        bar.close()


@contextmanager
def wall_clock_progress(label: str, total_s: float | None) -> Iterator[Progress]:
    """A line that a daemon thread advances with the wall clock (``total_s`` seconds)."""
    with progress(label, total_s) as bar:
        if not bar.enabled:
            yield bar
            return
        stop = threading.Event()

        def advance() -> None:
            while not stop.wait(REDRAW_S):
                bar.update(time.monotonic() - bar.started)

        thread = threading.Thread(target=advance, name="odocan-progress", daemon=True)
        thread.start()
        try:
            yield bar
        finally:
            stop.set()
            thread.join()


@contextmanager
def counted_progress(label: str, total: int) -> Iterator[Callable[[], None]]:
    """A progress line over ``total`` units with its ETA; yields the callback that counts one
    unit done (for loops that live in another module, e.g. an experiment's runs)."""
    with progress(label, total) as bar:
        done = [0]

        def one_more() -> None:
            done[0] += 1
            bar.update(done[0])

        yield one_more
