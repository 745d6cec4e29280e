"""The bridge's frame handling by part: what each live judge costs per robot-tick, by subtraction.

``bench/bridge_frames.py`` feeds a fleet's recorded frames to one ``RobotTelemetry`` per robot and
times the whole; its ``--by-message`` splits the time by the frame that spent it, which misleads
(a frame's ``advance`` settles the pose halves heard before it: the pairing, the comparison and the
losses land on whichever frame comes next). cProfile's split is worse (its cost per call inflates
the parts made of many small calls). Here each variant takes one part's work out (its methods
made no-ops on the class: the telemetry's route handlers, bound when the class was made, cannot be
patched and are not) and feeds the same recording; variants run interleaved, ``--repeat`` times,
and each keeps its least CPU (the machine's load only ever adds). A part's cost is the base's less
its variant's: an estimate (without a judge the rest does a little less, or more: without the E2E
check no frame is refused), good to a few us per robot-tick on a loaded machine.

    PYTHONPATH=. .venv/bin/python bench/bridge_frames.py --robots 10 --ticks 600 \
        --record /tmp/fleet10.pkl
    PYTHONPATH=. .venv/bin/python bench/bridge_parts.py --frames /tmp/fleet10.pkl [--repeat 5]

On a loaded machine the least CPU still moves by 5-10 us per robot-tick from run to run (load
9-13, two cores shared: a part's figure as much). ``--variant N`` runs variant N alone (0: the
base), once: under ``valgrind --tool=callgrind`` the instructions of each such process are the
same from run to run, and the base's less a variant's, over the robot-ticks, is that part's
cost in instructions, whatever the load (the processes differ only in the part taken out).
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bridge_frames import Recording, record, run_once  # bench/bridge_frames.py

import odocan.host.mqtt.topics as topics
from odocan.host.judge.livedistance import LiveDistance
from odocan.host.judge.livetwist import LiveTwist
from odocan.host.judge.tracking import PoseTracker
from odocan.host.protocol.e2e_live import E2EMonitor


def _none(*_args: Any, **_kwargs: Any) -> None:
    return None


def _ok(*_args: Any, **_kwargs: Any) -> str:
    return "ok"


Patch = tuple[type, str, Callable[..., Any]]
VARIANTS: dict[str, list[Patch]] = {
    "base": [],
    "DISTANCE judge (livedistance: its gate, sums, twist naming)": [
        (LiveDistance, "on_encoders", _none), (LiveDistance, "on_twist", _none)],
    "TWIST judge (livetwist: steps, bands)": [
        (LiveTwist, "on_encoders", _none), (LiveTwist, "on_twist", _none)],
    "E2E check (every frame 'ok')": [(E2EMonitor, "check", _ok)],
    "truth judge (SIM_TRUTH's samples)": [(PoseTracker, "on_truth", _none)],
    "JSON of the publications (topics.dumps)": [(topics, "dumps", lambda _payload: b"")],
}


def measure(recording: Recording, repeat: int) -> dict[str, float]:
    """The least CPU s per robot-tick of each variant over ``repeat`` interleaved rounds."""
    robots, batches = recording
    best: dict[str, float] = {}
    for _ in range(repeat):
        for name, patches in VARIANTS.items():
            saved = [(owner, attr, getattr(owner, attr)) for owner, attr, _ in patches]
            for owner, attr, replacement in patches:
                setattr(owner, attr, replacement)
            try:
                cpu_s = run_once(recording, None, Counter())[0] / (robots * len(batches))
            finally:
                for owner, attr, original in saved:
                    setattr(owner, attr, original)
            best[name] = min(best.get(name, cpu_s), cpu_s)
    return best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=10)
    parser.add_argument("--ticks", type=int, default=600)
    parser.add_argument("--frames", metavar="PATH", help="a recording (else one made now)")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--variant", type=int, metavar="N",
                        help="run only variant N (0: the base), once (for callgrind)")
    args = parser.parse_args()
    if args.variant is not None:
        name = list(VARIANTS)[args.variant]
        for other in [v for v in VARIANTS if v != name]:
            del VARIANTS[other]
        args.repeat = 1
    recording: Recording = (pickle.loads(Path(args.frames).read_bytes()) if args.frames
                            else record(args.robots, args.ticks))
    setattr(topics.time, "time", lambda: 1.0)  # noqa: B010 (as bridge_frames: a pinned clock)
    best = measure(recording, args.repeat)
    if "base" not in best:
        print(f"{args.variant}: {', '.join(best)}: {best[name] * 1e6:.1f} us CPU per robot-tick")
        return 0
    base_us = best["base"] * 1e6
    print(f"{recording[0]} robots, {len(recording[1])} ticks, least of {args.repeat}: "
          f"{base_us:.1f} us CPU per robot-tick in all, load {os.getloadavg()[0]:.2f}")
    for name, cpu_s in best.items():
        if name != "base":
            part_us = base_us - cpu_s * 1e6
            print(f"  {name:60s} {part_us:5.1f} us ({part_us / base_us * 100:4.1f}%)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
