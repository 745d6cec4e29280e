"""Forged encoder frames inside a firmware stall do not widen its allowance (issue 11, rule 5).

A babbler on the encoder ID (0x100) sends random payloads; about one in 256 passes Profile 2's
CRC and reaches the judges as an encoder frame with wild counts, which the firmware refuses as
implausible (firmware/ecu.py). The allowance across a stall (``breaks.merge_allowance_m``, the
worst merge error of any runs of frames the firmware may have missed) took the raw counts of
the log's frames, so a forged frame inside the stall's span made it 141 mm here: a pose
20 mm off after the stall passed. It now takes the counts the firmware integrates
(``lossgate.gated_counts``, the plausibility bound), whole, streamed and live.

The checker is independent of the judge: cantools decodes the log (``_Frames``: its own CRC), a
plausibility gate of its own drops the forged counts (``test_babble_loss_bound``), and float64
odometry of its own gives twice the real path over the stall's span (every merge error of runs
within it is at most their merged steps plus their fine path): the allowance lies below it.
"""

from __future__ import annotations

import math
from pathlib import Path

import can
import numpy as np
import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.reference import Geometry
from odocan.host.judge.reference_path import break_allowance
from odocan.host.judge.samples import Encoders
from odocan.host.judge.stream_stalls import StreamBreakCounts
from odocan.sim.board import TICK_S
from odocan.sim.faultspec import FaultSpec
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.independent_checker import _Frames
from tests.test_babble_firmware import _biased_x
from tests.test_babble_loss_bound import _accepted_counts, _step
from tests.test_live_reboot import monitor_of

HALT_AT, HALT_TICKS = 580, 40  # the MCU halted (a SIGSTOP) 0.4 s from 5.8 s
BABBLE = "babble=2000:0x100,seed=1"


def _stall_babble_log(path: Path) -> Path:
    """kobuki on a random drive, the encoder ID babbled, the MCU halted from 5 s for 0.4 s."""
    messages: list[can.Message] = []
    scenario = get_scenario("random", load("kobuki"), seed=4, duration_s=60.0)
    with FaultRig(sim_faults=FaultSpec.parse(BABBLE), scenario=scenario, robot="kobuki",
                  integrator="exact") as rig:
        rig.observers.append(lambda tick, frames: messages.extend(frames))
        rig.halted = lambda k: HALT_AT <= k < HALT_AT + HALT_TICKS
        rig.run((HALT_AT + HALT_TICKS + 300) * TICK_S)
    path.write_text("".join(  # in bus order, as the fault rig hears it
        f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#{bytes(m.data).hex().upper()}\n"
        for m in messages))
    return path


def _forged_in_stall(log: Path) -> int:
    """Encoder frames inside the stall that pass the CRC (cantools') but not the checker's
    plausibility gate: the case under test (one at 5.998 s the judges' E2E accepts too)."""
    frames = _Frames(log)
    t0, t1 = HALT_AT * TICK_S, (HALT_AT + HALT_TICKS) * TICK_S
    kept = set(_kept_times(frames))
    return sum(1 for t, name, _ in frames.rows
               if name == "WHEEL_ENCODERS" and t0 <= t < t1 and t not in kept)


def _checker_merge_bound_m(log: Path) -> float:
    """The worst sum (m, float64) of the merge errors of any runs of real frames lost across the
    stall, over a span a little wider than the judge's (from 30 ms before the halt to 30 ms
    after it: every set of runs in the judge's span is one here): dynamic programming over the
    frame last taken, each run's error the distance between its fine exact-arc steps and its
    one merged step from the same pose."""
    frames = _Frames(log)
    profile = load("kobuki")
    cum, kept_t = _accepted_counts(frames, "kobuki"), _kept_times(frames)
    assert len(kept_t) == len(cum)
    m = (2.0 * math.pi * profile.wheel_radius_left_m / profile.counts_per_rev,
         2.0 * math.pi * profile.wheel_radius_right_m / profile.counts_per_rev)
    t0, t1 = HALT_AT * TICK_S - 0.03, (HALT_AT + HALT_TICKS) * TICK_S + 0.03
    span = [c for c, t in zip(cum, kept_t, strict=True) if t0 <= t <= t1]
    best = [0.0] * len(span)
    for a in range(len(span) - 1):
        h = (span[a][1] * m[1] - span[a][0] * m[0]) / profile.wheelbase_m
        fine = (0.0, 0.0, h)
        for t in range(a + 1, len(span)):
            fine = _step(fine, span[t][0] - span[t - 1][0], span[t][1] - span[t - 1][1], m,
                         profile.wheelbase_m)
            merged = _step((0.0, 0.0, h), span[t][0] - span[a][0], span[t][1] - span[a][1], m,
                           profile.wheelbase_m)
            err = math.hypot(fine[0] - merged[0], fine[1] - merged[1])
            best[t] = max(best[t], best[a] + err)
    return best[-1]


