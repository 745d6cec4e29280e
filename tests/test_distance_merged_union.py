"""The DISTANCE judge's allowance below the reference counts each frame's path once, however
many merge spans hold it (``distance.merged_path_m``, issue #11 rule 5).

The firmware stalled 3 s mid-drive (``tests/test_stall_mid_drive_losses.py``'s lockstep rig):
it took its FIFO's two frames, then the frame ``RESUMED_AT`` as one step. ``analyze`` lets its
DISTANCE lie below the reference's path by the fine path of the frames it may have merged. The
stall's frames were counted three times: the stall's span (the last sample before it to the
first after), the span of the page after it (ENC_E2E_LOST grew by the overrun) and the span of
its ENC_E2E_OK (grown by ~290 frames less than the host took: past ``skipdefect.MAX_RUN``, the
span's whole fine path). A DISTANCE 4.5 m short from the stall on PASSed ``analyze`` whole and
streamed, though the stall's fine path is 1.51 m. Now the down allowance is the fine path over
the union of those spans: a DISTANCE short by 50 mm more than the stall's fine path FAILs.

The evidence (float64 on cantools-decoded frames, ``independent_checker``'s per-count travel):
the correct firmware's DISTANCE is within 1 mm of the path of the steps it took (its FIFO, the
merged step, then every frame), the edited one 1.5 m or more below it.

The live judges (``livedistance``) gave the stall the fine path since the last twist judged
before it, read from the encoder frames they keep (64): after 3 s those were gone and the
allowance unbounded, so a DISTANCE 20 m short from the stall on PASSed the monitor and the
bridge. Now the path at the last twist judged is kept: 5 m short FAILs them. Their allowance
there was then still 3.1 m (the stall's path and, added on top, the ENC_E2E_OK span's whole
path); it is the union now (``liveunion``, ``tests/test_live_distance_union.py``).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import can

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.sim.board import TICK_S
from tests.independent_checker import Robot, _Odometry
from tests.test_first_second_reboot import _decoded, _reencoded, _written
from tests.test_stall_before_first_pose_after_reboot import _live
from tests.test_stall_mid_drive_losses import HALTED, PMIR, RESUMED_AT, STALL, drive

SINCE_S = (STALL + HALTED) * TICK_S  # the twists after the stall


def _path_m(frames: list[int]) -> float:
    """Float64 path length (m) of the wheel-axis midpoint over one step to each next frame."""
    odo = _Odometry(Robot(PMIR.counts_per_rev, round(PMIR.wheel_radius_left_m * 1e9),
                          round(PMIR.wheel_radius_right_m * 1e9), round(PMIR.wheelbase_m * 1e9),
                          PMIR.counter_bits), "exact")
    enc = [_decoded(m) for m in drive() if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    total = 0.0
    for a, b in itertools.pairwise(frames):
        dl, dr = ((enc[b][s] - enc[a][s] + 32768) % 65536 - 32768
                  for s in ("LEFT_COUNT", "RIGHT_COUNT"))
        total += abs(0.5 * (dl * odo.m_left + dr * odo.m_right))
    return total


def _twists(messages: tuple[can.Message, ...]) -> list[dict[str, float]]:
    return [_decoded(m) for m in messages
            if m.arbitration_id == fr.ODOM_TWIST_ID and m.timestamp >= SINCE_S]


def _shifted(shift_mm: int) -> tuple[can.Message, ...]:
    """The firmware's frames with every DISTANCE after the stall ``shift_mm`` off (E2E
    re-protected with the frame's own COUNTER)."""
    out = []
    for m in drive():
        if m.arbitration_id == fr.ODOM_TWIST_ID and m.timestamp >= SINCE_S:
            signals = _decoded(m)
            signals["DISTANCE"] = (signals["DISTANCE"] + shift_mm) % 65536
            m = _reencoded(m, signals, fr.ODOM_TWIST_DATA_IDS)
        out.append(m)
    return tuple(out)


def _taken_mm(k: int) -> float:
    """The float64 path (mm) of the steps the firmware took up to the frame the ``k``-th twist
    after the stall names (k >= 1; the 0th names ``RESUMED_AT``)."""
    named = RESUMED_AT + 2 * k
    return 1e3 * _path_m([*range(STALL + 3), *range(RESUMED_AT, named + 1)])


def test_the_correct_distance_is_the_path_the_firmware_took() -> None:
    """The premise: within 1 mm of the float64 path of its steps (u16 mm), and the stall's
    fine path is 1.5 m (far above its merge's defect: 0, driving forward)."""
    for k in (1, 5, 60):
        twist = _twists(drive())[k]
        assert int(twist["ENC_COUNTER"]) == (RESUMED_AT + 2 * k) % 16
        assert abs((twist["DISTANCE"] - _taken_mm(k) + 32768) % 65536 - 32768) <= 1.0
    assert 1.4 < _path_m(list(range(STALL, RESUMED_AT + 3))) < 1.6


def test_a_distance_short_by_more_than_the_stalls_path_fails(tmp_path: Path) -> None:
    """DISTANCE from the stall on short by the stall's fine path (the last sample's frame
    before it to the first judged after it) plus 50 mm: FAIL whole and streamed. Before: PASS
    (3.1 m of allowance at the first twist after the stall)."""
    fine_mm = 1e3 * _path_m(list(range(STALL, RESUMED_AT + 3)))
    shift_mm = -math.ceil(fine_mm + 50.0)
    messages = _shifted(shift_mm)
    for k in (1, 60):
        assert _twists(messages)[k]["DISTANCE"] < _taken_mm(k) - 1400.0
    path = _written(messages, tmp_path / "short.log")
    report = analyze(read_log(path), PMIR, "exact").report["onboard_distance_vs_reference"]
    assert not report["passed"]
    assert report["max_excess_m"] > 0.04
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1


def test_the_live_judges_bound_a_long_stall() -> None:
    """The correct DISTANCE passes the monitor and the bridge; 5 m short from the stall on
    (3.5 m beyond the stall's fine path) FAILs them. Before: PASS (the allowance unbounded)."""
    monitor, bridge, _ = _live(drive())
    assert [live.as_dict()["passed"] for live in (monitor.distance, bridge.distance)] == [True] * 2
    messages = _shifted(-5000)
    assert (_twists(messages)[60]["DISTANCE"] - _taken_mm(60) + 32768) % 65536 - 32768 < -4900
    monitor, bridge, _ = _live(messages)
    for live in (monitor.distance, bridge.distance):
        assert not live.as_dict()["passed"]
