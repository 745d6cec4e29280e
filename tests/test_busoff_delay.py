"""A bus-off with frames held back: the firmware's poses after it prove which encoder frames it
skipped (issue #11, rule 5: a FAIL must never blame a correct firmware).

``odocan run --robot kobuki --scenario random --seed 3 --duration 8 --faults
busoff=4:0.5,delay=0.2:30`` FAILed the project's correct firmware 1.7796 mm off the reference
(run, analyze whole and ``--stream always``). The bus is silent from 3.99 s to the recovery at
4.502816 s, when the encoder frame COUNTER 15 the delay held goes out; the firmware takes it
(one on from the 14 of 3.98 s) and, its window 0 again, refuses every frame after it (COUNTER 3
.. 15 of 4.51 .. 4.63 s, late 7 and 8 of 4.58 and 4.59 s included) until the 0 of 4.640 s, one
on: its ODOM_POSE_X sent on cadence at 4.521 .. 4.601 s all name ENC_COUNTER 15, and the one of
4.641 s is one exact arc of 243 mm from the 15 to the 0. The host's window, a period wider after
that late frame, took the late 7 and 8, split the arc in three and was 1.72 .. 1.78 mm off from
4.64 s on. The poses' proof was ignored: the first pose after the silence is 11 COUNTERs on
(27 sends in 0.54 s), not 1..7, so no pair after it proved anything until the firmware moved on
(``host.protocol.e2e_sends``). Seed 4 FAILed the same way (0.2883 mm); seeds 5, 6 PASSed (0.0616,
0.0602 mm), each at durations 8 and 12 s; all 8 PASS now (max 0.0629 mm).

The independent check decodes with cantools and integrates the arcs in its own float64 code.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from odocan.host.mqtt.endverdict import end_verdict
from tests.judges_cli import (
    both_analyses,
    correct_drive,
    fails_by_position,
    live_judges,
    raise_first_x,
    raw_signals,
)

FAULTS = "busoff=4:0.5,delay=0.2:30"
WHEEL_RADIUS_M, WHEELBASE_M, COUNTS_PER_REV, COUNTER_BITS = 0.035, 0.230, 2578, 16  # kobuki
HELD_S, MERGED_TO_S = 4.502816, 4.640  # the held COUNTER 15, the 0 the firmware took next
SPLIT_AT_S = (4.580, 4.590)  # the late COUNTER 7 and 8 the firmware refused
X_LSB_M, HEADING_LSB_RAD = 1e-4, 2 * math.pi / 65536  # the DBC's scales
Enc = tuple[float, int, int, int]  # bus time, COUNTER, LEFT_COUNT, RIGHT_COUNT


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The seed-3 drive, recorded with the firmware's every step watched (run exits 0 and its
    steps are within 1/1000 LSB of float64: ``tests.judges_cli.correct_drive``)."""
    log = tmp_path_factory.mktemp("busoff_delay") / "drive.log"
    return correct_drive(log, "kobuki", "random", 3, 8, FAULTS)


def _decoded(log: Path) -> tuple[list[Enc], list[tuple[float, dict[str, float]]]]:
    """The encoder frames and the ODOM_POSE_X frames (X m, HEADING rad, ENC_COUNTER) of ``log``,
    decoded raw by cantools and scaled here (0.1 mm, 2 pi / 65536 rad)."""
    enc: list[Enc] = []
    pose_x: list[tuple[float, dict[str, float]]] = []
    for t_s, name, raw in raw_signals(log, ("WHEEL_ENCODERS", "ODOM_POSE_X")):
        if name == "WHEEL_ENCODERS":
            enc.append((round(t_s, 6), int(raw["COUNTER"]), int(raw["LEFT_COUNT"]),
                        int(raw["RIGHT_COUNT"])))
        else:
            pose_x.append((round(t_s, 6), {"X": int(raw["X"]) * X_LSB_M,
                                           "HEADING": int(raw["HEADING"]) * HEADING_LSB_RAD,
                                           "ENC_COUNTER": float(raw["ENC_COUNTER"])}))
    return enc, pose_x


def _wheel_m(d_counts: int) -> float:
    half = 1 << (COUNTER_BITS - 1)
    return 2 * math.pi * WHEEL_RADIUS_M * ((d_counts + half) % (2 * half) - half) / COUNTS_PER_REV


def _arcs(x_m: float, heading_rad: float, frames: list[Enc]) -> float:
    """X after exact arcs through ``frames`` from (``x_m``, ``heading_rad``) at the first."""
    for a, b in itertools.pairwise(frames):
        left, right = _wheel_m(b[2] - a[2]), _wheel_m(b[3] - a[3])
        ds, dh = (left + right) / 2, (right - left) / WHEELBASE_M
        x_m += ds * math.cos(heading_rad) if dh == 0 else ds / dh * (
            math.sin(heading_rad + dh) - math.sin(heading_rad))
        heading_rad += dh
    return x_m


