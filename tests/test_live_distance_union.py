"""The live DISTANCE judges allow below the reference the fine path over the union of the spans
whose frames the firmware may have merged, each frame once, as ``analyze`` does
(``host.judge.liveunion``; ``distance.merged_path_m``; issue #11, rule 5).

``tests/test_stall_mid_drive_losses.py``'s rig: pmir on the circle, the MCU halted 3 s after
tick 500 (5 s). Three spans hold the stall's frames: the stall's own (the last twist judged
before it to the first judged after), the page after it (ENC_E2E_LOST grew by the overrun) and
its ENC_E2E_OK span (~300 frames fewer than the host took: past ``skipdefect.MAX_RUN``, its whole
fine path). ``analyze`` allows their union: 1.57 m at the first twist judged after the stall
(frame 804), the fine path from the ENC_E2E page before the stall (frame 490) to it. The
monitor and the bridge summed them: 3.09 m there (5.12 m from frame 852 on), so a DISTANCE
2.3 m short from the stall on PASSed them and FAILed ``analyze``. Now they allow the union,
the same to the 2^-40 m at every sample of this drive: 20 mm beyond it FAILs every judge,
20 mm inside it PASSes every judge, and their excesses agree within ``AGREE_MM``.

The evidence (``independent_checker``'s float64 per-count travel on cantools-decoded frames,
not ``host.reference``): the correct DISTANCE is within 1 mm of the path of the steps it took;
the union's fine path is the checker's sum over frames 490..804 one step each.

The correct firmware PASSes the live judges on every drive shape of the sim with stalls of
0.02 s to 6 s at power-up and mid-drive (``test_the_correct_firmware_passes_live``).
"""

from __future__ import annotations

import itertools
import math
from functools import cache
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.firmware import frames as fr
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.distance import merged_path_m
from odocan.host.judge.liveunion import MergedSpans
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.sweeps import sample
from tests.test_distance_merged_union import _path_m, _shifted, _taken_mm, _twists
from tests.test_first_second_reboot import _decoded, _written
from tests.test_stall_before_first_pose_after_reboot import _live
from tests.test_stall_mid_drive_losses import PMIR, RESUMED_AT, STALL, drive

FIRST_AFTER = RESUMED_AT + 2  # the frame the first twist judged after the stall names
AGREE_MM = 1.0  # live and analyze's excess beyond the allowance agree within this


def _page_before_stall() -> int:
    """The latest encoder frame heard before the last ENC_E2E page (PAGE 2) sent before the
    stall: where the lossy and the ENC_E2E_OK spans begin."""
    frames, latest = -1, -1
    for m in drive():
        if m.timestamp > STALL * TICK_S:
            break
        if m.arbitration_id == fr.WHEEL_ENCODERS_ID:
            frames += 1
        elif m.arbitration_id == fr.ODOM_STATUS_ID and int(_decoded(m)["PAGE"]) == 2:
            latest = frames
    return latest


def _union_mm() -> float:
    """The checker's fine path (mm) over the frames the firmware may have merged by the first
    twist judged after the stall: from the page before it, one step to each next frame."""
    return 1e3 * _path_m(list(range(_page_before_stall(), FIRST_AFTER + 1)))


def _bound_mm() -> float:
    """How far the union lets DISTANCE fall from the last twist before the stall (frame
    ``STALL``: it pins the value there) to the first judged after: the checker's fine path
    between them (the union's frames before ``STALL`` were allowed to the twists naming them,
    which found the value on the reference's)."""
    return 1e3 * _path_m(list(range(STALL, FIRST_AFTER + 1)))


def _judged(shift_mm: int) -> tuple[float, float, float]:
    """DISTANCE ``shift_mm`` off from the stall on: analyze's, the monitor's and the bridge's
    excess beyond the allowance (mm; 0: PASS)."""
    messages = _shifted(shift_mm)
    path = _written(messages, Path(f"/tmp/odocan_union_{shift_mm}.log"))
    try:
        report = analyze(read_log(path), PMIR, "exact").report["onboard_distance_vs_reference"]
    finally:
        path.unlink()
    monitor, bridge, _ = _live(messages)
    lives = [live.as_dict() for live in (monitor.distance, bridge.distance)]
    for judged in (report, *lives):
        assert judged["passed"] == (judged["max_excess_m"] == 0.0)
    return (1e3 * report["max_excess_m"], *(1e3 * live["max_excess_m"] for live in lives))


def test_the_union_is_the_checkers_path_from_the_page_before_the_stall() -> None:
    """The premise: the correct DISTANCE is the path of the steps the firmware took (1 mm),
    the page before the stall at frame 490 and the union's path 1.5-1.6 m, the spans' sum
    (the stall's 500..804 added to it) above 3 m; the bound for a DISTANCE changed from the
    stall on (the union's growth since the last twist before it) is 1.5 m."""
    for k in (1, 30):
        twist = _twists(drive())[k]
        assert abs((twist["DISTANCE"] - _taken_mm(k) + 32768) % 65536 - 32768) <= 1.0
    assert _page_before_stall() == 490
    assert 1500.0 < _union_mm() < 1600.0
    assert _union_mm() + _bound_mm() > 3000.0
    assert 1500.0 < _bound_mm() < _union_mm()


