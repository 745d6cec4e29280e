"""The live judges' cost per frame (``odocan monitor``'s ``BusMonitor``, the MQTT bridge's
``RobotTelemetry``): figures, no assertion.

A drive is run in the lockstep rig (``odocan run --log``), clean and with a babbler below
WHEEL_ENCODERS (the poses come out in bursts: the live judges resolve those on their whole
window), and its frames are fed to each judge as they were heard. Printed: microseconds of CPU
per frame and the max on-board vs reference error each judge ends with (m).

``--slow``: every pose half by ``samples.match_encoder`` over the window (the fast path of
``livewindow.named_plain`` off: what the judges cost before it; the same results).

Run: ``.venv/bin/python bench/live_judge.py [--seconds S] [--slow]``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import can

from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.robot import load

RUNS = {
    "clean": [],
    "babble": ["-b", "125000", "--faults", "babble=3000:0x050:2:0.5,seed=3"],
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="drive length (s)")
    parser.add_argument("--slow", action="store_true",
                        help="every pose half by match_encoder (no fast path)")
    args = parser.parse_args()
    PoseTracker.fast_path = not args.slow
    profile = load("pmir")
    with tempfile.TemporaryDirectory() as tmp:
        for name, extra in RUNS.items():
            log = Path(tmp) / f"{name}.log"
            subprocess.run([sys.executable, "-m", "odocan", "run", "--robot", "pmir", "--seed",
                            "3", "--duration", str(args.seconds), "--log", str(log), *extra],
                           check=False, capture_output=True)
            with can.LogReader(str(log)) as reader:
                frames = list(reader)
            monitor = BusMonitor(profile, "exact")
            start = time.process_time()
            for msg in frames:
                monitor.feed(msg, now_s=msg.timestamp)
            monitor_s = time.process_time() - start
            bridge = RobotTelemetry("r", Geometry.of(profile), "exact",
                                    counter_bits=profile.counter_bits)
            start = time.process_time()
            for msg in frames:
                bridge.feed(msg)
            bridge_s = time.process_time() - start
            per_frame = 1e6 / len(frames)
            print(f"{name}: {len(frames)} frames; monitor {monitor_s * per_frame:.1f} us/frame "
                  f"(max {monitor.tracker.vs_reference.max_dpos_m:.3e} m), bridge "
                  f"{bridge_s * per_frame:.1f} us/frame "
                  f"(max {bridge.tracker.vs_reference.max_dpos_m:.3e} m)")


if __name__ == "__main__":
    main()