def _at(enc: list[Enc], t_s: float) -> Enc:
    return next(e for e in enc if abs(e[0] - t_s) < 1e-6)


def test_the_firmware_merged_one_arc_from_the_held_frame(drive: Path) -> None:
    """The poses on cadence from 4.521 to 4.601 s name ENC_COUNTER 15, the held frame of 4.502816
    s (the one 15 heard since the 14 of 3.98 s), after the late 7 and 8 reached the bus; from the
    pose of 4.521 s, the X of 4.641 s is the one arc from it to the 0 of 4.640 s (-0.035 mm, the
    pose's 0.1 mm LSB), not the arcs split at the 7 and 8 the host took (3.90 mm in X)."""
    enc, pose_x = _decoded(drive)
    held = [p for t, p in pose_x if 4.52 < t < 4.61 and round(t * 1000) % 20 == 1]
    assert len(held) == 5
    assert {int(p["ENC_COUNTER"]) for p in held} == {15}
    assert [e[0] for e in enc if e[1] == 15 and 3.98 < e[0] < 4.61] == [HELD_S]
    start = held[0]
    merged = _arcs(start["X"], start["HEADING"], [_at(enc, HELD_S), _at(enc, MERGED_TO_S)])
    split = _arcs(start["X"], start["HEADING"],
                  [_at(enc, t) for t in (HELD_S, *SPLIT_AT_S, MERGED_TO_S)])
    onboard = next(p for t, p in pose_x if abs(t - 4.641) < 1e-6)
    assert int(onboard["ENC_COUNTER"]) == 0
    assert abs(onboard["X"] - merged) < 0.1e-3, (onboard["X"], merged)
    assert abs(onboard["X"] - split) > 1e-3, (onboard["X"], split)


def test_the_correct_firmware_passes(drive: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """run exits 0 (``drive``); analyze whole and streamed: 1.7796 mm FAIL -> 0.0629 mm PASS."""
    codes = both_analyses(drive)
    capsys.readouterr()
    assert codes == [0, 0]


@pytest.mark.parametrize("from_s", [4.635, 4.595])
def test_an_affected_pose_10_mm_off_fails(drive: Path, tmp_path: Path, from_s: float,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """One ODOM_POSE_X raised 10 mm (re-signed by cantools): the merged arc's first pose of 4.641
    s, or the held pose of 4.601 s naming the held frame: each analysis FAILs by the position."""
    tampered = tmp_path / "t.log"
    raise_first_x(drive, tampered, 100, from_s, from_s + 0.01)
    wrong = fails_by_position(tampered, tmp_path)
    capsys.readouterr()
    assert wrong == []


def _live(log: Path) -> tuple[str, str]:
    """The monitor's state and the bridge's end verdict on ``log``, fed frame by frame."""
    monitor, bridge = live_judges("kobuki", log)
    bridge.end_watch()
    return str(monitor.health(monitor.bus_time_s)["state"]), end_verdict(bridge).verdict


def test_the_live_judges_pass_the_correct_firmware(drive: Path) -> None:
    """The monitor shows the firmware's own DEGRADED (POSE_UNCERTAIN: the merged arc), the
    bridge PASSes; on main both blamed it (POSE WRONG, FAIL)."""
    assert _live(drive) == ("DEGRADED", "PASS")


def test_the_live_judges_fail_the_merged_arcs_pose_10_mm_off(drive: Path,
                                                              tmp_path: Path) -> None:
    """The X of 4.641 s raised 10 mm: the monitor POSE WRONG, the bridge FAIL."""
    raise_first_x(drive, tmp_path / "t.log", 100, 4.635, 4.645)
    assert _live(tmp_path / "t.log") == ("POSE WRONG", "FAIL")


@pytest.mark.xfail(strict=True, reason=(
    "issue #11: the held ODOM_POSE_X of 4.601 s (naming the COUNTER 15 a bus-off held, 4.502816 "
    "s) raised 10 mm: analyze whole and streamed FAIL it, the monitor stays DEGRADED and the "
    "bridge PASSes (the live judges do not judge it; not analysed in time)"))
def test_the_live_judges_fail_the_held_pose_10_mm_off(drive: Path, tmp_path: Path) -> None:
    """The X of 4.601 s, which names the held frame, raised 10 mm: POSE WRONG and FAIL."""
    raise_first_x(drive, tmp_path / "t.log", 100, 4.595, 4.605)
    assert _live(tmp_path / "t.log") == ("POSE WRONG", "FAIL")


@pytest.mark.parametrize(("seed", "duration"), [(3, 12), (4, 8), (4, 12), (5, 8), (6, 12)])
def test_the_other_seeds_and_durations_pass(seed: int, duration: int, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Seed 4 FAILed at 8 and 12 s (0.2883 mm), seed 3 at 12 s (1.7796 mm); 5 and 6 PASSed."""
    log = correct_drive(tmp_path / "d.log", "kobuki", "random", seed, duration, FAULTS)
    codes = both_analyses(log)
    capsys.readouterr()
    assert codes == [0, 0]
