"""A pose made in a sender's flood, named by its HEADING (issue #11; ``host.judge.floodnames``).

After a 1 s or 6 s pause on the circle the firmware's first pose after the flood names frame
``AT + 16`` (its mailbox's last) by ENC_COUNTER, and frames ``AT``, ``AT + 32``, ... of that
COUNTER came in the same flood: the judges paired it with the latest (397 mm, 1.98 m off a
correct firmware). The pose's HEADING is the exact function of the counts from the pose before
the flood, so it picks the frame, only when exactly one candidate matches within 2 LSB.

Choosing the frame by the pose must not let a wrong pose pass: a position error moves no
heading (the pose keeps its frame and FAILs, 10 mm either way); a heading forged to another
candidate's gets that frame's reference, laps of travel from the position shown (FAIL); a
heading matching none keeps the plain rule's name (FAIL). Truth by the tests' float64 odometry
(``tests.independent_checker``) on cantools-decoded frames."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge import floodnames
from odocan.host.judge.analysis import analyze
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import HEADING_LSB_RAD
from odocan.host.mqtt.endverdict import end_verdict
from odocan.sim.board import TICK_S
from tests.sim_backlog import PMIR
from tests.test_first_second_reboot import _decoded, _reencoded, _written
from tests.test_sim_backlog_flood import AT, KEPT, _flood
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live

PAUSES = (100, 600)  # 1 s, 6 s: the latest frame of the pose's COUNTER is laps on


def _flood_pose(messages: tuple[can.Message, ...], paused: int) -> can.Message:
    """The firmware's first ODOM_POSE_X after the flood."""
    return next(m for m in messages if m.arbitration_id == fr.ODOM_POSE_X_ID
                and m.timestamp >= (AT + paused) * TICK_S)


