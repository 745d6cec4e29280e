"""A recorder chunk of 32 k + s periods, read in a burst, never FAILs a correct firmware: the
firmware's ODOM_STATUS pages number the hole (issue #11, rule 5; ``host.judge.holepages``).

Such a chunk takes 16 k poses (one every other period) and brings their COUNTER round, so the
poses around it look consecutive and the burst after it was read as a busy bus's: the hole was
numbered 32 k periods short, and the whole-log and streamed judges FAILed a correct kobuki and
pmir (chunks of 33, 65, 34 and 97 periods; all three judges FAILed). The numbers are checked
here against the complete log (the encoder frames' places in it: nothing of the judge), and
the verdicts against ``tests.independent_checker`` (float64 odometry and cantools).

The live judge (the monitor's model) FAILed the correct firmware (25 mm): its pages after a
hole come 0.6 s after it; its samples after such a hole now wait for them
(``host.judge.livelaphold``, ``livepagelaps``).
"""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest

import tests.test_recorder_holes as holes
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.holepages import page_numbered
from odocan.host.judge.samples import encoder_frames
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import load
from tests.independent_checker import check
from tests.test_capture_jitter import _live_passes
from tests.test_live_reboot import bridge_of
from tests.test_recorder_gap16 import _robot
from tests.test_reorder import _off_by_two

# (start s, periods between the encoder frames kept, periods the frame before is stamped late,
# periods after it read at once): chunks that bring the poses' COUNTER round (16 k sends)
LAPPED = ((1.0, 33, 1, 3), (2.5, 65, 1, 3), (4.0, 34, 2, 3), (5.0, 97, 1, 3))


def _holed_drive(tmp_path: Path, robot: str, wrong: str | None,
                 monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Path]:
    clean, holed = tmp_path / "clean.log", tmp_path / "holed.log"
    with _off_by_two(wrong):
        main(["run", "--robot", robot, "--scenario", "random", "--duration", "7", "--seed", "3",
              "--log", str(clean), "--firmware", "python"])  # patched: never auto's C
    monkeypatch.setattr(holes, "HOLES", LAPPED)
    holes._holed(clean, holed)
    return clean, holed


def _true_steps(clean: Path, holed: Path) -> list[int]:
    """The periods between the holed log's encoder frames, from their places in the complete
    log (each line of the holed log is one of the complete log's, in order)."""
    full = clean.read_text().splitlines()
    kept = holed.read_text().splitlines()
    places, j = [], 0
    for line in kept:
        while full[j].split(")", 1)[1] != line.split(")", 1)[1]:
            j += 1
        if " 100#" in line:
            places.append(j)
        j += 1
    order = {p: n for n, p in enumerate(i for i, line in enumerate(full) if " 100#" in line)}
    return [order[b] - order[a] for a, b in pairwise(places)]


@pytest.mark.parametrize("robot", ["kobuki", "pmir"])
def test_lapped_holes_are_numbered_by_the_pages(
    tmp_path: Path, robot: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    clean, holed = _holed_drive(tmp_path, robot, None, monkeypatch)
    frames, db = read_log(holed), default_plan()
    decoder = BulkDecoder(db)
    _, accepted = check_frames(frames, db)
    enc = page_numbered(frames, decoder, encoder_frames(frames, accepted, decoder))
    true = _true_steps(clean, holed)
    assert len(enc.seq) == len(true) + 1  # every encoder frame of the holed log accepted
    assert sorted(s for s in true if s > 1) == [33, 34, 65, 97]
    assert np.diff(enc.seq).tolist() == true


@pytest.mark.parametrize("robot", ["kobuki", "pmir"])
def test_a_correct_firmware_passes_lapped_holes(
    tmp_path: Path, robot: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    clean, holed = _holed_drive(tmp_path, robot, None, monkeypatch)
    assert check(clean, _robot(robot), "exact", lambda _t: (0.0, 0.0, 0.0)).passed
    assert analyze(read_log(holed), load(robot), "exact").passed
    assert main(["analyze", str(holed), "--robot", robot, "--stream", "always"]) == 0


@pytest.mark.parametrize("robot", ["kobuki", "pmir"])
def test_the_live_judges_pass_lapped_holes(
    tmp_path: Path, robot: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The monitor's model and the bridge give analyze's PASS (one judge). Kobuki was never
    run live: its chunk at 4 s (34 periods) waited behind the one before for 56 frames, its
    burst had left the window's latest rows when asked, so it was numbered 2 periods without
    waiting for its pages: placed 1.8 mm short, POSE WRONG on a correct firmware
    (``livelaphold._read_at_once``)."""
    _, holed = _holed_drive(tmp_path, robot, None, monkeypatch)
    assert analyze(read_log(holed), load(robot), "exact").passed
    assert _live_passes(holed, robot)
    bridge = bridge_of(holed, robot, "exact")
    assert bridge.tracker.wrongs.count == 0
    assert bridge.tracker.vs_reference.max_dpos_m <= POSITION_LSB_M


@pytest.mark.parametrize(("robot", "wrong"), [("kobuki", "X"), ("pmir", "HEADING")])
def test_a_pose_two_lsb_off_fails_lapped_holes(
    tmp_path: Path, robot: str, wrong: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    clean, holed = _holed_drive(tmp_path, robot, wrong, monkeypatch)
    assert not check(clean, _robot(robot), "exact", lambda _t: (0.0, 0.0, 0.0)).passed
    assert not analyze(read_log(holed), load(robot), "exact").passed
    assert main(["analyze", str(holed), "--robot", robot, "--stream", "always"]) != 0
    assert not _live_passes(holed, robot)
