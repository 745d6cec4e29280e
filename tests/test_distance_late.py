"""ODOM_TWIST DISTANCE after frames the bus let through late (issue #11: a FAIL must never blame
a correct firmware, a PASS never hide a wrong pose).

kobuki circle 652, 9 s, ``busoff=3.1:0.3,stall=5.5:0.2,delay=0.3:55``: every judge FAILed, DISTANCE
1.99 mm beyond its tolerance, the pose within it. The firmware was wrong: after the bus-off it
integrated COUNTER 3 and 4, SENT BEFORE the COUNTER 5 it had integrated (held 55 ms, then by the
bus-off): steps of +156, -104 and +52 counts (left) where the wheels turned +104, every count
forward (the sender's own order, recorded here). The pose nets out (absolute counts); DISTANCE
counted the way back and forth (and again after the stall: COUNTER 0 after 3), 50.0 mm above
the wheels' path at the end. Pinned (``HELD``): a firmware that drops, before its E2E check, a
frame sampled inside a step it integrated already whose step back the bound would pass (branch
distlate, commits ea44d5b3 and a0114f90, reverted) PASSes every test here and every judge, but
the judges then read its pose held over the dropped frames as a firmware hold and re-place the
reference across it with a wide allowance: a +10 mm pose step after a bus-off PASSed
(``tests/test_edge_tamper.py``, kobuki random 241). The judges must learn that rule first.

kobuki circle 714, 9 s, ``drop=0.05,stall=1.5:0.3,delay=0.3:150``: DISTANCE 74.5 mm beyond, the
pose met: not the same cause. The judge was wrong: the firmware, back from its stall, took the
frame of COUNTER 6 sampled at 1.66 s and heard at 1.81 s (held 150 ms), which the host's E2E
refused; its twist named it, and the name resolved to the frame of COUNTER 6 of 1.82 s, 80 mm
on (``host.judge.earlytwins``: such a name is left out): every judge PASSes it now. Still wrong
in the firmware there, and pinned below (``FORWARD``): frames
held back 150 ms come as the E2E successor of the latest one (the COUNTER came round), the bound
refuses them, and three of them in a row are taken for a counter restart: re-primed on a frame
sent 15 periods earlier and stepped through again (the judge's reference re-primes as it does:
no judge FAILs it).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from odocan.firmware import encoders as fe
from odocan.host.cli.app import main
from odocan.sim import motor_controller as mc
from odocan.sim.robot import load
from tests.fw_watch import Watch, watched
from tests.judges_cli import reported_analyses, x_10_mm_off_fails
from tests.log_edit import raise_raw

DISTANCE = (6, 2)  # ODOM_TWIST's DISTANCE: bytes 6..7, 1 mm
TEN_MM_DISTANCE_LSB = 10  # 10 mm in DISTANCE's 1 mm LSBs
FORWARD = ("a firmware step goes back in the sender's order: after a counter restart taken on "
           "frames held back 150 ms (three in a row, each the E2E successor of the latest "
           "frame: the COUNTER came round), the firmware re-primes on a frame sent 15 periods "
           "earlier and steps through them again (firmware.encoders._on_implausible); the judge's "
           "reference re-primes as it does")
HELD = ("kobuki circle 652: the firmware integrates COUNTER 3 (send 307) after COUNTER 5 (send "
        "309), both let out after the bus-off, and COUNTER 0 (send 544) after 3 (547) past the "
        "stall: steps back in the sender's order, DISTANCE 50.0 mm above the wheels' path, 1.99 "
        "mm beyond the judges' tolerance. The fix (drop such a frame before E2E) is held back: "
        "the judges then give the bus-off's held pose a hold's allowance (kobuki random 241: a "
        "+10 mm pose step PASSed, tests/test_edge_tamper.py)")
# name: (robot, scenario, seed, duration s, faults, the tamper's start times s, None or the
#        strict xfail's reason of the sender-order tests, of the verdict tests)
DRIVES = {
    "busoff_held": ("kobuki", "circle", 652, 9, "busoff=3.1:0.3,stall=5.5:0.2,delay=0.3:55",
                    (3.45, 5.8), HELD, HELD),
    "stall_early_twin": ("kobuki", "circle", 714, 9, "drop=0.05,stall=1.5:0.3,delay=0.3:150",
                         (1.85, 2.0), FORWARD, None),
}


@dataclass
class Drive:
    """A watched drive: its log, run's exit code, the firmware's watch, the sender's frames in
    send order ((COUNTER, left, right) -> send index) and the firmware's accepted frames."""

    log: Path
    code: int
    watch: Watch
    sent: dict[tuple[int, int, int], int] = field(default_factory=dict)
    sent_counts: list[tuple[int, int]] = field(default_factory=list)
    taken: list[tuple[int, int, int]] = field(default_factory=list)
    distance_mm: list[int] = field(default_factory=list)  # DISTANCE after each taken frame


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[str, Drive]:
    name = str(request.param)
    robot, scenario, seed, duration, faults, _, _, _ = DRIVES[name]
    log = tmp_path_factory.mktemp(name) / "drive.log"
    sent: dict[tuple[int, int, int], int] = {}
    sent_counts: list[tuple[int, int]] = []
    taken: list[tuple[int, int, int]] = []
    distance_mm: list[int] = []
    send, accept = mc.MotorController.sample_and_send, fe.EncoderInput._accept

    def recorded_send(node: mc.MotorController) -> int:
        counter = send(node)
        left, right = node.vehicle.encoder_counts()
        mask = (1 << node.vehicle.profile.counter_bits) - 1
        counts = ((left - node._count_offset[0]) & mask, (right - node._count_offset[1]) & mask)
        sent.setdefault((counter, *counts), len(sent_counts))
        sent_counts.append(counts)
        return counter

    def recorded_accept(enc: fe.EncoderInput, counter: int, wire: tuple[int, int],
                        counts: tuple[int, int]) -> None:
        accept(enc, counter, wire, counts)
        taken.append((counter, *wire))
        distance_mm.append((enc._odometry.distance_q40_m * 1000 + (1 << 39)) >> 40)

    with watched(robot) as watch, pytest.MonkeyPatch.context() as patch:
        patch.setattr(mc.MotorController, "sample_and_send", recorded_send)
        patch.setattr(fe.EncoderInput, "_accept", recorded_accept)
        code = main(["run", "--robot", robot, "--scenario", scenario, "--seed", str(seed),
                     "--duration", str(duration), "--faults", faults, "--firmware", "python",
                     "--log", str(log)])
    return name, Drive(log, code, watch, sent, sent_counts, taken, distance_mm)