def _kept_times(frames: _Frames) -> list[float]:
    """The bus times of the frames ``_accepted_counts`` keeps (its own gate, run again)."""
    profile = load("kobuki")
    bits = min(profile.counter_bits, 24)
    per_count = [2.0 * math.pi * r / profile.counts_per_rev
                 for r in (profile.wheel_radius_left_m, profile.wheel_radius_right_m)]
    bound = [profile.max_wheel_speed_mm_s * 1e-3 * 0.01 / m + 2.0 for m in per_count]
    half = 1 << (bits - 1)
    kept: list[tuple[float, int, int]] = []
    for t_s, name, s in frames.rows:
        if name != "WHEEL_ENCODERS":
            continue
        counts = (int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))
        if kept:
            t0, l0, r0 = kept[-1]
            d = [((c - c0 + half) % (1 << bits)) - half
                 for c, c0 in zip(counts, (l0, r0), strict=True)]
            periods = max(1, round((t_s - t0) / 0.01))
            if not all(abs(x) <= periods * b for x, b in zip(d, bound, strict=True)):
                continue
        kept.append((t_s, *counts))
    return [k[0] for k in kept]


@pytest.fixture(scope="module")
def stall_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _stall_babble_log(tmp_path_factory.mktemp("stallgate") / "stall.log")


def test_the_stall_allowance_is_tight_and_the_correct_firmware_passes(stall_log: Path) -> None:
    assert _forged_in_stall(stall_log) >= 1
    right = analyze(read_log(stall_log), load("kobuki"), "exact")
    breaks = right.report["reference_breaks"]
    bound_m = _checker_merge_bound_m(stall_log)
    print(f"\nstall allowance {breaks['offset_allowance_m'] * 1e3:.4f} mm, checker's bound "
          f"{bound_m * 1e3:.4f} mm")
    assert right.passed, (right.report["onboard_vs_reference"], breaks)
    assert breaks["stall_placements"] >= 1
    assert breaks["offset_allowance_m"] <= bound_m + POSITION_LSB_M
    for stream in ("never", "always"):
        assert main(["analyze", str(stall_log), "--robot", "kobuki", "--stream", stream]) == 0


@pytest.mark.parametrize("beyond_lsb", [2, 200])
def test_a_pose_off_after_the_stall_fails_whole_streamed_and_live(
    stall_log: Path, tmp_path: Path, beyond_lsb: int
) -> None:
    """Every X from the stall's end on off by 2 LSB (0.2 mm) or 200 LSB (20 mm) beyond the
    checker's bound on the stall's merge errors (1.7 mm; the judge's allowance was 141 mm,
    from a forged frame's counts): FAIL."""
    wrong = tmp_path / "wrong.log"
    resumed_s = (HALT_AT + HALT_TICKS) * TICK_S - 0.0005
    bias_lsb = math.ceil(_checker_merge_bound_m(stall_log) / POSITION_LSB_M) + beyond_lsb
    assert _biased_x(stall_log, wrong, lambda k, t_s: t_s >= resumed_s, bias_lsb) > 100
    for stream in ("never", "always"):
        assert main(["analyze", str(wrong), "--robot", "kobuki", "--stream", stream]) == 1
    tracker = monitor_of(wrong, "kobuki", "exact").tracker  # as test_stall_bound's
    assert tracker.stall.stalls >= 1
    assert tracker.vs_reference.max_dpos_m > POSITION_LSB_M


@pytest.mark.parametrize("frames", [60, 700])  # the merge allowance; beyond MAX_MERGE_FRAMES
def test_the_streamed_stall_allowance_gates_a_forged_frame_as_the_whole_one(frames: int) -> None:
    """The streamed judge falls back to the whole log on this drive (the babble's twins), so
    ``StreamBreakCounts`` is fed here directly: a curve on kobuki, a break at frame 1 to the
    last frame, one forged frame (counts half the counter away) in it; in any chunks, the
    allowance is ``break_allowance``'s bit for bit, and below the path bound of the real
    steps (the raw counts gave metres)."""
    profile = load("kobuki")
    g, bits = Geometry.of(profile), min(profile.counter_bits, 24)
    steps = [(45 - k % 3, 38 + k % 2) for k in range(frames - 1)]
    left = np.concatenate(([0], np.cumsum([s[0] for s in steps]))).astype(np.int64)
    right = np.concatenate(([0], np.cumsum([s[1] for s in steps]))).astype(np.int64)
    left[frames // 2] += 1 << (bits - 2)  # forged: a babbler's payload that passed the CRC
    seq = np.arange(frames, dtype=np.int64)
    enc = Encoders(index=seq, counter=seq % 16, seq=seq, left=left % (1 << bits),
                   right=right % (1 << bits), timestamp_s=seq.astype(np.float64) * 0.01,
                   cycle_s=0.01)
    whole = break_allowance(enc, 1, np.array([frames - 1]), g, bits, "exact")
    real_path_m = sum(abs(a) * g.m_per_count_left + abs(b) * g.m_per_count_right
                      for a, b in steps)
    assert whole <= 2.0 * real_path_m + 1e-9
    for size in (7, 333, frames):
        counts = StreamBreakCounts([1], g, bits, "exact")
        counts.named(np.array([0, frames - 1]))
        for lo in range(0, frames, size):
            hi = min(lo + size, frames)
            counts.feed(Encoders(index=enc.index[lo:hi], counter=enc.counter[lo:hi],
                                 seq=enc.seq[lo:hi], left=enc.left[lo:hi],
                                 right=enc.right[lo:hi], timestamp_s=enc.timestamp_s[lo:hi],
                                 cycle_s=0.01))
        assert counts.allowance(1) == whole
