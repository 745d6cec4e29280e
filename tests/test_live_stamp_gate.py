"""The live judges' stamp gate (``host.judge.livestampgate``; issue #11, one judge): the
monitor and the bridge set aside the frames the log's readers set aside
(``host.io.stampglitch``), by the same rule (``host.io.stamprule``); a pose 10 mm off beside a
glitched stamp still FAILs live; a paused recorder is no glitch live either. The drive and its
edits are tests/test_log_stamp_span.py's."""

from __future__ import annotations

import itertools
import random
from collections import deque
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

from odocan.host.io.frames import FrameArrays
from odocan.host.io.stampglitch import StampGlitches
from odocan.host.io.stamprule import MAX_SET_ASIDE
from odocan.host.judge.livestampgate import StampGate
from odocan.host.judge.watchend import end_watch
from tests.judges_cli import both_analyses, fails_by_position, live_judges, raise_x_10_mm
from tests.test_log_stamp_span import GLITCHED, _glitched, _restamped, _write, drive

__all__ = ["drive"]  # (the module's fixture, shared)


def _gated(times_s: list[float]) -> tuple[list[int], int]:
    """``times_s`` through a ``StampGate`` frame by frame, flushed: the frames passed on (their
    positions, in order) and the count set aside."""
    gate = StampGate[int](deque())
    out: list[int] = []
    for k, t_s in enumerate(times_s):
        out += [k] if gate.passes(t_s) else gate.take(t_s, k)
    return out + gate.flush(), gate.count


def _read(times_s: list[float], parts: int) -> list[float]:
    """The stamps ``StampGlitches`` keeps of ``times_s``: whole (``parts`` 0) or streamed in
    ``parts`` parts."""
    n = len(times_s)
    frames = FrameArrays(timestamp_s=np.array(times_s), can_id=np.zeros(n, np.uint32),
                         dlc=np.zeros(n, np.uint8), data=np.zeros((n, 8), np.uint8),
                         flags=np.zeros(n, np.uint8))
    if parts == 0:
        return [float(t) for t in StampGlitches().whole(frames).timestamp_s]
    cuts = sorted({0, n, *random.Random(parts).sample(range(1, n), min(parts, n - 1))})
    kept = StampGlitches().through(frames.select(slice(a, b)) for a, b in itertools.pairwise(cuts))
    return [t for part in kept for t in part.timestamp_s.tolist()]


@pytest.mark.parametrize("seed", range(40))
def test_the_gate_keeps_what_the_readers_keep(seed: int) -> None:
    """Random stamps, glitches, pauses and runs: the gate passes the frames the readers keep
    (whole and streamed), in order; a frame within 1 s of the one before is never held."""
    rng = random.Random(seed)
    times_s, t_s = [], 0.0
    for _ in range(rng.randrange(1, 80)):
        t_s += 0.01
        roll = rng.random()
        if roll < 0.08:
            times_s.append(t_s + rng.choice([-1e3, 1e3, 5.0, -1.5]))  # a glitch
        elif roll < 0.12:
            t_s += rng.choice([2.0, 1e5])  # a pause: every later frame
            times_s.append(t_s)
        else:
            times_s.append(t_s)
    passed, _ = _gated(times_s)
    assert passed == sorted(passed)
    kept = [times_s[k] for k in passed]
    assert kept == _read(times_s, 0) == _read(times_s, 5), times_s


def test_the_gate_sets_aside_at_most_the_readers_count() -> None:
    """Every other frame glitched: ``MAX_SET_ASIDE`` set aside, the rest passed, as read."""
    times_s = [k * 0.01 + (1e3 if k % 2 else 0.0) for k in range(2 * MAX_SET_ASIDE + 8)]
    passed, count = _gated(times_s)
    assert count == MAX_SET_ASIDE
    assert [times_s[k] for k in passed] == _read(times_s, 0)


def test_the_frame_held_at_the_end_is_judged() -> None:
    """The last frame 5 s after the one before (no next to tell): held, given at the end."""
    gate = StampGate[int](deque())
    assert gate.passes(0.0)
    assert gate.passes(0.5)
    assert gate.take(5.5, 2) == []
    assert gate.flush() == [2]
    assert gate.flush() == []
    assert gate.count == 0


