"""What the monitor's screen costs: the trace's decode per frame, and one redraw per terminal size.

The frames are 10 s of the lockstep rig (pmir, seed 2): the trace decodes every one of them
(about 360 frames/s on a live bus), and the screen is redrawn every ``REFRESH_S`` (0.25 s) from a
model fed with the same frames. Median of repeated runs. Prints figures; asserts nothing.
Run: ``.venv/bin/python bench/tui.py``.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

import can
from rich.console import Console

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from odocan.host.judge.monitor import BusMonitor  # noqa: E402
from odocan.host.report.trace import Trace  # noqa: E402
from odocan.host.report.tui import View, screen  # noqa: E402
from odocan.host.report.tui_app import REFRESH_S  # noqa: E402
from odocan.sim import robot  # noqa: E402
from odocan.sim.rig import LockstepRig, RigConfig  # noqa: E402

TICKS = 1000  # 10 s
SIZES = ((80, 24), (120, 40), (200, 60))


def frames() -> list[can.Message]:
    """Every host-bus frame of TICKS rig steps."""
    out: list[can.Message] = []

    class Keep(can.Listener):
        def on_message_received(self, msg: can.Message) -> None:
            out.append(msg)

    config = RigConfig(robot=robot.load("pmir"), seed=2, channel=f"bench-tui-{os.getpid()}")
    with LockstepRig(config, listeners=[Keep()]) as rig:
        for _ in range(TICKS):
            rig.step()
    return out


def main() -> None:
    """Print the decode cost per frame and the redraw cost per terminal size."""
    msgs = frames()
    model = BusMonitor(robot.load("pmir"))
    per_frame_s = []
    for _ in range(5):
        trace = Trace(model.db)
        start = time.perf_counter()
        for msg in msgs:
            trace.feed(msg)
        per_frame_s.append((time.perf_counter() - start) / len(msgs))
    rate_hz = len(msgs) / (TICKS * 0.01)
    decode_s = statistics.median(per_frame_s)
    print(f"trace decode: {decode_s * 1e6:.1f} µs/frame (median of 5 × {len(msgs)} frames); "
          f"at {rate_hz:.0f} frames/s: {100 * decode_s * rate_hz:.2f} % of one core")
    for msg in msgs:
        model.feed(msg, now_s=msg.timestamp)
    last_s = msgs[-1].timestamp
    view = View(source="bench", now_s=last_s, started_s=0.0, last_frame_s=last_s,
                heard_s={n: last_s - s.heard_monotonic_s for n, s in model.messages.items()})
    for width, height in SIZES:
        console = Console(width=width, height=height, file=open(os.devnull, "w"),  # noqa: SIM115
                          force_terminal=True, color_system="truecolor")
        times_s = []
        for _ in range(30):
            start = time.perf_counter()
            console.print(screen(model.snapshot(), trace, view, width=width, height=height))
            times_s.append(time.perf_counter() - start)
        redraw_s = statistics.median(times_s)
        print(f"redraw {width}×{height}: {redraw_s * 1e3:.1f} ms (median of 30, snapshot "
              f"included); every {REFRESH_S} s: {100 * redraw_s / REFRESH_S:.1f} % of one core")


if __name__ == "__main__":
    main()