def test_short_between_analyze_and_the_spans_sum_fails_live() -> None:
    """2.3 m short from the stall on (0.7 m beyond the bound, 0.7 m inside the spans' sum's):
    before, analyze FAILed it and the monitor and the bridge PASSed it."""
    assert _bound_mm() + 500.0 < 2300.0 < _bound_mm() + _union_mm() - 500.0
    assert (_twists(_shifted(-2300))[1]["DISTANCE"] - _taken_mm(1) + 32768) % 65536 - 32768 \
        < -2290.0
    offline, monitor, bridge = _judged(-2300)
    print(f"\n2.3 m short: analyze {offline:.3f} mm, monitor {monitor:.3f} mm, "
          f"bridge {bridge:.3f} mm beyond")
    assert offline > 500.0
    assert monitor > 500.0
    assert bridge > 500.0


@pytest.mark.parametrize("beyond_mm", [-20.0, 20.0])
def test_live_and_analyze_agree_at_the_bound(beyond_mm: float) -> None:
    """Short by the checker's bound ``beyond_mm`` (and the wire's 1 mm) from the stall on:
    20 mm inside PASSes every judge, 20 mm beyond FAILs every judge by 18-21 mm, within
    ``AGREE_MM`` of each other."""
    shift = -math.ceil(_bound_mm() + beyond_mm)
    offline, monitor, bridge = _judged(shift)
    print(f"\nshort by {-shift} mm (bound {_bound_mm():.3f} mm): analyze {offline:.3f}, "
          f"monitor {monitor:.3f}, bridge {bridge:.3f} mm beyond")
    if beyond_mm < 0:
        assert (offline, monitor, bridge) == (0.0, 0.0, 0.0)
    else:
        assert 17.0 < offline < 21.0
    assert abs(monitor - offline) <= AGREE_MM
    assert abs(bridge - offline) <= AGREE_MM


@pytest.mark.parametrize("seed", range(6))
def test_the_live_union_grows_as_the_whole_logs(seed: int) -> None:
    """Overlapping, nested and disjoint spans known before the twists (half of their ends'
    paths taken as their frame is fed): the live growth summed twist by twist is
    ``distance.merged_path_m``'s union at every twist, to the unit."""
    rng = np.random.default_rng(seed)
    units = np.concatenate(([0], np.cumsum(rng.integers(0, 1 << 30, 400))))
    spans = [(int(a), int(a + rng.integers(1, 80))) for a in rng.integers(0, 320, 7)]
    union = MergedSpans()
    for a, z in spans:
        union.add(a, int(units[a]), z, int(units[z]) if rng.random() < 0.5 else None)
    e = np.unique(rng.integers(0, 400, 60))
    want = merged_path_m(spans, {f: int(units[f]) for f in range(400)}, e, units[e])
    since, grown, fed = -1, 0, 0
    got = []
    for frame in e.tolist():
        for seq in range(fed, frame + 1):
            if seq >= union.want:
                union.on_frame(seq, int(units[seq]))
        fed = frame + 1
        grown += union.grown_units(since, frame, int(units[frame]))
        since = int(units[frame])
        got.append(grown / (1 << 40))
    assert max(got) > 0
    assert np.array_equal(np.array(got), want)


@cache
def _stalled(shape: str, at_tick: int, halted: int) -> tuple[can.Message, ...]:
    """pmir on ``shape``, its MCU halted ``halted`` ticks after tick ``at_tick`` (0: from
    power-up, its FIFO emptied at tick 0 as ``tests/test_stall_beyond_window.py`` does), then
    3 s more."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario(shape, PMIR, duration_s=60.0)) as rig:
        def drained(k: int) -> None:
            if k == at_tick == 0:  # an empty FIFO at power-up: INIT, no frame to prime on
                while rig.fw_bus.recv(0) is not None:
                    pass
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(drained)
        rig.halted = lambda k: at_tick < k <= at_tick + halted
        rig.run((at_tick + halted) * TICK_S + 3.0)
    return tuple(heard)


SHAPES = ("straight", "spin", "circle", "square", "figure8", "random")  # sim.scenarios
STALLS = (2, 17, 150, 300, 600)  # ticks: 0.02 s, 0.17 s, 1.5 s, 3 s, 6 s


@pytest.mark.parametrize(("shape", "at_tick", "halted"),  # tests.sweeps
                         sample(itertools.product(SHAPES, [0, 300], STALLS), 3))
def test_the_correct_firmware_passes_live(shape: str, at_tick: int, halted: int) -> None:
    """Stalls of 0.02, 0.17, 1.5, 3 and 6 s, mid-drive (3 s in) and at power-up."""
    messages = _stalled(shape, at_tick, halted)
    monitor, bridge, _ = _live(messages)
    for live in (monitor.distance, bridge.distance):
        judged = live.as_dict()
        assert judged["samples"] > 100
        assert judged["passed"], (shape, at_tick, halted, judged)
