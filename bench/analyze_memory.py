"""Max RSS and frames/s of ``odocan analyze`` against ``cantools decode`` on a big candump log.

Builds a log of about ``--gb`` GB (default 1) by concatenating one lockstep drive (``--drive-s``
seconds of the rig's ``random`` scenario on pmir, made once) again and again, each copy's
timestamps shifted to follow the previous one: every copy starts with a firmware power-up, so
the analysis sees a reboot at each seam (``host.judge.reboots``) and judges every life from its
power-up pose -- the verdict must stay PASS (``--set-pose-s S``: the host sets the pose S s
into the drive, so every copy is also cut there: ``host.judge.stream_cuts``). Then runs, as
whole processes measured like ``/usr/bin/time -v`` (``os.wait4``: wall, user + system CPU, max RSS):

* ``python -m odocan analyze LOG --robot pmir --stream always`` (streamed:
  ``host.judge.stream_analysis``), and ``--stream never`` (the whole log) with ``--whole``;
* ``cantools decode --single-line dbc/odocan.dbc < LOG`` (skipped with ``--no-cantools``);
* the first pass's stages alone, chunk by chunk over the whole log as one life
  (``host.judge.stream``: ``iter_log`` -> E2E -> encoder sequence -> on-board samples and the
  reference's steps and increments; ``stream_stalls``, ``stream_truth``, ``stream_twist``,
  ``stream_facts``, ``stream_lives``), in a child process of their own; it prints what it
  found.

The log is written to ``--dir`` (default: the system's temporary directory; check ``df -h``
first: it needs ``--gb`` GB free) and deleted afterwards (``--keep`` keeps it). Prints figures;
asserts nothing. Run: ``.venv/bin/python bench/analyze_memory.py [--gb 1] [--no-cantools]``.

``--threshold MB MB ...``: instead, the whole-log path's max RSS on logs of those sizes in each
format (the first MB of one long drive: a single life, the whole path's worst case; .log, then
the same frames as .asc and .blf through python-can), a line fitted per
format (base + MB/MB of log) and the size where it reaches the 300 MB target divided by the
margin: what ``stream_analysis.WHOLE_RSS_MB`` holds and where ``--stream auto`` starts to stream;
and ``--stream auto`` itself on each log (whichever path it chose: its max RSS).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import can  # noqa: E402

from odocan.sim.contract import DBC_PATH  # noqa: E402
from odocan.sim.rig import LockstepRig, RigConfig  # noqa: E402
from odocan.sim.robot import load  # noqa: E402

ROBOT = "pmir"
_STAMP = re.compile(rb"^\((\d+)\.(\d{6})\)")


def make_drive(seconds: float, path: Path, set_pose_s: float | None = None) -> Path:
    """One drive of the lockstep rig as a candump log; ``set_pose_s``: at that time the host
    sets the pose (ODOM_SET_POSE X, Y, HEADING, APPLY, each ACKed: the judges cut the life
    there, ``host.judge.setposes``, ``stream_cuts``)."""
    from odocan.host.protocol.heard import Recorder
    from odocan.host.protocol.session import CommandSession
    from odocan.sim.board import TICK_S
    from odocan.sim.contract import database

    logger, heard = can.Logger(str(path)), Recorder(database())
    with LockstepRig(RigConfig(load(ROBOT), "exact", "random", 1), [logger, heard]) as rig:
        if set_pose_s is not None and 0 < set_pose_s < seconds:
            rig.run(set_pose_s)
            CommandSession(heard, rig.send, rig.run_until, ack_timeout_s=0.5).set_pose(
                1.2345, -0.6789, 1.0)
        rig.run(seconds - rig.ticks * TICK_S)
    return path


def concatenate(drive: Path, target_bytes: int, out: Path) -> tuple[int, int]:
    """Copies of ``drive`` one after the other (timestamps shifted by whole drives, in
    microseconds so that the text keeps 6 decimals) until ``target_bytes``; (copies, frames)."""
    lines = drive.read_bytes().splitlines(keepends=True)
    stamps = [_STAMP.match(line) for line in lines]
    micros = [int(m.group(1)) * 1_000_000 + int(m.group(2)) if m else 0 for m in stamps]
    span_us = micros[-1] - micros[0] + 10_000
    size = copies = frames = 0
    with out.open("wb") as f:
        while size < target_bytes:
            shift = copies * span_us
            chunk = b"".join(
                b"(%d.%06d)" % divmod(us + shift, 1_000_000) + line[m.end():] if m else line
                for line, m, us in zip(lines, stamps, micros, strict=True)
            )
            f.write(chunk)
            size += len(chunk)
            copies += 1
            frames += len(lines)
    return copies, frames


TIME = Path("/usr/bin/time")  # GNU time: the child's own max RSS (%M), see whole_process


def whole_process(
    argv: list[str], stdin: Path | None = None, *, show: bool = False
) -> tuple[float, float, float, int]:
    """Wall s, CPU s (user + system), max RSS MB and exit code of ``argv`` (stdout dropped
    unless ``show``). The max RSS is GNU time's %M of ``argv`` when /usr/bin/time is there:
    ``os.wait4``'s ru_maxrss of a child that Python spawned (vfork) counts this process's own
    RSS at the spawn, which is large here while a log is built."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    stdin_file = stdin.open("rb") if stdin is not None else subprocess.DEVNULL
    with tempfile.NamedTemporaryFile("r", suffix=".rss") as rss_file:
        timed = ["/usr/bin/time", "-f", "%M", "-o", rss_file.name, *argv] if TIME.exists() else argv
        start = time.perf_counter()
        child = subprocess.Popen(timed, stdin=stdin_file,
                                 stdout=None if show else subprocess.DEVNULL, env=env)
        _, status, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - start
        text = Path(rss_file.name).read_text().split()
        rss_mb = int(text[-1]) / 1024 if TIME.exists() and text else usage.ru_maxrss / 1024
    if stdin is not None:
        stdin_file.close()  # type: ignore[union-attr]
    return (wall, usage.ru_utime + usage.ru_stime, rss_mb, os.waitstatus_to_exitcode(status))