def _heading_at(messages: tuple[can.Message, ...], last: int) -> float:
    """The float64 odometry's heading (rad) on encoder frames 0 .. ``last`` one by one."""
    enc = [_decoded(m) for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    return _odometry(enc, list(range(last + 1))).heading


def _forged(messages: tuple[can.Message, ...], target: can.Message, **change: int
            ) -> tuple[can.Message, ...]:
    """``messages`` with the pose ``target``'s signals moved by ``change`` (raw LSB; HEADING
    mod 2^16), E2E re-protected."""
    out = []
    for m in messages:
        if m is target:
            signals: dict[str, Any] = _decoded(m)
            for name, lsb in change.items():
                signals[name] = (signals[name] + lsb) % 65536 if name == "HEADING" else (
                    signals[name] + lsb)
            m = _reencoded(m, signals, fr.ODOM_POSE_X_DATA_IDS)
        out.append(m)
    return tuple(out)


@pytest.mark.parametrize("paused", PAUSES)
def test_the_flood_pose_is_the_mailboxs_last_frame(paused: int) -> None:
    """The premise: that pose is frames 0 .. ``AT + 16`` one by one (within an LSB), and the
    frames a lap, two, ... after it of its COUNTER came in the flood, laps of travel away."""
    messages = _flood(paused)
    pose = _decoded(_flood_pose(messages, paused))
    assert int(pose["ENC_COUNTER"]) == (AT + KEPT - 1) % 16
    mine = _heading_at(messages, AT + KEPT - 1)
    assert abs(math.remainder(mine - pose["HEADING"] * HEADING_LSB_RAD, 2 * math.pi)
               ) <= HEADING_LSB_RAD
    lap = _heading_at(messages, AT + KEPT - 1 + 16) - mine
    assert abs(lap) > 100 * HEADING_LSB_RAD  # another candidate's heading: far from it


def _verdicts(messages: tuple[can.Message, ...], tmp_path: Path) -> tuple[bool | str, ...]:
    """Whether analyze whole and --stream PASSed, whether the monitor saw no wrong pose, twist
    or DISTANCE, and the bridge's end verdict (its watch ended)."""
    path = _written(messages, tmp_path / "flood.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    beyond = analysis.report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"]
    print(f"\nbeyond the allowance {beyond * 1e3:.3f} mm")
    streamed = main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                     "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(messages)
    bridge.end_watch()
    verdict = end_verdict(bridge)
    print(verdict.text)
    return (analysis.passed, streamed,
            monitor.health(end_s)["pose_wrongs"]["episodes"] == 0 and not monitor.twist.wrong
            and bool(monitor.distance.as_dict()["passed"]), verdict.verdict)


@pytest.mark.parametrize(("paused", "forge"), [
    *[(paused, forge) for paused in PAUSES for forge in ("x+10mm", "heading one lap on")],
    (100, "x-10mm"), (100, "heading +4 LSB")])
def test_a_wrong_flood_pose_fails_every_judge(paused: int, forge: str, tmp_path: Path) -> None:
    """Only the flood's pose wrong (every pose after it right): 10 mm X either way, its
    HEADING forged to the frame a lap after the one it is (the candidate it would then match),
    or 4 LSB off (matching none: the plain rule's name, laps off). analyze whole and streamed
    FAIL; live, after a 1 s pause the monitor sees the wrong pose and the bridge FAILs; after
    6 s the pose names (by its HEADING, forged or not) a frame beyond the live window (600
    frames back, its reference no longer kept): not judged there, the bridge's end verdict
    UNJUDGED, never a PASS."""
    messages = _flood(paused)
    target = _flood_pose(messages, paused)
    if forge.startswith("x"):
        change = {"X": 100 if forge == "x+10mm" else -100}
    elif forge == "heading +4 LSB":
        change = {"HEADING": 4}
    else:
        lap = (_heading_at(messages, AT + KEPT - 1 + 16)
               - _heading_at(messages, AT + KEPT - 1))
        change = {"HEADING": round(lap / HEADING_LSB_RAD)}
    whole, streamed, monitor_ok, bridge = _verdicts(_forged(messages, target, **change),
                                                    tmp_path)
    assert (whole, streamed) == (False, False)
    if paused == 600:
        assert bridge == "UNJUDGED"
    else:
        assert (monitor_ok, bridge) == (False, "FAIL")


def test_the_correct_firmware_after_six_s_is_unjudged_live_not_failed(tmp_path: Path) -> None:
    """The correct firmware after a 6 s pause: analyze PASSes; the bridge's end verdict is
    UNJUDGED (its flood pose names a frame beyond the live window), not a FAIL, not a PASS."""
    whole, streamed, monitor_ok, bridge = _verdicts(_flood(600), tmp_path)
    assert (whole, streamed, monitor_ok, bridge) == (True, True, True, "UNJUDGED")


def test_the_heading_picks_only_one_candidate() -> None:
    """``floodnames.pick``: the candidate within 2 LSB of the pose's HEADING when it alone is;
    none when two are (a straight line's laps), none when none is; a position never enters."""
    geometry = Geometry.of(PMIR)
    turn = floodnames.heading_bam(geometry, -100, 100)  # one candidate's heading change
    anchor = (0, 0, 1000)
    counts = [(0, 0), (-100, 100), (-200, 200)]
    assert turn > 100
    assert floodnames.pick(geometry, anchor, counts, round(1000 + turn)) == 1
    assert floodnames.pick(geometry, anchor, counts, round(1000 + turn) + 5) is None
    assert floodnames.pick(geometry, anchor, [(0, 0), (100, 100), (200, 200)], 1000) is None
    assert floodnames.pick(geometry, anchor, counts, round(1000 + 2 * turn - 1.5)) == 2


def test_a_name_without_doubt_is_not_touched() -> None:
    """Frames on time (16 cycles a lap apart): one candidate, the name as the plain rule gave
    it, whatever the HEADING says."""
    t_s = np.arange(64, dtype=np.float64) * 0.01
    seq = np.arange(64, dtype=np.int64)
    assert floodnames.candidates(seq, t_s, 60, 0.01, -1) == [60]
    burst = np.where(seq < 20, t_s, 0.2 + seq * 2e-6).astype(np.float64)
    assert floodnames.candidates(seq, burst, 60, 0.01, 19) == [60, 44, 28]
