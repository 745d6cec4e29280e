"""A loaded recorder's stamps never make the live judge FAIL a correct firmware (issue #11, rule 5),
and it still FAILs a wrong one.

The monitor's own recording of a replayed drive on a loaded machine (all its frames, in the
drive's order) stamps each frame when the recorder's process wakes: the frames since the last
wake-up get one instant's stamps, 0..87 ms late (measured against the drive played: 615 frames
on time, the rest late in bunches, every wake-up within about 35 ms of the last). There the
firmware's poses look stalled or held again and again (17 to 35 placements in 20 s), and the live
judge said "pose wrong in 5 episodes, worst 0.1739 mm beyond allowance" where ``analyze`` PASSed
with 0.0697 mm: the start fit anchored at each placement (``livefit.LiveFit.carried``) moved the
reference by up to half an LSB on each axis, taken into it at the next placement
(``livefit.rebase``) but not counted in the placements' offset, so the reference walked 0.24 mm
from where it started while the placements' bound (a budget the firmware's pages had proven 0)
held the offset asked to 0.1 mm.

Here the same drive (``run --robot pmir --duration 20 --seed 0``, the played log's) is stamped by
a recorder that wakes at seeded random intervals of 0..35 ms (each frame stamped at the first
wake-up at or after its bus time, bus order kept).
"""

from __future__ import annotations

import random
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.livegapseen import end_of_watch
from odocan.host.judge.monitor import BusMonitor
from odocan.sim.robot import load
from tests.test_reorder import _off_by_two

DRIVE = ["run", "--robot", "pmir", "--duration", "20", "--seed", "0"]
MAX_SLEEP_S = 0.035  # the recorder's wake-ups at most this far apart (uniform)
STAMP_SEED = 1  # (seed 0 too: 5 episodes before the fix; seeds 2, 4, 5 none)


def _woken(log: Path, out: Path, seed: int) -> None:
    """``log`` (candump text) stamped by a recorder waking at random intervals of up to
    ``MAX_SLEEP_S``: each frame at the first wake-up at or after its bus time, the frames of one
    wake-up 10 us apart (bus order kept)."""
    rnd = random.Random(seed)
    lines, wake_s, last_s = [], 0.0, -1.0
    for line in log.read_text().splitlines():
        parts = line.split()
        bus_s = float(parts[0].strip("()"))
        while wake_s < bus_s:
            wake_s += rnd.uniform(0.0, MAX_SLEEP_S)
        last_s = max(wake_s, last_s + 1e-5)
        lines.append(" ".join([f"({last_s:.6f})", *parts[1:]]))
    out.write_text("\n".join(lines) + "\n")


def _live_wrongs(path: Path) -> int:
    """The monitor model's POSE WRONG episodes on ``path`` (its verdict at the end of watch)."""
    monitor = BusMonitor(load("pmir"))
    with can.LogReader(path) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
    tracker = monitor.tracker
    end_of_watch(tracker)
    tracker.wrongs.finish(tracker.allowance_m)
    return tracker.wrongs.count


@pytest.mark.parametrize("wrong", [None, "X"])
def test_loaded_recorder_stamps(tmp_path: Path, wrong: str | None) -> None:
    log, woken = tmp_path / "drive.log", tmp_path / "woken.log"
    with _off_by_two(wrong):
        assert main([*DRIVE, "--log", str(log)]) == (wrong is not None)  # run judges it too
    _woken(log, woken, STAMP_SEED)
    frames = [line.split()[1:] for line in log.read_text().splitlines()]
    assert [line.split()[1:] for line in woken.read_text().splitlines()] == frames
    late_s = [float(b.split()[0].strip("()")) - float(a.split()[0].strip("()"))
              for a, b in zip(log.read_text().splitlines(), woken.read_text().splitlines(),
                              strict=True)]
    assert min(late_s) >= 0.0  # only late (the frames and their order kept)
    assert max(late_s) < MAX_SLEEP_S + 0.01
    assert analyze(read_log(woken), load("pmir")).passed is (wrong is None)
    wrongs = _live_wrongs(woken)
    assert (wrongs == 0) if wrong is None else (wrongs > 0)
