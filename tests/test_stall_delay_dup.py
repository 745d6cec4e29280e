"""A firmware stall under a delaying, duplicating bus (issue #11: a FAIL blamed a correct firmware).

pmir, random, seed 2, 12 s, ``delay=0.3:55,dup=0.1,stall=4:6`` FAILed the correct firmware by
252.9 mm (158 of 221 poses judged): the Python firmware's every step, watched and integrated again
in float64 (``tests.fw_watch``), is within 1/1000 LSB. The judge's fault: under the delay the host
pairs few poses (its E2E refuses the reordered pose frames), so the next sample after the 6 s halt
came after the firmware's first poses, and the silence rule read only the silence right before a
sample: the halt was no stall, the reference integrated across it where the firmware re-primed
(its step's bound reached half the counters' range). Now any silence between two samples is a
stall, broken after the last frame a pose named before it (``stalls.inner_silences``,
``last_named_before``), the re-prime's left-out span carries no gap allowance, and the resume rule
judges the first sample after every stall (``stallfirst.resume_across``): without it the told
stall's placement absorbed a pose 10 mm off from the stall's end. The same seed halted 2 s FAILed
13.5 mm and now PASSes; kobuki's 423.3 mm was 2.0 mm, 13.4 mrad.

That kobuki residue: the resumed firmware's first frame was a late one its receive FIFO kept
(COUNTER 10, stamped 3.995 s, sent before the COUNTER 15 it took last at 3.99 s): its E2E
window wide open after the halt, it took it as a step back (watched here, ``firmware.encoders``),
then re-primed on the next fresh frame (6.01 s). The host's E2E, never stalled, refused that
frame, so no pair of accepted frames (f, r) fitted (the nearest, f at 3.98 s, r at 6.03 s, left
13.4 mrad). The judge's rule now (``host.judge.fifolate``): f may be followed by any refused
CRC-right frame of the log stamped after an accepted frame of f's range, taken as one step; the
kobuki drive PASSes (0.055 mm, 0.048 mrad). The 6 s drive's 9.47 mrad is 3.19 mrad (its f too
was such a late frame; it re-primed on a late frame as well: LATE_REPRIME).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from odocan.firmware import encoders as fe
from odocan.host.cli.app import main
from odocan.host.judge.analysis import POSITION_LSB_M
from tests.fw_watch import Watch, watched
from tests.judges_cli import (
    analyze,
    both_analyses,
    raise_x_10_mm,
    raw_signals,
    x_10_mm_off_fails,
)

FAULTS_6S = "delay=0.3:55,dup=0.1,stall=4:6"
FAULTS_2S = "delay=0.3:55,dup=0.1,stall=4:2"
LATE_REPRIME = (
    "issue #11: after the 6 s halt the host's E2E takes the on-time encoder frames the firmware "
    "refused (seq 1000, 1003, 1004) and reads the late COUNTER 7 (seq 999, CTRL_UPTIME 10) as seq "
    "1015, a controller restart (CTRL_UPTIME went back): the reference re-primes there too; the "
    "firmware re-primed on the late seq 996 after a late seq 394 from its FIFO, both frames the "
    "host refused; the late f is now a candidate (fifolate: 9.47 mrad before), the late r is "
    "not: 3.19 mrad off, the position within 0.07 mm (252.9 mm before)")
KOBUKI_2S = (  # before host.judge.fifolate: the firmware's f was a late frame the host refused
    "issue #11: kobuki seed 2 halted 2 s: 2.0 mm, 13.4 mrad off (423.3 mm, 7805 mrad before the "
    "stall was told)")
ABSORBED = (
    "issue #11: on the 6 s drive a pose 10 mm off from the stall's end (10.0 s) FAILs only by the "
    "heading the judge gets wrong on the correct firmware too (6.3 mrad): the resume rule's "
    "re-primed candidates (stallresume: any frame q of the halt re-primed on, the tail turned) "
    "reach within 0.31 mm of it, and the log's gaps after it (late frames read a lap on) are "
    "placed within 1293 mm summed; from 11.0 s it FAILs by 10.0 mm")

Drive = tuple[Path, Watch, int]  # the log, the firmware's watch, run's exit code
Took = tuple[str, int, int]  # the firmware's word on a WHEEL_ENCODERS frame: "acc"/"reprime", L, R


def _drive(root: Path, robot: str, faults: str) -> Drive:
    log = root / f"{robot}.log"
    with watched(robot) as watch:
        code = main(["run", "--robot", robot, "--scenario", "random", "--seed", "2",
                     "--duration", "12", "--faults", faults, "--firmware", "python",
                     "--log", str(log)])
    return log, watch, code


@pytest.fixture(scope="module")
def six(tmp_path_factory: pytest.TempPathFactory) -> Drive:
    return _drive(tmp_path_factory.mktemp("six"), "pmir", FAULTS_6S)


@pytest.fixture(scope="module")
def two(tmp_path_factory: pytest.TempPathFactory) -> Drive:
    return _drive(tmp_path_factory.mktemp("two"), "pmir", FAULTS_2S)


@pytest.fixture(scope="module")
def kobuki_two(tmp_path_factory: pytest.TempPathFactory) -> Drive:
    return _drive(tmp_path_factory.mktemp("ktwo"), "kobuki", FAULTS_2S)


@pytest.mark.parametrize("name", ["six", "two", "kobuki_two"])
def test_the_firmware_integrates_the_frames_it_took(name: str,
                                                    request: pytest.FixtureRequest) -> None:
    _, watch, _ = request.getfixturevalue(name)
    assert watch.steps > 300, watch.steps
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)


def test_the_six_second_halt_is_a_stall_the_firmware_re_primed_across(
        six: Drive, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The halt is told where it was (not only a false one at 2.79 s) and the reference
    re-primes with the firmware: the position within the tolerance (252.9 mm off before)."""
    log, _, _ = six
    analyze(log, "never", tmp_path / "r.json")
    capsys.readouterr()
    report = json.loads((tmp_path / "r.json").read_text())
    stalls = [e["t_s"] for e in report["events"] if e["kind"] == "firmware_stall"]
    reprimes = [e["t_s"] for e in report["events"] if e["kind"] == "stall_reprime"]
    assert any(3.9 <= t <= 4.0 for t in stalls), stalls
    assert len(reprimes) == 1, reprimes
    assert 9.9 <= reprimes[0] <= 10.1, reprimes
    assert report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"] < 1e-4


