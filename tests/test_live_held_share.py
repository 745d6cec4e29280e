"""A mildly delayed bus leaves the live verdict HELD for short spells only (issue #11: usability;
rule 5: a FAIL never blames a correct firmware, an OK never hides a wrong pose).

Under ``delay=0.1:20`` (a tenth of the frames 20 ms late on the bus) the monitor held every
frame from an encoder frame whose stamps read three ways (a bus that delays it and a recorder
that stamped it late look alike) for a fixed 1.36 s, the ENC_E2E pages' time, then again from
the next: HELD for 45..85 % of a 10 s drive (pmir figure8 seed 3: 85 %, first judged OK at
5.85 s; kobuki random seed 5: 82 %), though the firmware's poses had settled each such frame
within 0.2 s. Now a hold ends once they have (``host.judge.liveearly``): 17..46 % over pmir and
kobuki, seeds 1..5, here 38 % and 46 %. The frames taken are still the whole log's, ``run`` and
both ``analyze`` PASS the correct firmware, and X raised 10 mm from 5 s FAILs every judge. The
firmware's own DEGRADED (ENCODER_TIMEOUT, its encoder frames late), whose summaries waited in the
held frames, now shows between the holds.
"""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from odocan.host.io.logs import read_log
from odocan.host.judge.monitor import BusMonitor
from odocan.host.protocol.e2e import check_frames
from odocan.sim.robot import load
from tests.judges_cli import both_analyses, correct_drive, live_judges, x_10_mm_off_fails

FAULTS = "delay=0.1:20"
DRIVES = {"pmir_figure8_3": ("pmir", "figure8", 3), "kobuki_random_5": ("kobuki", "random", 5)}
DURATION_S = 10
SAMPLE_S = 0.05  # the verdict read this often (a screen's refresh)
MOST_HELD = 0.5  # the share of the drive's samples HELD at most (before: 0.85 and 0.82)
FIRST_OK_S = 1.5  # the first judged OK by this bus time (before: 5.85 s on pmir seed 3)
TAMPER_FROM_S = 5.0
FOUND_WITHIN_S = 1.5  # the tamper's POSE WRONG found within this after it starts (s)
WRONG = ("POSE WRONG", "DISTANCE WRONG", "TWIST WRONG")


@pytest.fixture(scope="module", params=sorted(DRIVES))
def drive(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
          ) -> tuple[str, Path]:
    """The delayed drive's robot and its log, the correct firmware's (``correct_drive``)."""
    robot, scenario, seed = DRIVES[request.param]
    log = tmp_path_factory.mktemp(request.param) / "drive.log"
    return robot, correct_drive(log, robot, scenario, seed, DURATION_S, FAULTS)


def _states(robot: str, log: Path) -> tuple[list[tuple[float, str]], BusMonitor]:
    """The monitor's verdict every ``SAMPLE_S`` of bus time as it hears ``log`` (bus time s,
    state), and the monitor, its held frames judged at the watch's end."""
    monitor = BusMonitor(load(robot))
    states: list[tuple[float, str]] = []
    next_s: float | None = None
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            next_s = msg.timestamp if next_s is None else next_s
            while msg.timestamp >= next_s:
                states.append((next_s, monitor.health(now_s=next_s)["state"]))
                next_s += SAMPLE_S
            monitor.feed(msg, now_s=msg.timestamp)
    monitor.release_held()
    return states, monitor


def test_the_verdict_is_held_for_short_spells(drive: tuple[str, Path]) -> None:
    """Before: HELD 85 % (pmir) and 82 % (kobuki) of the drive, first OK at 5.85 s (pmir)."""
    robot, log = drive
    states, _ = _states(robot, log)
    held = sum(state == "HELD" for _, state in states) / len(states)
    assert held <= MOST_HELD, held
    first_ok_s = next(t_s for t_s, state in states if state == "OK")
    assert first_ok_s <= FIRST_OK_S, first_ok_s
    assert not [s for _, s in states if s in WRONG]


def test_every_judge_passes_the_correct_firmware_on_the_whole_logs_frames(
        drive: tuple[str, Path]) -> None:
    """The live judges (monitor, bridge) take the frames the whole log's check takes; ``run``
    (``correct_drive``) and both ``analyze`` PASS, and so does the monitor's placement."""
    robot, log = drive
    whole_taken = check_frames(read_log(log))[0]["WHEEL_ENCODERS"]["ok"]
    monitor, bridge = live_judges(robot, log)
    monitor.release_held()
    bridge.hold.release(ends=True)
    assert monitor.e2e.counts()["WHEEL_ENCODERS"]["ok"] == whole_taken
    assert bridge.e2e.counts()["WHEEL_ENCODERS"]["ok"] == whole_taken
    assert monitor.settle.early.reads > 0  # the holds ended early (liveearly)
    assert both_analyses(log) == [0, 0]
    ref = monitor.tracker.vs_reference
    assert ref.max_dpos_m <= 1e-4, ref.max_dpos_m


def test_x_10_mm_off_from_5_s_fails_live_at_once(drive: tuple[str, Path], tmp_path: Path
                                                 ) -> None:
    """The tamper FAILs both ``analyze`` by the position, and the monitor says POSE WRONG
    within ``FOUND_WITHIN_S`` of it, never OK once the tampered poses are heard."""
    robot, log = drive
    tampered = tmp_path / "tampered.log"
    assert x_10_mm_off_fails(log, tampered, TAMPER_FROM_S, more_than=200) == []
    states, _ = _states(robot, tampered)
    after = [(t_s, state) for t_s, state in states if t_s > TAMPER_FROM_S + SAMPLE_S]
    found_s = next(t_s for t_s, state in after if state == "POSE WRONG")
    assert found_s - TAMPER_FROM_S <= FOUND_WITHIN_S, found_s
    assert "OK" not in {state for _, state in after}