def test_the_firmware_integrates_the_frames_it_took(drive: tuple[str, Drive]) -> None:
    _, d = drive
    assert d.watch.steps > 300, d.watch.steps
    assert d.watch.within_a_thousandth_lsb(), (d.watch.worst_m, d.watch.worst_rad)


def test_the_wheels_only_turn_forward(drive: tuple[str, Drive]) -> None:
    """The truth the tests below stand on: in the sender's order, no count ever goes back."""
    _, d = drive
    assert len(d.sent_counts) > 800
    assert all(b[0] >= a[0] and b[1] >= a[1] for a, b in itertools.pairwise(d.sent_counts))


def _send_order(d: Drive) -> list[int]:
    """The send index of every frame the firmware took, in the order it took them."""
    return [d.sent[frame] for frame in d.taken]


def test_the_firmware_never_steps_back_in_the_senders_order(
        drive: tuple[str, Drive], request: pytest.FixtureRequest) -> None:
    """652: COUNTER 3 (send 307) taken after COUNTER 5 (send 309), and COUNTER 0 (send 544)
    after 3 (547) past the stall (pinned, ``HELD``)."""
    name, d = drive
    if (reason := DRIVES[name][6]) is not None:
        request.applymarker(pytest.mark.xfail(strict=True, reason=reason))
    order = _send_order(d)
    back = [(a, b) for a, b in itertools.pairwise(order) if b < a]
    assert back == []


