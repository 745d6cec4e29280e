"""A step's doubt counts from the frame the firmware took before, not from a refused one heard
between (issue #11: a FAIL must never blame a correct firmware).

``odocan run --scenario random --seed 5 --robot pmir --duration 10 --faults delay=0.5:150``
FAILed the correct firmware by 86.0 mm (run, analyze whole and streamed alike; kobuki seed 5 by
75.7 mm, 6 by DISTANCE 1.16 mm, 8 by 847 mm, 10 by 72.2 mm: ``DRIVES``), the firmware within
1/1000 LSB at every step (``tests.fw_watch``). The trigger looked like a pairing fault, a lone
ODOM_POSE_Y of 4.941 s whose ODOM_POSE_X of the same tick was on the bus, but that X half was
refused by the host's E2E check of the pose stream (its sequence had followed the frames held
back 150 ms), and pairing it would not have helped: the Y half was 87.4 mm off a reference that
was wrong there.

The firmware took the encoder frame of COUNTER 5 at 4.84 s, refused COUNTER 8 and 9 (4.88,
4.89 s: beyond the bound from 5), took COUNTER 13 at 4.93 s over 8 periods, and in the same tick
the late COUNTER 14 (sent 4.78 s, 152 counts back): beyond one period's bound, it took it over
the doubted periods (``firmware.sampledoubt``): COUNTER 13's doubt is the 9 periods since its
last acceptance (COUNTER 5), 17 periods in all. The judges counted that doubt from the frame
heard before COUNTER 13 (the refused COUNTER 9, 4 periods back: no whole lap more), refused
COUNTER 14 and 15, and stepped 84 mm from 13 to 0 at once: the lone Y named COUNTER 15, where
the reference had not moved. Now every judge counts the doubt from the frame taken before
(``step_periods.doubt_origin_s``; the streamed judge carries it across chunks, the live
``StepGate`` keeps it per accepted frame, also across a counter restart's run); the five drives
PASS every analysis. The live judges (monitor and bridge alike) were 0.05, 6.33, 7.21, 972 and
17.9 mm beyond their allowance on them; 0.05, 6.33, 7.21, 303 and 17.9 mm now (their own limits,
not traced here). A sweep of seeds 1-10 x {pmir, kobuki} at delay=0.5:150 changed no other
verdict (kobuki 3's pinned DISTANCE, ``tests/test_delay_long.py``: 42.8 mm beyond, now 17.0).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.livepose import RestartLog, StepGate
from odocan.host.judge.reference import PROFILE_SPEED, Geometry
from odocan.host.judge.reference_path import firmware_steps
from odocan.host.judge.samples import Encoders
from odocan.host.judge.step_periods import doubt_origin_s, doubted_bound_periods
from odocan.host.judge.stream import StreamReference
from odocan.sim.robot import load
from tests.fw_watch import watched
from tests.judges_cli import both_analyses, fails_by_position, raise_x_10_mm

CYCLE_S = 0.01
# pmir random 5, delay=0.5:150: the accepted WHEEL_ENCODERS frames from 4.83 s (seq: the
# sender's numbering, COUNTER, bus time s, LEFT_COUNT, RIGHT_COUNT)
SEQ = [481, 482, 485, 486, 490, 491, 492, 493, 494, 495]
COUNTER = [4, 5, 8, 9, 13, 14, 15, 0, 1, 2]
T_S = [4.83, 4.84, 4.88, 4.89, 4.93, 4.93, 4.94, 4.95, 4.96, 4.97]
LEFT = [65531, 65520, 65327, 65316, 65276, 65428, 65418, 65408, 65398, 65388]
RIGHT = [64005, 64001, 63932, 63929, 63915, 63968, 63964, 63961, 63957, 63954]
# the firmware's steps into each frame after the first, as its trace showed them: COUNTER 8, 9
# refused, 13 taken from 5, the late 14 from 13 over 17 periods, then one by one
FIRMWARE_LEFT = [-11, 0, 0, -244, 152, -10, -10, -10, -10]


def _encoders(upto: slice = slice(None)) -> Encoders:
    n = len(SEQ[upto])
    return Encoders(index=np.arange(n, dtype=np.int64), counter=np.array(COUNTER[upto]),
                    seq=np.array(SEQ[upto]), left=np.array(LEFT[upto]),
                    right=np.array(RIGHT[upto]), timestamp_s=np.array(T_S[upto]),
                    cycle_s=CYCLE_S, uptime=np.zeros(n, dtype=np.int64))


def test_the_doubt_counts_from_the_frame_taken_before() -> None:
    """COUNTER 13 (frame 4) taken after COUNTER 5 (frame 1): its doubt counts from 4.84 s, and
    the step to the late COUNTER 14 spans 1 + 16 periods; from the refused COUNTER 9 heard
    before it (4 periods), 1."""
    seq, stamps = np.array(SEQ), np.array(T_S)
    assert doubted_bound_periods(seq, stamps, CYCLE_S, 4, 5) == 1
    assert doubt_origin_s(stamps, CYCLE_S, 4, {4: 1}) == 4.84
    assert doubted_bound_periods(seq, stamps, CYCLE_S, 4, 5, {4: 1}) == 17
    assert doubt_origin_s(stamps, CYCLE_S, 5, {4: 1}) == 4.84  # one tick: 13's doubt
    assert doubt_origin_s(stamps, CYCLE_S, 4, {}, None) == 4.89
    assert doubt_origin_s(stamps, CYCLE_S, 1) is None  # a period after the one before
    assert doubt_origin_s(stamps, CYCLE_S, 0, {}, 4.5) == 4.5  # frame 0: the carried origin


def test_the_reference_steps_as_the_firmware_did() -> None:
    """Before: COUNTER 14 and 15 refused, 84 mm stepped from 13 to 0 at once."""
    geometry = Geometry.of(load("pmir"))
    steps = firmware_steps(_encoders(), 0, geometry, 16, PROFILE_SPEED)
    assert steps.d_left.tolist() == FIRMWARE_LEFT
    assert steps.d_right.tolist() == [RIGHT[1] - RIGHT[0], 0, 0, RIGHT[4] - RIGHT[1],
                                      *np.diff(RIGHT[4:]).tolist()]
    assert steps.refused == 2
    assert steps.reprimed == []


@pytest.mark.parametrize("cut", [2, 4, 5, 6])
def test_the_streamed_reference_carries_the_doubt(cut: int) -> None:
    """Chunks cut anywhere (after COUNTER 13: the doubt carried with it) step as the whole."""
    geometry = Geometry.of(load("pmir"))
    reference = StreamReference(geometry, "exact", 16, PROFILE_SPEED)
    got = []
    for part in (slice(0, cut), slice(cut, None)):
        enc = _encoders(part)
        enc = Encoders(index=enc.index + (part.start or 0), counter=enc.counter, seq=enc.seq,
                       left=enc.left, right=enc.right, timestamp_s=enc.timestamp_s,
                       cycle_s=CYCLE_S, uptime=enc.uptime)
        reference.feed(enc)
        assert reference.last_steps is not None
        got += reference.last_steps[0].tolist()
    assert got == [0, *FIRMWARE_LEFT]


def test_the_live_gate_steps_as_the_firmware_did() -> None:
    """The monitor's and the bridge's gate: the late COUNTER 14 taken, as the firmware did."""
    assert _gate_lefts("pmir", SEQ, COUNTER, LEFT, RIGHT, T_S) == [
        None, *(d or None for d in FIRMWARE_LEFT)]


def _gate_lefts(robot: str, seq: list[int], counter: list[int], left: list[int],
                right: list[int], t_s: list[float]) -> list[int | None]:
    """The live gate's left-wheel step per frame (None: refused or held), fed in order."""
    gate = StepGate(Geometry.of(load(robot)), 16, RestartLog(lambda _seq, _uptime: None))
    heard = [1, *np.diff(seq).tolist()]
    steps = [gate.step((s, c, lc, rc, h, 0, t)) for s, c, lc, rc, h, t in
             zip(seq, counter, left, right, heard, t_s, strict=True)]
    return [None if d is None else d[0] for d in steps]


