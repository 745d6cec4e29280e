"""A second (and third) stall the firmware re-primed after, its COUNTER_RESET already latched
(issue #11: a FAIL must never blame a correct firmware).

pmir (the lockstep ``FaultRig``) halted 6 s from tick ``MID``, 8 s from tick 1500 and (thrice) 7
s from tick 2800, each past pmir's ~3.7 s re-prime, on the circle, square, spin and figure-8.
COUNTER_RESET is sticky (firmware/errors.py; the DBC: latched until ODOM_SET_POSE APPLY): the
first stall sets it, so at the later ones the firmware's summaries say nothing new. But its rule
is the step's bound, not the bit (firmware/encoders.py: the bound after the overrun, about twice
the stall, reaches half the 16-bit counters' range): it re-primes at every one. The tests'
float64 odometry on cantools-decoded frames shows it (``test_the_firmware_reprimed_at_the_
second_stall``: on the square and the figure-8; the circle and the spin are at rest by the second
stall, their programs done). Before, every judge kept the exact rule at the later stalls:
``analyze`` FAILed the square's correct firmware by 2733 mrad, the monitor and the bridge said
POSE WRONG. Now each stall long enough that the firmware surely re-primed
(``stallreprime.certain``) with the word latched re-primes the reference as a declared one
(whole, streamed byte for byte, live); a pose 10 mm or 1 m off from the first pose after the
second stall still FAILs every judge.

tests.sweeps: the judges keep the square's two stalls (its FAIL before) and every scenario and
stall count once; a pose off keeps every scenario and both offsets once.
"""

from __future__ import annotations

import itertools
import math
from functools import cache
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.judge.stallreprime import FIFO_SPAN
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.independent_checker import Robot, _Odometry
from tests.sweeps import sample
from tests.test_first_second_reboot import _decoded, _wrong
from tests.test_stall_before_first_pose_after_reboot import _live
from tests.test_stall_beyond_window import COUNTER_RESET_BIT, MID, PMIR
from tests.test_stream_reprime import _both, _reprimed, drive_twice

SCENARIOS = ("circle", "square", "spin", "figure8")
SECOND = 1500  # the second stall's start (tick); it resumes at tick 2301
LSB_M, LSB_RAD = 1e-4, 2 * math.pi / 65536


@cache
def drive_thrice(scenario: str) -> tuple[can.Message, ...]:
    """``drive_twice``'s two stalls and a third, 7 s from tick 2800; 3 s driven after."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario(scenario, PMIR, duration_s=60.0)) as rig:
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.halted = lambda k: MID < k <= MID + 600 or 1500 < k <= 2300 or 2800 < k <= 3500
        rig.run(3500 * TICK_S + 3.0)
    return tuple(heard)


def _drive(scenario: str, stalls: int) -> tuple[can.Message, ...]:
    return drive_twice(scenario, 3.0) if stalls == 2 else drive_thrice(scenario)


def _frames_and_poses(messages: tuple[can.Message, ...]
                      ) -> tuple[list[dict[str, float]], list[tuple[float, dict[str, float]]]]:
    """The WHEEL_ENCODERS signals in bus order, and each pose (X and Y halves) with its time
    and the index of the encoder frame it names (the latest with its ENC_COUNTER)."""
    enc: list[dict[str, float]] = []
    poses: list[tuple[float, dict[str, float]]] = []
    half: dict[str, float] = {}
    for m in messages:
        if m.arbitration_id == fr.WHEEL_ENCODERS_ID:
            enc.append(_decoded(m))
        elif m.arbitration_id == fr.ODOM_POSE_X_ID:
            half = _decoded(m)
        elif m.arbitration_id == fr.ODOM_POSE_Y_ID and half:
            pose = {**half, **_decoded(m)}
            named = next(k for k in range(len(enc) - 1, -1, -1)
                         if int(enc[k]["COUNTER"]) == int(pose["ENC_COUNTER"]))
            poses.append((m.timestamp, {**pose, "frame": named}))
    return enc, poses


def _heading(pose: dict[str, float]) -> float:
    return float(pose["TURNS"]) * 2 * math.pi + float(pose["HEADING"]) * LSB_RAD


def _counts(enc: list[dict[str, float]], a: int, b: int) -> tuple[int, int]:
    """The wheels' steps from frame ``a`` to ``b`` (16-bit counters)."""
    return (round((enc[b]["LEFT_COUNT"] - enc[a]["LEFT_COUNT"] + 32768) % 65536 - 32768),
            round((enc[b]["RIGHT_COUNT"] - enc[a]["RIGHT_COUNT"] + 32768) % 65536 - 32768))