def test_distance_is_the_wheels_path(drive: tuple[str, Drive],
                                     request: pytest.FixtureRequest) -> None:
    """The firmware's DISTANCE (its Q40 sum, to the wire's mm) after each frame it took is the
    path of the wheel-axis midpoint over the frames SENT from the first it took to that one
    (every count forward: merged steps lose nothing), within 1 mm (the wire's rounding and the
    per-count constants). 652: 20 mm above it from the bus-off on, 50.0 mm from the stall on
    (pinned, ``HELD``)."""
    name, d = drive
    if (reason := DRIVES[name][6]) is not None:
        request.applymarker(pytest.mark.xfail(strict=True, reason=reason))
    p = load("kobuki").firmware_params()
    m_left = 2 * math.pi * p["wheel_radius_left_nm"] * 1e-9 / p["counts_per_rev"]
    m_right = 2 * math.pi * p["wheel_radius_right_nm"] * 1e-9 / p["counts_per_rev"]
    order = _send_order(d)
    first = d.sent_counts[order[0]]
    worst = 0.0
    for k, index in enumerate(order):
        left, right = (d.sent_counts[index][i] - first[i] for i in (0, 1))
        path_mm = 1e3 * 0.5 * (left * m_left + right * m_right)  # monotone: |sum| = sum |ds|
        worst = max(worst, abs(d.distance_mm[k] - path_mm))
    assert worst <= 1.0, worst


def test_run_and_both_analyzes_pass_the_correct_firmware(
        drive: tuple[str, Drive], tmp_path: Path, capsys: pytest.CaptureFixture[str],
        request: pytest.FixtureRequest) -> None:
    """714 before: FAIL, DISTANCE 74.498 mm beyond (the judge's fault). 652: FAIL, DISTANCE
    1.986 mm beyond (the firmware's fault: pinned)."""
    name, d = drive
    if (reason := DRIVES[name][7]) is not None:
        request.applymarker(pytest.mark.xfail(strict=True, reason=reason))
    judged = reported_analyses(d.log, tmp_path)
    out = capsys.readouterr().out
    assert [d.code, *(code for _, code, _ in judged)] == [0, 0, 0], out[-2500:]
    for s, _, report in judged:
        assert report["onboard_distance_vs_reference"]["passed"], s


@pytest.mark.parametrize("at", [0, 1])
def test_ten_mm_more_distance_after_the_faults_fails(
        drive: tuple[str, Drive], at: int, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """DISTANCE raised 10 mm from just after the held frames (or the early twin) and from after
    the faults: every analysis FAILs it on DISTANCE, by more than 2 mm (four times the wire's
    rounding; the gaps' and merged steps' allowances take the rest)."""
    name, d = drive
    if DRIVES[name][7] is not None:
        pytest.skip("not fixed: the untampered drive FAILs already")
    tampered = tmp_path / "t.log"
    assert raise_raw(d.log, tampered, "ODOM_TWIST", DISTANCE, TEN_MM_DISTANCE_LSB,
                     DRIVES[name][5][at]) > 50
    wrong = []
    for s, code, report in reported_analyses(tampered, tmp_path):
        distance = report["onboard_distance_vs_reference"]
        if code != 1 or distance["passed"] or distance["max_excess_m"] <= 2e-3:
            wrong.append(f"--stream {s}: exit {code}, {distance}")
    capsys.readouterr()
    assert wrong == []


@pytest.mark.parametrize("at", [0, 1])
def test_ten_mm_more_x_after_the_faults_fails_by_the_position(
        drive: tuple[str, Drive], at: int, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    name, d = drive
    if DRIVES[name][7] is not None:
        pytest.skip("not fixed: the untampered drive FAILs already")
    wrong = x_10_mm_off_fails(d.log, tmp_path / "t.log", DRIVES[name][5][at], 50)
    capsys.readouterr()
    assert wrong == []