# kobuki random 2, delay=0.5:150, from 5.84 s: the firmware took COUNTER 8, re-primed on 9 over
# 9, 10, 12 (three refused frames consistent among themselves: COUNTER_RESET), again on 14 over
# 14, 15, 0, took 4 from 0 and refused the late 5 (heard with 4 at 5.96 s) and 6, re-primed on
# 5 at 7, refused 8 and took 9 from 7 (its trace): (seq: the COUNTER unwrapped, COUNTER, bus
# time s, LEFT, RIGHT)
RESTARTS = [(323, 8, 5.84, 43159, 61869), (324, 9, 5.84, 44132, 61068),
            (325, 10, 5.85, 44067, 61121), (327, 12, 5.87, 43937, 61228),
            (329, 14, 5.90, 42773, 62189), (330, 15, 5.91, 42709, 62242),
            (331, 0, 5.92, 42645, 62295), (332, 1, 5.92, 43612, 61495),
            (335, 4, 5.96, 42390, 62507), (336, 5, 5.96, 43353, 61709),
            (337, 6, 5.97, 43288, 61762), (338, 7, 5.98, 43224, 61816),
            (339, 8, 6.00, 42137, 62718), (340, 9, 6.00, 43095, 61922)]
RESTARTS_LEFT = [0, 0, -195, 0, 0, -128, 0, -255, 0, 0, -129, 0, -129]  # the firmware's steps