def _walked(enc: list[dict[str, float]], start: dict[str, float], f: int, r: int, end: int,
            *, merged: bool) -> _Odometry:
    """From the firmware's pose ``start`` (on its frame), float64 steps to each frame up to
    ``f``, then (``merged``) one step f -> r or (re-primed) none, then a step to each frame up
    to ``end``."""
    odo = _Odometry(Robot(PMIR.counts_per_rev, round(PMIR.wheel_radius_left_m * 1e9),
                          round(PMIR.wheel_radius_right_m * 1e9), round(PMIR.wheelbase_m * 1e9),
                          PMIR.counter_bits), "exact")
    odo.place(float(start["X"]) * LSB_M, float(start["Y"]) * LSB_M, _heading(start))
    for a, b in itertools.pairwise(range(int(start["frame"]), f + 1)):
        odo.step(*_counts(enc, a, b))
    if merged:  # re-primed: no step, nothing of the jump (its turn neither)
        odo.step(*_counts(enc, f, r))
    for a, b in itertools.pairwise(range(r, end + 1)):
        odo.step(*_counts(enc, a, b))
    return odo


def _off(odo: _Odometry, pose: dict[str, float]) -> tuple[float, float]:
    """Position (m) and wrapped heading (rad) of ``pose`` from ``odo``."""
    turn = (_heading(pose) - odo.heading + math.pi) % (2 * math.pi) - math.pi
    return (math.hypot(odo.x - float(pose["X"]) * LSB_M, odo.y - float(pose["Y"]) * LSB_M),
            abs(turn))


@pytest.mark.parametrize("scenario", ["square", "figure8"])
def test_the_firmware_reprimed_at_the_second_stall(scenario: str) -> None:
    """COUNTER_RESET set on every summary from the first stall on (latched: nothing new at the
    second); the 5th pose after the second stall is the pose before it stepped over the frames
    its FIFO kept (up to ``f``), then re-primed on a frame ``r`` (no step into it) and stepped
    on, within an LSB, for some pair; with the step f -> r taken (no re-prime), no pair comes
    within 0.1 m and 0.1 rad. (The circle's and the spin's programs are done by then, the
    robot at rest: a re-prime there leaves nothing out, either rule fits them.)"""
    messages = drive_twice(scenario, 3.0)
    masks = [(m.timestamp, int(_decoded(m)["ERROR_MASK"])) for m in messages
             if m.arbitration_id == fr.ODOM_STATUS_ID and int(_decoded(m)["PAGE"]) == 0]
    assert all(mask & COUNTER_RESET_BIT for t_s, mask in masks if t_s > (MID + 700) * TICK_S)
    enc, poses = _frames_and_poses(messages)
    before = [p for t_s, p in poses if t_s < SECOND * TICK_S][-1]
    after = [p for t_s, p in poses if t_s > (SECOND + 800) * TICK_S][4]
    e_b, e_a = int(before["frame"]), int(after["frame"])
    reprimed, merged = math.inf, math.inf
    for f in range(e_b, e_b + FIFO_SPAN + 1):
        for r in range(f + 1, e_a + 1):
            gap_m, turn = _off(_walked(enc, before, f, r, e_a, merged=False), after)
            reprimed = min(reprimed, max(gap_m / LSB_M, turn / LSB_RAD))
            gap_m, turn = _off(_walked(enc, before, f, r, e_a, merged=True), after)
            merged = min(merged, max(gap_m / 0.1, turn / 0.1))
    assert reprimed <= 1.0, reprimed
    assert merged > 1.0, merged


@pytest.mark.parametrize(("scenario", "stalls"), sample(
    [(s, n) for s in SCENARIOS for n in (2, 3)], 4, [("square", 2), ("circle", 3),
                                                      ("figure8", 3)]))
def test_every_judge_passes_the_correct_firmware(scenario: str, stalls: int,
                                                 tmp_path: Path) -> None:
    """``analyze`` (whole and streamed, the same report) and the live judges PASS it with a
    ``stall_reprime`` event at every stall (before: one, and the square FAILed)."""
    messages = _drive(scenario, stalls)
    whole, same = _both(messages, tmp_path / "right.log")
    assert (whole["passed"], _reprimed(whole), same) == (True, stalls, [True, True]), \
        whole["onboard_vs_reference"]
    monitor, bridge, end_s = _live(messages)
    assert (monitor.health(end_s)["pose_wrongs"]["episodes"],
            bridge.tracker.wrongs.as_dict()["episodes"]) == (0, 0)
    for judge in (monitor, bridge):
        assert [e["kind"] for e in judge.events].count("stall_reprime") == stalls


@pytest.mark.parametrize(("scenario", "bias_lsb"), sample(
    [(s, b) for s in SCENARIOS for b in (100, 10_000)], 3, [("figure8", 100)]))
def test_a_pose_off_after_the_second_stall_fails(scenario: str, bias_lsb: int,
                                                 tmp_path: Path) -> None:
    """X 10 mm or 1 m off from the first pose after the second stall's start on: every judge
    FAILs it, whole and streamed the same."""
    wrong = _wrong(drive_twice(scenario, 3.0), SECOND + 1, bias_lsb, 1)
    whole, same = _both(wrong, tmp_path / "wrong.log")
    assert (whole["passed"], same) == (False, [True, True])
    assert whole["onboard_vs_reference"]["max_position_error_m"] > 5e-3
    monitor, bridge, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert bridge.tracker.wrongs.as_dict()["episodes"] >= 1
