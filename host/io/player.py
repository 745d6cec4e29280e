"""Play a log's frames onto a live bus with their recorded timing (``odocan replay --realtime``)."""

from __future__ import annotations

import signal
import time
from collections.abc import Callable

import can
import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FLAG_ERROR, FrameArrays, to_message
from odocan.host.stopped import signum_of
from odocan.sim.realtime import StopRequest, stop_on_signals

IntArray = npt.NDArray[np.int64]
POLL_S = 0.1  # a stop request is seen within this while waiting for a frame's time


def play(
    bus: can.BusABC, frames: FrameArrays, selection: IntArray, speed: float,
    played: Callable[[int], None] | None = None,
) -> tuple[int, int | None]:
    """Send ``frames[selection]`` on ``bus`` at their timestamps (relative to the first one)
    divided by ``speed`` (error frames are skipped); returns (frames sent, the number of the
    signal that stopped it before the last frame, or None).

    Ctrl-C and SIGTERM stop it between two frames (within ``POLL_S`` while waiting), never in
    the middle of a send; a second signal at once. ``played`` is told the frames played so far
    (a progress line's ``update``)."""
    sent = 0
    if len(selection) == 0:
        return sent, None
    t_first = float(frames.timestamp_s[selection[0]])
    start = time.monotonic()
    stop = StopRequest()
    try:
        with stop_on_signals(stop):
            for done, i in enumerate(selection.tolist()):
                if played is not None:
                    played(done)
                due = start + (float(frames.timestamp_s[i]) - t_first) / speed
                while not stop.stop_requested and (delay := due - time.monotonic()) > 0:
                    time.sleep(min(delay, POLL_S))
                if stop.stop_requested:
                    return sent, stop.signum or int(signal.SIGINT)
                if not frames.flags[i] & FLAG_ERROR:
                    bus.send(to_message(frames, i))
                    sent += 1
    except KeyboardInterrupt as exc:
        return sent, stop.signum or signum_of(exc)
    return sent, None