def stream_stages(log: Path) -> None:
    """The streaming stages over ``log`` (run in the child process, the whole log as one
    life): prints what they found."""
    from odocan.host.io.logs import iter_log
    from odocan.host.judge.reference import Geometry
    from odocan.host.judge.stream import (
        StreamE2E,
        StreamEncoders,
        StreamPoses,
        StreamReference,
    )
    from odocan.host.judge.stream_facts import StreamFacts
    from odocan.host.judge.stream_lives import StreamLives
    from odocan.host.judge.stream_stalls import StreamStalls
    from odocan.host.judge.stream_truth import StreamTruth
    from odocan.host.judge.stream_twist import StreamTwist
    from odocan.host.protocol.decode import BulkDecoder
    from odocan.sim.contract import database

    db, profile = database(), load(ROBOT)
    e2e, numbering, poses = StreamE2E(db), StreamEncoders(BulkDecoder(db)), StreamPoses(
        BulkDecoder(db))
    reference = StreamReference(Geometry.of(profile), "exact", min(profile.counter_bits, 24),
                                profile.max_wheel_speed_mm_s)
    truth, twist = StreamTruth(BulkDecoder(db)), StreamTwist(BulkDecoder(db), profile)
    facts, lives = StreamFacts(BulkDecoder(db)), StreamLives(BulkDecoder(db))
    stalls: StreamStalls | None = None
    samples = truths = 0
    for chunk in iter_log(log):
        accepted = e2e.feed(chunk)
        enc = numbering.feed(chunk, accepted)
        stalls = stalls or StreamStalls(enc.cycle_s)
        reference.feed(enc)
        onboard, sent = poses.feed(chunk, accepted, enc)
        watermark = min(float(chunk.timestamp_s[-1]), poses.open_sent_s())
        samples += len(stalls.feed(onboard, sent, enc.timestamp_s, watermark)["enc"])
        truths += len(truth.feed(chunk, accepted, enc)[0]["enc"])
        twist.feed(chunk, accepted, enc)
        facts.feed(chunk, accepted)
        lives.feed(chunk, accepted)
    assert stalls is not None
    onboard, sent = poses.finish()
    samples += len(stalls.feed(onboard, sent, numbering_empty(), float("inf"))["enc"])
    samples += len(stalls.finish()["enc"])
    truths += len(truth.finish()[0]["enc"])
    print(f"{samples} on-board samples after {len(stalls.breaks)} stalls (exact: "
          f"{stalls.exact}), {poses.unmatched} unmatched, {len(reference.reprimed)} counter "
          f"restarts, {truths} truth samples, twist {twist.finish()}, "
          f"{len(lives.finish())} lives, {facts.covered_s():.1f} s covered")


def numbering_empty() -> Any:
    """No encoder frame (the stalls' last feed)."""
    import numpy as np
    return np.zeros(0)


def report(label: str, frames: int, figures: tuple[float, float, float, int]) -> None:
    wall, cpu, rss_mb, code = figures
    print(f"{label:<26} {wall:8.1f} s wall {cpu:8.1f} s CPU {rss_mb:8.0f} MB max RSS "
          f"{frames / wall / 1e6:6.2f} M frames/s  exit {code}", flush=True)


