"""A simulator that pauses and then floods its backlog (issue #11, HIGH, an outside trial: a
FAIL must never blame a correct firmware). ``odocan sim`` SIGSTOPped 3 s and continued sent
the ~300 frames it skipped back to back; the firmware's 32-slot mailbox kept the first and
dropped the rest (262 counted), merged the steps it lost into one and said MAILBOX_OVERFLOW and
POSE_UNCERTAIN, as documented. The judges said POSE WRONG (3.6 mm, allowing 0.098 mm) and
ODOM_TWIST off by 410 mm/s, exit 1:

* ENC_E2E_LOST is a u8: 262 lost read as 6 (the allowance was six frames'). It is unwrapped by
  ENC_E2E_OK (u16), which grew by 84 of the log's 347 frames (``losses.unwrapped_lost``);
* a twist repeating its predecessor's ENC_COUNTER across the flood was carried as a resend of
  the frame before the silence and judged in that window (0.05 m/s against 0.46): not carried
  over a lap of frames (``samples.lapped_out``);
* with a fitted start (a log that begins mid-drive) the start's rotation leaned on the samples
  after the merge, 0.17 mm off before it (``fitsegments``);
* a pose made in the flood names its frame by the 4-bit COUNTER: the judges paired it with
  the latest frame of that COUNTER on the bus, laps after the one the firmware had (1 s pause:
  397 mm, 6 s: 1.98 m, every judge). Its HEADING now tells the frame (``floodnames``,
  ``livefloodnames``; ``tests/test_sim_backlog_flood_names.py``: a wrong pose there FAILs).

Left open (strict xfail): the loss span's allowance is every run's worst case, not the merge
the firmware made (8.47 mm on the Python firmware's trial log, its merge 3.3 mm).

Lockstep pmir (``tests.sim_backlog``): the simulator's frames held ``PAUSE`` ticks and let out
together; the firmware's poses checked with the tests' float64 odometry on cantools-decoded
frames."""

from __future__ import annotations

import json
import math
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.sim.board import TICK_S
from tests.sim_backlog import PMIR, paused_drive
from tests.sweeps import sample
from tests.test_first_second_reboot import _decoded, _reencoded, _written
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live, _poses

AT = 400  # the first tick the simulator is paused (4 s)
KEPT = 17  # encoder frames among the 32 the mailbox took of the flood (SIM_TRUTH, MOTOR_CMD too)
FILES = Path(__file__).parent / "files"
TRIALS = ("c", "python")  # the trial's logs: sim_sigstop_3s_{c,python}.blf


def _flood(paused: int, scenario: str = "circle", firmware: str = "python"
           ) -> tuple[can.Message, ...]:
    return paused_drive(AT, paused, scenario, run_s=(AT + paused) * TICK_S + 6.0,
                        firmware=firmware)