def _ended(robot: str, path: Path) -> tuple[Any, Any]:
    """``live_judges`` then the watch's end (the gate's frame, the holds, what waits)."""
    monitor, bridge = live_judges(robot, path)
    monitor.release_held()
    end_watch(monitor.tracker, monitor.distance)
    bridge.end_watch()
    return monitor, bridge


@pytest.mark.parametrize("jump_s", [1000.0, 1e6])  # (a .log cannot stamp before 0)
def test_a_10_mm_pose_still_fails_live_beside_a_glitched_stamp(
    drive: tuple[Path, list[can.Message]], jump_s: float, tmp_path: Path,
) -> None:
    """X raised 10 mm from 2 s on, one encoder frame's stamp glitched: the monitor and the
    bridge say POSE WRONG by the position (more than 5 mm beyond), as ``analyze`` FAILs."""
    log, _ = drive
    tampered = tmp_path / "tampered.log"
    assert raise_x_10_mm(log, tampered, 2.0) > 100
    glitched = _glitched(list(can.LogReader(str(tampered))), tmp_path / "glitched.log", jump_s)
    assert fails_by_position(glitched, tmp_path) == []
    for judge in _ended("kobuki", glitched):
        assert judge.stamps.count == 1
        assert judge.tracker.wrongs.count > 0
        assert judge.tracker.max_beyond_allowance_m > 5e-3, judge.tracker.max_beyond_allowance_m


def test_a_paused_recorder_is_no_glitch_live(
    drive: tuple[Path, list[can.Message]], tmp_path: Path,
) -> None:
    """Every frame from ``GLITCHED`` on 1e8 s later (a recorder paused): nothing set aside, the
    frame after the pause held one frame only, the drive's verdict live."""
    _, frames = drive
    paused = _write([m if k < GLITCHED else _restamped(m, m.timestamp + 1e8)
                     for k, m in enumerate(frames)], tmp_path / "paused.csv")
    for judge in _ended("kobuki", paused):
        assert judge.stamps.count == 0
        assert judge.stamps.event is None
        assert judge.stamps.frames == len(frames)
        assert judge.stamps.flush() == []
        assert judge.tracker.wrongs.count == 0
        assert not any(e["kind"] == "stamp_glitch" for e in judge.events)


def _run(frames: list[can.Message], path: Path, jump_s: float, run: int) -> Path:
    """``frames`` with ``run`` frames from ``GLITCHED`` on stamped ``jump_s`` off, written."""
    return _write([_restamped(m, m.timestamp + jump_s) if GLITCHED <= k < GLITCHED + run else m
                   for k, m in enumerate(frames)], path)


@pytest.mark.xfail(strict=True, reason=(
    "a run of 2 glitched stamps is taken as recorded by all four judges alike (the readers' "
    "rule, stampglitch/stamprule.lone, sets aside a frame far off BOTH its neighbours; in a run "
    "each frame's neighbour is the other, within 1 ms): frames 242-243 1000 s ahead FAIL the "
    "correct drive, analyze whole and streamed, the monitor and the bridge each 'ODOM_TWIST "
    "DISTANCE off the reference's path length by 3.053 mm beyond its tolerance' (a 1000 s "
    "silence, a re-prime); 1000 s behind, 2.968 mm, and the live pose 3.035 mm beyond (POSE "
    "WRONG); a run of 3: the same. Setting runs aside needs the rule widened to a run far off "
    "both outer neighbours (bounded length), in the readers and the gate alike: not this pass"))
@pytest.mark.parametrize("jump_s", [1000.0])
def test_a_run_of_two_glitched_stamps_passes(
    drive: tuple[Path, list[can.Message]], jump_s: float, tmp_path: Path,
) -> None:
    _, frames = drive
    path = _run(frames, tmp_path / "run2.csv", jump_s, 2)
    assert both_analyses(path) == [0, 0]
    for judge in _ended("kobuki", path):
        assert judge.distance.verdict() == [], judge.distance.verdict()
        assert judge.tracker.wrongs.count == 0