def threshold(sizes_mb: list[float], drive_s: float, directory: Path) -> None:
    """The whole-log path's max RSS per format and size, the fitted lines and the sizes
    where ``--stream auto`` streams (module docstring)."""
    from odocan.host.judge.stream_analysis import RSS_MARGIN, RSS_TARGET_MB

    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        # one life (the whole path's worst case: its arrays span the life), long enough
        drive_s = max(drive_s, max(sizes_mb) * 1e6 / CANDUMP_BYTES_PER_S * 1.05)
        drive = make_drive(drive_s, Path(tmp) / "drive.log")
        rows: dict[str, list[tuple[float, float]]] = {}
        for mb in sizes_mb:
            log = Path(tmp) / f"t{mb:g}.log"
            frames = head(drive, int(mb * 1e6), log)
            for suffix in (".log", ".asc", ".blf"):
                path = log if suffix == ".log" else convert(log, suffix)
                size_mb = path.stat().st_size / 1e6
                argv = [sys.executable, "-m", "odocan", "analyze", str(path), "--robot", ROBOT,
                        "--stream", "never"]
                wall, cpu, rss, code = whole_process(argv)
                rows.setdefault(suffix, []).append((size_mb, rss))
                print(f"whole {suffix:<5} {size_mb:8.1f} MB {frames:9d} frames {wall:7.1f} s "
                      f"wall {cpu:7.1f} s CPU {rss:7.0f} MB max RSS  "
                      f"{rss / size_mb:5.2f} MB/MB  exit {code}", flush=True)
                wall, cpu, rss, code = whole_process([*argv[:-1], "auto"])
                print(f"auto  {suffix:<5} {size_mb:8.1f} MB {frames:9d} frames {wall:7.1f} s "
                      f"wall {cpu:7.1f} s CPU {rss:7.0f} MB max RSS  exit {code}", flush=True)
                if path != log:
                    path.unlink()
            log.unlink()
    for suffix, points in rows.items():
        (s0, r0), (s1, r1) = points[0], points[-1]
        per_mb = (r1 - r0) / (s1 - s0)
        base = r0 - per_mb * s0
        above = (RSS_TARGET_MB / RSS_MARGIN - base) / per_mb
        print(f"{suffix:<5} max RSS = {base:.1f} MB + {per_mb:.3f} x MB of log; streams above "
              f"{above:.0f} MB (whole path there: {RSS_TARGET_MB / RSS_MARGIN:.0f} MB, target "
              f"{RSS_TARGET_MB:.0f} MB / margin {RSS_MARGIN:g})")


CANDUMP_BYTES_PER_S = 15_400  # the rig's candump log: 360 frames/s of about 43 bytes


def head(drive: Path, target_bytes: int, out: Path) -> int:
    """The first lines of ``drive`` up to ``target_bytes`` into ``out``; how many."""
    lines, size = [], 0
    with drive.open("rb") as f:
        for line in f:
            if size + len(line) > target_bytes:
                break
            lines.append(line)
            size += len(line)
    out.write_bytes(b"".join(lines))
    return len(lines)


def convert(log: Path, suffix: str) -> Path:
    """``log``'s frames in another format (python-can's reader and writer)."""
    out = log.with_suffix(suffix)
    with can.Logger(str(out)) as writer:
        for message in can.LogReader(str(log)):
            writer.on_message_received(message)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gb", type=float, default=1.0, help="log size in GB (1e9 bytes)")
    parser.add_argument("--drive-s", type=float, default=600.0, help="seconds of one drive")
    parser.add_argument("--set-pose-s", type=float, metavar="S",
                        help="the host sets the pose S s into the drive (in every copy)")
    parser.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()))
    parser.add_argument("--no-cantools", action="store_true")
    parser.add_argument("--keep", action="store_true", help="keep the log")
    parser.add_argument("--whole", action="store_true",
                        help="also the whole-log path (--stream never) on the big log")
    parser.add_argument("--threshold", type=float, nargs="+", metavar="MB",
                        help="measure the whole path's max RSS at these log sizes instead")
    parser.add_argument("--stream-child", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.stream_child is not None:
        stream_stages(args.stream_child)
        return
    if args.threshold:
        threshold(args.threshold, 0.0, args.dir)
        return
    log = args.dir / f"odocan_bench_{args.gb:g}gb.log"
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        drive = make_drive(args.drive_s, Path(tmp) / "drive.log", args.set_pose_s)
        copies, frames = concatenate(drive, int(args.gb * 1e9), log)
    print(f"{log}: {log.stat().st_size / 1e9:.2f} GB, {frames} frames, {copies} drives of "
          f"{args.drive_s:g} s (made in {time.perf_counter() - start:.0f} s)", flush=True)
    try:
        odocan = [sys.executable, "-m", "odocan", "analyze", str(log), "--robot", ROBOT]
        report("odocan analyze (streamed)", frames, whole_process([*odocan, "--stream", "always"]))
        if args.whole:
            report("odocan analyze (whole)", frames, whole_process([*odocan, "--stream", "never"]))
        stages = [sys.executable, __file__, "--stream-child", str(log)]
        report("streamed stages", frames, whole_process(stages, show=True))
        if not args.no_cantools:
            cantools = [str(Path(sys.executable).parent / "cantools"), "decode",
                        "--single-line", str(DBC_PATH)]
            report("cantools decode < LOG", frames, whole_process(cantools, stdin=log))
    finally:
        if not args.keep:
            log.unlink()


if __name__ == "__main__":
    main()
