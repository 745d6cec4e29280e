"""How many captures the streamed E2E check still refuses, and whether one it keeps ever judges
otherwise than the whole log (``host.judge.stream_carry``, issue #11, one judge).

Lockstep drives (``--drives`` seeds on kobuki and pmir, each with a delay fault, a burst fault or
none, ``--duration`` s) recorded as they are, starved (the recorder seeds 1 and 2 of
tests/test_capture_bunched.py) and jittered 0..3 ms (seeds 1..3 of
tests/test_capture_jitter.py); each capture streamed at ``--chunks`` frames a chunk through
``carried`` and ``StreamE2E`` and compared with the whole log's ``check_frames`` (the same
accepted frames, the same counts). Prints, per recorder: streams, refused (``exact`` False),
kept and the same, kept and different (must be 0: a stream that says exact and is not). Asserts
nothing. Run: ``.venv/bin/python bench/stream_carry.py [--drives 10] [--duration 12]``."""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from odocan.host.cli.app import main
from odocan.host.io.logs import iter_log, read_log
from odocan.host.judge.stream_carry import carried
from odocan.host.judge.stream_e2e import StreamE2E
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.e2e import check_frames
from tests.test_capture_bunched import _starved
from tests.test_capture_jitter import _jittered

RECORDERS = {"bus": None, "starved1": (_starved, 1), "starved2": (_starved, 2),
             "jittered1": (_jittered, 1), "jittered2": (_jittered, 2), "jittered3": (_jittered, 3)}


def _drive(tmp: Path, robot: str, seed: int, faults: str, duration_s: float) -> Path:
    log = tmp / f"{robot}-{seed}-{faults.split('=')[0] or 'clean'}.log"
    argv = ["run", "--robot", robot, "--duration", str(duration_s), "--seed", str(seed),
            "--log", str(log), "--firmware", "python"]
    with contextlib.redirect_stdout(io.StringIO()):
        main(argv + (["--faults", faults] if faults else []))
    return log


def _verdict(path: Path, chunk_frames: int) -> str:
    """refused, same or DIFFERENT (kept as exact, judged otherwise than the whole log)."""
    db = default_plan()
    counts, accepted = check_frames(read_log(path), db)
    e2e = StreamE2E(db)
    chunks = carried(iter_log(path, chunk_frames=chunk_frames), db)
    streamed = np.concatenate([e2e.feed(chunk) for chunk in chunks])
    if not e2e.exact:
        return "refused"
    same = bool(np.array_equal(streamed, accepted)) and e2e.counts == counts
    return "same" if same else "DIFFERENT"


def run(drives: int, duration_s: float, chunks: list[int]) -> None:
    tally: dict[str, Counter[str]] = {name: Counter() for name in RECORDERS}
    with tempfile.TemporaryDirectory() as tmp_dir:
        tmp = Path(tmp_dir)
        for seed in range(1, drives + 1):
            robot = "kobuki" if seed % 2 else "pmir"
            for faults in (f"delay=0.1:15,seed={seed}", f"burst=0.05:3,seed={seed}", ""):
                log = _drive(tmp, robot, seed, faults, duration_s)
                for name, recorder in RECORDERS.items():
                    path = log
                    if recorder is not None:
                        path = tmp / f"{name}.log"
                        recorder[0](log, path, recorder[1])
                    for chunk_frames in chunks:
                        tally[name][_verdict(path, chunk_frames)] += 1
            print(f"drive seed {seed} done", flush=True)
    for name, counts in tally.items():
        print(f"{name:10s} streams {sum(counts.values()):4d}  refused {counts['refused']:4d}  "
              f"same {counts['same']:4d}  DIFFERENT {counts['DIFFERENT']:4d}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=int, default=10)
    parser.add_argument("--duration", type=float, default=12.0, help="s of each drive")
    parser.add_argument("--chunks", type=int, nargs="+", default=[97, 1000])
    args = parser.parse_args()
    run(args.drives, args.duration, args.chunks)