def _gap_m(messages: tuple[can.Message, ...], path: list[int], pose: dict[str, float]) -> float:
    enc = [_decoded(m) for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    odo = _odometry(enc, path)
    return math.hypot(odo.x - pose["X"] * 1e-4, odo.y - pose["Y"] * 1e-4)


def test_the_firmware_took_the_mailbox_then_one_step_and_its_count_wrapped() -> None:
    """The premise (3 s): ENC_E2E_LOST grew by 284 mod 256; its first pose after the flood is
    frames ``AT`` .. ``AT + 16`` one by one (its mailbox), the second those then one step to
    ``AT + 301`` (the tick after the flood), then ``AT + 302`` (float64, within an LSB); the fine
    path is 0.5 mm away."""
    messages = _flood(300)
    pages = [_decoded(m) for m in messages if m.arbitration_id == fr.ODOM_STATUS_ID]
    lost = [p["ENC_E2E_LOST"] for p in pages if p["PAGE"] == 2]
    assert sorted(set(lost)) == [0, 284 - 256]
    first, second = _poses(messages, (AT + 300) * TICK_S)[:2]
    assert int(first["ENC_COUNTER"]) == (AT + KEPT - 1) % 16
    assert _gap_m(messages, list(range(AT + KEPT)), first) <= POSITION_LSB_M
    merged = [*range(AT + KEPT), AT + 301, AT + 302]
    assert int(second["ENC_COUNTER"]) == (AT + 302) % 16
    assert _gap_m(messages, merged, second) <= POSITION_LSB_M
    assert _gap_m(messages, list(range(AT + 303)), second) > 4 * POSITION_LSB_M


@pytest.mark.parametrize(("paused", "scenario", "firmware"), [
    (100, "circle", "python"), (300, "circle", "python"), (600, "circle", "python"),
    (300, "straight", "python"), (300, "figure8", "python"), (300, "circle", "c")])
def test_the_correct_firmware_passes_every_judge(paused: int, scenario: str, firmware: str,
                                                 tmp_path: Path) -> None:
    """1 s, 3 s, 6 s pauses: 3 s on the figure 8 FAILed analyze before (0.60 mm: ENC_E2E_LOST
    read mod 256); 1 s and 6 s on the circle FAILed every judge (a pose in the flood paired
    with a frame laps after the one it named: 397 mm, 1.98 m; now named by its HEADING)."""
    messages = _flood(paused, scenario, firmware)
    path = _written(messages, tmp_path / "flood.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    report = analysis.report
    assert analysis.passed, (report["onboard_vs_reference"], report["onboard_twist_vs_reference"])
    assert report["onboard_twist_vs_reference"]["passed"]
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] == 0
    assert not monitor.twist.wrong
    assert not bridge.twist.wrong
    assert bridge.tracker.wrongs.as_dict()["episodes"] == 0
    assert monitor.distance.as_dict()["passed"]


def _biased(messages: tuple[can.Message, ...], from_s: float, lsb: int
            ) -> tuple[can.Message, ...]:
    """Every ODOM_POSE_X from bus time ``from_s`` on ``lsb`` off (E2E re-protected)."""
    out = []
    for m in messages:
        if m.arbitration_id == fr.ODOM_POSE_X_ID and m.timestamp >= from_s:
            signals = _decoded(m)
            signals["X"] += lsb
            m = _reencoded(m, signals, fr.ODOM_POSE_X_DATA_IDS)
        out.append(m)
    return tuple(out)


def _trial(name: str) -> tuple[tuple[can.Message, ...], float]:
    """A trial's log (``TRIALS``) and the bus time its flood began (the end of the longest
    silence of the encoder frames)."""
    messages = tuple(can.LogReader(str(FILES / f"sim_sigstop_3s_{name}.blf")))
    enc_t = [m.timestamp for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    gap = max(range(len(enc_t) - 1), key=lambda k: enc_t[k + 1] - enc_t[k])
    return messages, enc_t[gap + 1]


def _source(name: str) -> tuple[tuple[can.Message, ...], float]:
    return (_flood(300), (AT + 300) * TICK_S) if name == "lockstep" else _trial(name)


@pytest.mark.parametrize("name", TRIALS)
def test_the_trials_logs_pass_every_judge(name: str, tmp_path: Path) -> None:
    """The trial's own logs (``odocan sim`` SIGSTOPped 3 s on the circle, real time; C and
    Python firmware): before, analyze FAILed (3.55 mm beyond 0.098 mm, ODOM_TWIST 410 mm/s
    off on the C firmware's) and the monitor showed POSE WRONG (414 samples)."""
    messages, _ = _trial(name)
    path = FILES / f"sim_sigstop_3s_{name}.blf"
    report = tmp_path / "report.json"
    assert main(["analyze", str(path), "--robot", "pmir", "--report", str(report)]) == 0
    assert json.loads(report.read_text())["onboard_twist_vs_reference"]["passed"]
    assert main(["analyze", str(path), "--robot", "pmir", "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] == 0
    assert bridge.tracker.wrongs.as_dict()["episodes"] == 0
    assert not monitor.twist.wrong
    assert not bridge.twist.wrong


LOOSE = pytest.mark.xfail(strict=True, reason=(
    "the Python firmware's trial: 266 frames lost among 350 allow 8.47 mm (every set of runs "
    "merged, losses.loss_allowance); the firmware's merge was 3.3 mm, +10 mm X lands 7.5 mm off"))


@pytest.mark.parametrize(("name", "lsb", "after_s"), [
    *sample([(name, lsb, after_s) for name in ("lockstep", "c") for lsb in (100, -100, 10_000)
             for after_s in (0.0, 0.5)], 3, [("lockstep", 100, 0.0), ("c", -100, 0.5)]),
    *[("python", lsb, after_s) for lsb in (-100, 10_000) for after_s in (0.0, 0.5)],
    *[pytest.param("python", 100, after_s, marks=LOOSE) for after_s in (0.0, 0.5)]])
def test_ten_mm_or_one_m_after_the_flood_fail_every_judge(name: str, lsb: int, after_s: float,
                                                          tmp_path: Path) -> None:
    """X 10 mm (either way) or 1 m off from the flood on (or 0.5 s after it): FAIL whole,
    streamed and live. On the C firmware's trial +10 mm from the flood on FAILs by 0.39 mm
    only: the judge takes the flood for a stall (its names left out, the poses before it name
    the frame before the silence) and places the reference again within the merge bound of
    every set of runs lost there (9.6 mm); on the Python firmware's, the loss span's bound
    (8.47 mm) keeps +10 mm X within it (xfail, strict: the allowance is every run's worst
    case, not the merge the firmware made)."""
    messages, flood_s = _source(name)
    messages = _biased(messages, flood_s + after_s, lsb)
    path = _written(messages, tmp_path / "wrong.log")
    analysis = analyze(read_log(path), PMIR, None if name in TRIALS else "exact")
    vs_ref = analysis.report["onboard_vs_reference"]
    print(f"\n{name} {lsb} {after_s}: {vs_ref}")
    assert not analysis.passed
    assert vs_ref["max_position_error_beyond_allowance_m"] > 2 * POSITION_LSB_M
    assert main(["analyze", str(path), "--robot", "pmir", "--stream", "always"]) == 1
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] >= 1
    assert bridge.tracker.wrongs.as_dict()["episodes"] >= 1