def test_a_restart_run_s_frame_is_the_frame_taken_before() -> None:
    """The doubt of COUNTER 4 counts from COUNTER 0, the frame a counter restart's run took at
    5.92 s, not from the frame the live gate took before that run (COUNTER 12, 5.87 s: 9
    periods to COUNTER 5, which it took over 17, 963 counts, where the firmware refused it;
    kobuki 2 live: 4.12 mm beyond in the first cut of this rule, 0.04 mm on main and now)."""
    seq, counter, t_s, left, right = (list(c) for c in zip(*RESTARTS, strict=True))
    assert _gate_lefts("kobuki", seq, counter, left, right, t_s) == [
        None, *(d or None for d in RESTARTS_LEFT)]
    n = len(seq)
    enc = Encoders(index=np.arange(n, dtype=np.int64), counter=np.array(counter),
                   seq=np.array(seq), left=np.array(left), right=np.array(right),
                   timestamp_s=np.array(t_s), cycle_s=CYCLE_S, uptime=np.zeros(n, dtype=np.int64))
    whole = firmware_steps(enc, 0, Geometry.of(load("kobuki")), 16, PROFILE_SPEED)
    assert whole.d_left.tolist() == RESTARTS_LEFT


DRIVES = {  # name: robot, seed; FAILed on main 0470678f by (run, analyze whole and streamed;
    # the first step the judges now take as the firmware did)
    "pmir_5": ("pmir", 5),  # 86.0 mm (4.93 s)
    "kobuki_5": ("kobuki", 5),  # 75.7 mm
    "kobuki_6": ("kobuki", 6),  # DISTANCE 1.16 mm beyond its tolerance (6.59 s)
    # 847 mm: the reference 816 mrad off the firmware's heading from 4.76 s (4.44 s), 977 mrad
    # from 8.24 s (7.72 s)
    "kobuki_8": ("kobuki", 8),
    # 72.2 mm: the reference turned 500 mrad the firmware did not from the sample of 5.93 s
    # (5.93 s), across the CTRL_UPTIME restarts told at 5.85 and 5.93 s
    "kobuki_10": ("kobuki", 10),
}


def _drive(root: Path, robot: str, seed: int) -> tuple[Path, bool, int]:
    log = root / "drive.log"
    with watched(robot) as watch:
        code = main(["run", "--robot", robot, "--seed", str(seed), "--duration", "10",
                     "--faults", "delay=0.5:150", "--firmware", "python", "--log", str(log)])
    return log, watch.steps > 400 and watch.within_a_thousandth_lsb(), code


@pytest.mark.parametrize("name", sorted(DRIVES))
def test_the_correct_firmware_passes(name: str, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    log, correct, code = _drive(tmp_path, *DRIVES[name])
    assert correct
    assert [code, *both_analyses(log)] == [0, 0, 0]
    capsys.readouterr()


TAMPERED = {  # X raised 10 mm from 4.5 s: beyond the allowance (whole, streamed) as measured
    "kobuki_5": 7.76e-3,
    "kobuki_8": 7.09e-3,
}
ABSORBED = ("pmir random 5, X +10 mm from 4.5 s PASSes (0.0 mm beyond, whole and streamed): the "
            "first sample raised lies in the segment opened at encoder frame 221, whose "
            "placement may step 54.0 mm from the one before (the gaps of the accepted stream "
            "since: 38.3, 3.24 and 12.4 mm, gapbound's travel over the frames missing): it "
            "absorbs 10.0 mm; the delay leaves 99 such gaps, and from 5.0 s the tamper PASSes "
            "alike (a judge's limit under this delay, not this fix's)")


@pytest.mark.parametrize("name", [*sorted(TAMPERED), pytest.param(
    "pmir_5", marks=pytest.mark.xfail(strict=True, reason=ABSORBED))])
def test_x_10_mm_off_from_4_5_s_fails(name: str, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    log, _, _ = _drive(tmp_path, *DRIVES[name])
    tampered = tmp_path / "t.log"
    assert raise_x_10_mm(log, tampered, 4.5) > 200
    wrong = fails_by_position(tampered, tmp_path)
    capsys.readouterr()
    assert wrong == []
