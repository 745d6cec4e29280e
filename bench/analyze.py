"""Log analysis throughput: ``read_log + analyze`` against cantools' per-frame decoding.

Makes (once, cached under ``out/bench/``) a candump log of about 1M frames with the lockstep rig
(``can.Logger`` on a ``.log`` path), then times:

* odocan: ``host.logio.read_log`` + ``host.analysis.analyze`` (parse, E2E on every frame, decode,
  align, float64 reference, truth comparison);
* cantools, in process: ``db.decode_message`` on every frame of the same log (frames already
  parsed, so the parse is not counted against it);
* cantools' command line: ``cantools decode --single-line dbc/odocan.dbc < LOG > /dev/null``.

Target (issue #4): >= 20x faster than cantools while doing more. Prints figures; asserts
nothing. Run: ``.venv/bin/python bench/analyze.py [--frames N] [--no-cli]``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import can  # noqa: E402

from odocan.host.io.logs import FrameArrays, read_log  # noqa: E402
from odocan.host.judge.analysis import analyze  # noqa: E402
from odocan.sim.contract import DBC_PATH, database  # noqa: E402
from odocan.sim.rig import LockstepRig, RigConfig  # noqa: E402
from odocan.sim.robot import load  # noqa: E402

FRAMES_PER_SIM_SECOND = 360  # the rig's bus load: 100 + 50 + 3 * 50 + 20 + 30 + 10 frames/s
ROBOT = "pmir"
INTEGRATOR = "exact"


def make_log(frames: int) -> Path:
    """The cached candump log of about ``frames`` frames (made with the rig when missing)."""
    seconds = round(frames / FRAMES_PER_SIM_SECOND)
    path = ROOT / "out" / "bench" / f"analyze_{seconds}s.log"
    if path.is_file():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".part.log")
    print(f"making {path.relative_to(ROOT)}: {seconds} s of lockstep rig ...", flush=True)
    start = time.perf_counter()
    logger = can.Logger(str(partial))
    with LockstepRig(RigConfig(load(ROBOT), INTEGRATOR, "random", 1), [logger]) as rig:
        rig.run(seconds)
    partial.rename(path)
    print(f"  done in {time.perf_counter() - start:.1f} s", flush=True)
    return path


def time_odocan(path: Path, runs: int = 3) -> tuple[float, float, FrameArrays, bool]:
    """Seconds of read_log, of analyze (best of ``runs`` each); the frames; the verdict."""
    best_read = best_analyze = float("inf")
    for _ in range(runs):
        start = time.perf_counter()
        frames = read_log(path)
        parsed = time.perf_counter()
        analysis = analyze(frames, load(ROBOT))
        done = time.perf_counter()
        best_read = min(best_read, parsed - start)
        best_analyze = min(best_analyze, done - parsed)
    return best_read, best_analyze, frames, analysis.passed


def time_cantools_decode(frames: FrameArrays) -> float:
    """Seconds of ``db.decode_message`` on every frame (already parsed)."""
    db = database()
    ids = frames.can_id.tolist()
    payloads = [bytes(row) for row in frames.data]
    decode = db.decode_message
    start = time.perf_counter()
    for can_id, data in zip(ids, payloads, strict=True):
        decode(can_id, data)
    return time.perf_counter() - start


def time_cantools_cli(path: Path) -> float:
    """Seconds of ``cantools decode --single-line DBC < LOG > /dev/null``."""
    cantools_cli = Path(sys.executable).parent / "cantools"
    start = time.perf_counter()
    with path.open("rb") as log:
        subprocess.run(
            [str(cantools_cli), "decode", "--single-line", str(DBC_PATH)],
            stdin=log, stdout=subprocess.DEVNULL, check=True,
        )
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=1_000_000, help="log size (frames)")
    parser.add_argument("--no-cli", action="store_true", help="skip the cantools CLI run")
    args = parser.parse_args()
    path = make_log(args.frames)
    t_read, t_analyze, frames, passed = time_odocan(path)
    n = len(frames)
    ours = t_read + t_analyze
    size_mb = path.stat().st_size / 1e6
    print(f"log: {path.relative_to(ROOT)}, {n} frames, {size_mb:.0f} MB")
    print("odocan, best of 3 (cantools: one run each)")
    print(f"odocan read_log          {t_read:8.2f} s  {n / t_read / 1e6:6.2f} M frames/s")
    print(f"odocan analyze           {t_analyze:8.2f} s  (passed: {passed})")
    print(f"odocan read_log+analyze  {ours:8.2f} s  {n / ours / 1e6:6.2f} M frames/s")
    t_decode = time_cantools_decode(frames)
    print(f"cantools decode_message  {t_decode:8.2f} s  {n / t_decode / 1e6:6.2f} M frames/s"
          f"  -> odocan {t_decode / ours:5.1f}x faster")
    if not args.no_cli:
        t_cli = time_cantools_cli(path)
        print(f"cantools decode (CLI)    {t_cli:8.2f} s  {n / t_cli / 1e6:6.2f} M frames/s"
              f"  -> odocan {t_cli / ours:5.1f}x faster")


if __name__ == "__main__":
    main()