def _run_and_judges(log: Path, _watch: Watch, code: int,
                    capsys: pytest.CaptureFixture[str]) -> list[int]:
    """run's exit code, then analyze's whole and streamed, on a drive's log."""
    codes = [code, *both_analyses(log)]
    capsys.readouterr()
    return codes


@pytest.mark.xfail(strict=True, reason=LATE_REPRIME)
def test_the_correct_firmware_passes_a_six_second_halt(
        six: Drive, capsys: pytest.CaptureFixture[str]) -> None:
    assert _run_and_judges(*six, capsys) == [0, 0, 0]


def test_the_correct_firmware_passes_a_two_second_halt(
        two: Drive, capsys: pytest.CaptureFixture[str]) -> None:
    """13.5 mm beyond the allowance before: the halt was no stall."""
    assert _run_and_judges(*two, capsys) == [0, 0, 0]


def test_the_correct_firmware_passes_a_two_second_halt_on_kobuki(
        kobuki_two: Drive, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """2.0 mm, 13.4 mrad beyond before (KOBUKI_2S); 0.055 mm, 0.048 mrad now."""
    assert _run_and_judges(*kobuki_two, capsys) == [0, 0, 0]
    analyze(kobuki_two[0], "never", tmp_path / "r.json")
    capsys.readouterr()
    vs = json.loads((tmp_path / "r.json").read_text())["onboard_vs_reference"]
    assert vs["max_position_error_beyond_allowance_m"] < 1e-4
    assert abs(vs["max_heading_error_rad"]) < 1e-4


def _took(monkeypatch: pytest.MonkeyPatch) -> list[Took]:
    """The firmware's accepted and re-primed-on encoder frames, in order (its own word)."""
    took: list[Took] = []
    accept, reprime = fe.EncoderInput._accept, fe.EncoderInput._reprime

    def on_accept(rx: fe.EncoderInput, counter: int, wire: tuple[int, int],
                  counts: tuple[int, int]) -> None:
        took.append(("acc", *wire))
        accept(rx, counter, wire, counts)

    def on_reprime(rx: fe.EncoderInput, counter: int, wire: tuple[int, int],
                   counts: tuple[int, int]) -> None:
        reprime(rx, counter, wire, counts)
        took[-1] = ("reprime", *wire)  # its _accept's entry, said as the re-prime it is

    monkeypatch.setattr(fe.EncoderInput, "_accept", on_accept)
    monkeypatch.setattr(fe.EncoderInput, "_reprime", on_reprime)
    return took


def test_the_resumed_kobuki_firmware_took_a_late_frame_before_it_re_primed(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Why KOBUKI_2S FAILed: the firmware's last frame before its re-prime was sent before the
    last one it took before the halt (a late frame, refused by the host's E2E), read here from
    the firmware's own steps and the log by cantools."""
    took = _took(monkeypatch)
    log = tmp_path / "k.log"
    assert main(["run", "--robot", "kobuki", "--scenario", "random", "--seed", "2",
                 "--duration", "12", "--faults", FAULTS_2S, "--firmware", "python",
                 "--log", str(log)]) == 0
    capsys.readouterr()
    at = [i for i, t in enumerate(took) if t[0] == "reprime"]
    assert len(at) == 1, at
    before_halt, late, reprimed = took[at[0] - 2], took[at[0] - 1], took[at[0]]
    sent = _encoder_frames(log)
    assert sent[before_halt[1:]][0] == pytest.approx(3.99)
    late_s, late_counter = sent[late[1:]]
    assert late_s == pytest.approx(3.995)
    assert (sent[before_halt[1:]][1] - late_counter) % 16 == 5  # sent 5 periods before it
    assert sent[reprimed[1:]][0] == pytest.approx(6.01)


def _encoder_frames(log: Path) -> dict[tuple[int, int], tuple[float, int]]:
    """Each WHEEL_ENCODERS frame's counts: its first stamp (s) and COUNTER (cantools)."""
    out: dict[tuple[int, int], tuple[float, int]] = {}
    for t_s, _, d in raw_signals(log, ("WHEEL_ENCODERS",)):
        out.setdefault((int(d["LEFT_COUNT"]), int(d["RIGHT_COUNT"])),
                       (round(t_s, 4), int(d["COUNTER"])))
    return out


@pytest.mark.parametrize("from_s", [6.0, 8.0])  # the stall's end, and 2 s after it
def test_a_pose_10_mm_off_after_a_two_second_halt_fails(
        two: Drive, from_s: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, _, _ = two
    tampered = tmp_path / "t.log"
    assert raise_x_10_mm(log, tampered, from_s) > 100
    codes = both_analyses(tampered)
    capsys.readouterr()
    assert codes == [1, 1]


@pytest.mark.parametrize("from_s", [6.0, 8.0])  # the stall's end, and 2 s after it
def test_a_pose_10_mm_off_after_kobukis_two_second_halt_fails_by_its_position(
        kobuki_two: Drive, from_s: float, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The late frames f may be followed by (fifolate) absorb no 10 mm: FAIL by the position."""
    wrong = x_10_mm_off_fails(kobuki_two[0], tmp_path / "t.log", from_s, 40)
    capsys.readouterr()
    assert wrong == []


@pytest.mark.parametrize("from_s", [  # the stall's end, and 1 s after (a 12 s drive)
    pytest.param(10.0, marks=pytest.mark.xfail(strict=True, reason=ABSORBED)), 11.0])
def test_a_pose_10_mm_off_after_a_six_second_halt_fails_by_its_position(
        six: Drive, from_s: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """FAIL by the position, beyond the allowance by most of the 10 mm (a FAIL by the heading
    alone says nothing: the correct firmware FAILs by it too)."""
    log, _, _ = six
    wrong = x_10_mm_off_fails(log, tmp_path / "t.log", from_s, 40)
    capsys.readouterr()
    assert wrong == []


def _live_worst(log: Path, robot: str) -> list[float]:
    """The monitor's and the bridge's largest position error beyond the loss allowance (m)."""
    from tests.test_live_reboot import bridge_of, monitor_of

    return [judge(log, robot, "exact").tracker.max_beyond_allowance_m
            for judge in (monitor_of, bridge_of)]


def test_the_live_judges_pass_the_two_second_halt(two: Drive) -> None:
    """The live judges agree with analyze on pmir's 2 s halt: 0.07 mm."""
    assert all(m <= POSITION_LSB_M for m in _live_worst(two[0], "pmir"))


@pytest.mark.xfail(strict=True, reason=(
    "issue #11: the live judges (monitor, bridge) have no resume rule (stallfirst.resume_across) "
    "nor a silence between two samples told a stall (stalls.inner_silences): kobuki seed 2 halted "
    "2 s FAILs the correct firmware 364.18 mm, 7805 mrad beyond the allowance (analyze PASSes "
    "it, fifolate); pmir's 6 s halt 2.26 mm beyond, 5919 mrad (analyze 3.19 mrad, LATE_REPRIME), "
    "a POSE WRONG episode from 11.08 s"))
@pytest.mark.parametrize(("name", "robot"), [("kobuki_two", "kobuki"), ("six", "pmir")])
def test_the_live_judges_pass_the_halts_analyze_fails(
        name: str, robot: str, request: pytest.FixtureRequest) -> None:
    log, _, _ = request.getfixturevalue(name)
    assert all(m <= POSITION_LSB_M for m in _live_worst(log, robot))
