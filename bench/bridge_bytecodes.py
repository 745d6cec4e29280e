"""The bridge's frame handling by Python function, in bytecodes and calls per robot-tick: a
load-free profile that needs no valgrind and takes seconds.

``bench/bridge_parts.py --variant N`` under callgrind counts instructions per part, but a pass
takes minutes and names C functions, not the judge's; cProfile names them but its cost per call
inflates the parts made of many small calls. Here a tracer (``sys.settrace`` with
``f_trace_opcodes``) counts the bytecodes each Python function executes itself and the calls
made to it while the first ``--robots`` robots of a recording (``bench/bridge_frames.py
--record``) are fed as ``bridge_frames.run_once`` feeds them: the same counts on every run,
whatever the machine's load. On this tree a bytecode costs ~65 instructions on average (calls
and C work included), a Python call ~500 more, so both columns say where the instructions go.

    PYTHONPATH=. .venv/bin/python bench/bridge_bytecodes.py /tmp/fleet10.pkl [--robots 3] \
        [--top 40] [--lines check,step]

``--lines`` splits the named functions by line.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from collections import Counter
from pathlib import Path
from types import FrameType
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import bridge_frames  # bench/bridge_frames.py

import odocan.host.mqtt.topics as topics

ROOT = str(Path(__file__).resolve().parent.parent) + "/"
Key = tuple[str, ...]


def profile(path: str, robots: int, lines: set[str]) -> tuple[Counter[Key], Counter[Key], int]:
    """Bytecodes and calls per function (per line for those named in ``lines``), robot-ticks."""
    _, batches = pickle.loads(Path(path).read_bytes())
    batches = [[(i, f) for i, f in batch if i < robots] for batch in batches]
    tels = bridge_frames.telemetries(robots)
    plans = [telemetry.plans for telemetry in tels]
    bytecodes: Counter[Key] = Counter()
    calls: Counter[Key] = Counter()

    def tracer(frame: FrameType, event: str, _arg: Any) -> Any:
        code = frame.f_code
        key: Key = (f"{code.co_filename.replace(ROOT, '')}:{code.co_firstlineno}", code.co_name)
        if code.co_name in lines:
            key = (*key, str(frame.f_lineno))
        if event == "call":
            calls[key] += 1
            frame.f_trace_opcodes = True
        elif event == "opcode":
            bytecodes[key] += 1
        return tracer

    sys.settrace(tracer)
    try:
        for batch in batches:
            for index, (t_s, can_id, data) in batch:
                plan = plans[index].get(can_id)
                for _, payload in (plan(t_s, data) if plan is not None else
                                   bridge_frames.FEED(tels[index], t_s, can_id, data, False)):
                    topics.dumps(payload)
    finally:
        sys.settrace(None)
    return bytecodes, calls, robots * len(batches)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames", help="a recording (bench/bridge_frames.py --record)")
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--top", type=int, default=40)
    parser.add_argument("--lines", default="", help="functions split by line (comma-separated)")
    args = parser.parse_args()
    bytecodes, calls, robot_ticks = profile(args.frames, args.robots,
                                            set(filter(None, args.lines.split(","))))
    print(f"{sum(bytecodes.values()) / robot_ticks:.0f} bytecodes and "
          f"{sum(calls.values()) / robot_ticks:.1f} Python calls per robot-tick "
          f"({args.robots} robots, {robot_ticks} robot-ticks)")
    for key, n in bytecodes.most_common(args.top):
        print(f"{n / robot_ticks:7.1f} {calls[key] / robot_ticks:5.2f}  {' '.join(key)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
