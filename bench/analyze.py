"""Log analysis throughput: ``read_log + analyze`` against cantools' per-frame decoding.

Makes (once, cached under ``out/bench/``) a candump log of about 1M frames with the lockstep rig
(``can.Logger`` on a ``.log`` path), then times:

* odocan: ``host.logio.read_log`` + ``host.analysis.analyze`` (parse, E2E on every frame, decode,
  align, float64 reference, truth comparison);
* cantools, in process: ``db.decode_message`` on every frame of the same log (frames already
  parsed, so the parse is not counted against it);
* cantools' command line: ``cantools decode --single-line dbc/odocan.dbc < LOG > /dev/null``.

Then, as whole processes (start-up and imports included, issue #14.2): ``odocan analyze LOG``
against ``cantools decode --single-line``, each one's wall time, CPU time (user + system, the
figure that suffers least from a loaded machine) and max RSS, read from ``wait4`` as
``/usr/bin/time -v`` does, in ``--runs`` pairs run alternately (a shared machine's load moves
both), with each pair's ratio and their range; odocan once more before them with an empty
DBC-plan cache (``host.protocol.dbcplan``: its first run after a DBC change); and with
``--batch N``, N copies (symlinks) of a smaller drive analysed as a fleet's archive with
``--jobs 1``, ``--jobs 2`` and a 2-worker Dask ``LocalCluster``.

With ``--startup``: the start-up alone, as whole processes (best of ``--runs``): the bare
interpreter, ``odocan --version`` and ``odocan analyze`` on a 2-second drive.

Target (issues #4, #14): >= 20x faster than cantools while doing more. Prints figures; asserts
nothing. Run: ``.venv/bin/python bench/analyze.py [--frames N | --log PATH] [--no-cli]
[--batch 20] [--startup]``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
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


def whole_process(
    argv: list[str], stdin: Path | None = None, env: dict[str, str] | None = None
) -> tuple[float, float, float, int]:
    """Wall seconds, CPU seconds (user + system), max RSS in MB and exit code of ``argv`` run
    to completion (stdout discarded), measured as ``/usr/bin/time -v`` does (``wait4``).
    Python's bytecode caches are on (``PYTHONDONTWRITEBYTECODE`` dropped), as for a package
    pip installed, whose modules are compiled at install: without them each run compiled
    odocan's 161 modules again (0.23 s of a 1.6 s run on this log, cProfile) while cantools,
    installed from a wheel, had its caches."""
    env = {key: value for key, value in (os.environ if env is None else env).items()
           if key != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(ROOT)
    stdin_file = stdin.open("rb") if stdin is not None else subprocess.DEVNULL
    start = time.perf_counter()
    child = subprocess.Popen(argv, stdin=stdin_file, stdout=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    if stdin is not None:
        stdin_file.close()  # type: ignore[union-attr]
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, child.returncode


def print_whole_processes(path: Path, frames: int, runs: int, cli: bool) -> None:
    """``odocan analyze LOG`` and ``cantools decode`` as whole processes, side by side: first
    odocan with an empty DBC-plan cache (its first run after a DBC change parses the DBC with
    cantools), then ``runs`` pairs alternating odocan (warm cache) and cantools, each pair's
    ratio and their range (a shared machine's load moves both)."""
    odocan = [sys.executable, "-m", "odocan", "analyze", str(path)]
    cantools_cli = [str(Path(sys.executable).parent / "cantools"), "decode", "--single-line",
                    str(DBC_PATH)]
    print(f"whole processes on {frames} frames (wall / CPU user+sys / max RSS)")
    with tempfile.TemporaryDirectory() as cache:
        cold = whole_process(odocan, env=dict(os.environ, ODOCAN_CACHE_DIR=cache))
    print(f"odocan analyze, cold     {cold[0]:8.2f} s  {cold[1]:8.2f} s CPU  {cold[2]:7.0f} MB"
          f"  exit {cold[3]}  (empty DBC-plan cache)")
    whole_process(odocan)  # the default cache warm, whatever ran before
    ratios_cpu, ratios_wall = [], []
    for run in range(runs):
        ours = whole_process(odocan)
        print(f"odocan analyze LOG       {ours[0]:8.2f} s  {ours[1]:8.2f} s CPU  {ours[2]:7.0f} MB"
              f"  exit {ours[3]}")
        if not cli:
            continue
        theirs = whole_process(cantools_cli, stdin=path)
        ratios_cpu.append(theirs[1] / ours[1])
        ratios_wall.append(theirs[0] / ours[0])
        print(f"cantools decode < LOG    {theirs[0]:8.2f} s  {theirs[1]:8.2f} s CPU  "
              f"{theirs[2]:7.0f} MB  exit {theirs[3]}   pair {run + 1}: CPU "
              f"{ratios_cpu[-1]:5.1f}x, wall {ratios_wall[-1]:5.1f}x")
    if ratios_cpu:
        print(f"ratio (cantools / odocan) over {len(ratios_cpu)} pairs: CPU "
              f"{min(ratios_cpu):.1f}-{max(ratios_cpu):.1f}x, wall "
              f"{min(ratios_wall):.1f}-{max(ratios_wall):.1f}x (target >= 20x)")


def print_startup(runs: int) -> None:
    """Start-up as whole processes, best of ``runs`` by CPU: the interpreter alone, ``odocan
    --version``, ``odocan analyze`` on a 2-second drive (720 frames)."""
    small = make_log(720)
    print(f"start-up, whole processes (best of {runs}; wall / CPU)")
    for label, argv in (
        ("python -c pass", [sys.executable, "-c", "pass"]),
        ("odocan --version", [sys.executable, "-m", "odocan", "--version"]),
        ("odocan analyze (720 fr.)", [sys.executable, "-m", "odocan", "analyze", str(small)]),
    ):
        best = min((whole_process(argv) for _ in range(runs)), key=lambda r: r[1])
        print(f"{label:24s} {best[0]:6.3f} s  {best[1]:6.3f} s CPU  exit {best[3]}")


def print_batch(count: int, frames: int) -> None:
    """``count`` copies of a drive of ``frames`` frames as one archive: --jobs 1, --jobs 2 and a
    2-worker Dask LocalCluster (wall seconds; the cluster's start-up not counted)."""
    drive = make_log(frames)
    with tempfile.TemporaryDirectory() as folder:
        for i in range(count):
            (Path(folder) / f"drive{i:02d}.log").symlink_to(drive)
        base = [sys.executable, "-m", "odocan", "analyze", folder]
        print(f"archive of {count} logs of {frames} frames (symlinks to one drive)")
        for jobs in (1, 2):
            wall, cpu, _, code = whole_process([*base, "--jobs", str(jobs)])
            print(f"  --jobs {jobs}               {wall:8.2f} s  {cpu:8.2f} s CPU  exit {code}")
        try:
            from distributed import LocalCluster
        except ImportError:
            print("  dask: not installed (pip install 'odocan[dask]')")
            return
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster:
            wall, _, _, code = whole_process([*base, "--dask", cluster.scheduler_address])
            print(f"  --dask (2 workers)     {wall:8.2f} s  (CPU in the workers)  exit {code}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--frames", type=int, default=1_000_000, help="log size (frames)")
    parser.add_argument("--log", type=Path, help="use this candump log instead of making one")
    parser.add_argument("--no-cli", action="store_true", help="skip the cantools CLI run")
    parser.add_argument("--runs", type=int, default=3,
                        help="whole-process pairs (odocan, cantools); start-up: runs (best kept)")
    parser.add_argument("--batch", type=int, default=0, metavar="N",
                        help="also time an archive of N logs (0: not)")
    parser.add_argument("--batch-frames", type=int, default=36_000, help="frames per batch log")
    parser.add_argument("--whole-only", action="store_true",
                        help="only the whole-process figures (and --batch)")
    parser.add_argument("--startup", action="store_true",
                        help="only the start-up figures (--version, analyze on 720 frames)")
    args = parser.parse_args()
    if args.startup:
        print_startup(args.runs)
        return
    path = args.log or make_log(args.frames)
    if args.whole_only:
        print_whole_processes(path, sum(1 for _ in path.open("rb")), args.runs, not args.no_cli)
        if args.batch:
            print_batch(args.batch, args.batch_frames)
        return
    t_read, t_analyze, frames, passed = time_odocan(path)
    n = len(frames)
    ours = t_read + t_analyze
    size_mb = path.stat().st_size / 1e6
    print(f"log: {path}, {n} frames, {size_mb:.0f} MB")
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
    print_whole_processes(path, n, args.runs, not args.no_cli)
    if args.batch:
        print_batch(args.batch, args.batch_frames)


if __name__ == "__main__":
    main()
