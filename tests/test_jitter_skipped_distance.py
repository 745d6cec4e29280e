"""ODOM_TWIST DISTANCE where a jittered capture made the host's E2E take encoder frames the
firmware refused (issue #11, rule 5: a FAIL never blames a correct firmware, a PASS never hides
a wrong DISTANCE).

Found on an hour of kobuki (``run --duration 3600 --seed 3 --faults delay=0.1:15,seed=7``), its
stamps moved 0..3 ms (``test_capture_jitter._jittered``, seed 1): the whole-log and the streamed
``analyze`` FAILed the correct firmware ("ODOM_TWIST DISTANCE off by 0.813 mm beyond its
tolerance"); the log as recorded PASSed. The host's E2E counts the window's periods from the bus
times: under jitter it took frames the firmware's receiver refused (there, sequence 10993, 11014
and 11015 after a delay), and its path stepped through them where the firmware's merged step
was shorter (the midpoint reversing). The firmware's ENC_E2E_OK shows it: it grew by fewer than
the host's accepted frames between those pages (``losses.ok_count_spans``, ``skipdefect``).
Shown here on a minute of kobuki (seed 6, ``delay=0.1:15,seed=7``, jitter seed 2), which main
FAILed by 0.505 mm.

The verdict is the float64 checker's (``test_twist_jitter_distance._float64_distance_off_mm``:
the firmware's DISTANCE against the float64 path of the frames its receiver took, its own
record, which the judges never see).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path

import pytest

import odocan.firmware.odometry as odometry
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.sim.robot import load
from tests.firmware_patch import after_lock_outs, distance_taken_off, edited_after
from tests.test_capture_jitter import _jittered
from tests.test_live_jitter_lockout import _frames_taken
from tests.test_twist_jitter_distance import (
    WIRE_MM,
    _float64_distance_off_mm,
    _live_distance_passes,
)

DRIVE = ("kobuki", 60, 6, "delay=0.1:15,seed=7")  # robot, s, seed, faults
JITTER_SEED = 2
DROP_EVERY = 700  # the dropping firmware: every 700th step of its odometry left out


@contextmanager
def _dropping_steps() -> Iterator[list[int]]:
    """The Python firmware, but every ``DROP_EVERY``-th step of its odometry not made (a frame
    its receiver took, counted in ENC_E2E_OK, never integrated); yields [steps dropped]."""
    step, calls, dropped = odometry.Odometry.step_deltas, [0], [0]

    def stepped(self: odometry.Odometry, d_left: int, d_right: int) -> None:
        calls[0] += 1
        if calls[0] % DROP_EVERY == 0 and (d_left or d_right):
            dropped[0] += 1
            return
        step(self, d_left, d_right)

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(odometry.Odometry, "step_deltas", stepped)
        yield dropped


def _drive(tmp_path: Path, wrong: AbstractContextManager[list[int]]
           ) -> tuple[Path, list[float], int, int]:
    """``DRIVE`` under ``wrong`` (the patched Python firmware), its capture jittered: the
    capture, the checker's offsets (mm), the edits made and the frames the firmware took."""
    robot, duration_s, seed, faults = DRIVE
    log, moved = tmp_path / "drive.log", tmp_path / "moved.log"
    with _frames_taken() as taken, wrong as done:
        main(["run", "--robot", robot, "--duration", str(duration_s), "--seed", str(seed),
              "--faults", faults, "--log", str(log), "--firmware", "python"])
    _jittered(log, moved, JITTER_SEED)
    return moved, _float64_distance_off_mm(log, robot, taken), done[0], len(taken)


def _distance_verdicts(moved: Path) -> tuple[dict[str, bool], int]:
    """The DISTANCE verdict of the whole-log and the streamed analyze and the live judge's
    (``livedistance``), and the encoder frames the host's E2E took."""
    robot = DRIVE[0]
    whole = analyze(read_log(moved), load(robot)).report
    streamed = moved.with_suffix(".json")
    main(["analyze", str(moved), "--robot", robot, "--stream", "always",
          "--report", str(streamed)])
    streamed_report = json.loads(streamed.read_text())
    return ({"whole": whole["onboard_distance_vs_reference"]["passed"],
             "streamed": streamed_report["onboard_distance_vs_reference"]["passed"],
             "live": _live_distance_passes(moved, robot)},
            int(whole["e2e"]["WHEEL_ENCODERS"]["ok"]))


def test_a_correct_firmware_passes_where_the_host_took_frames_it_refused(
        tmp_path: Path) -> None:
    moved, offs, _, taken = _drive(tmp_path, nullcontext([0]))
    assert len(offs) > 2000
    assert max(map(abs, offs)) <= WIRE_MM  # the checker: the firmware is right
    verdicts, host_ok = _distance_verdicts(moved)
    assert host_ok > taken  # the host took frames the firmware refused
    assert all(verdicts.values()), verdicts


@pytest.mark.parametrize("wrong", ["2 LSB low after its first lock-out", "drops steps"])
def test_a_wrong_distance_still_fails(tmp_path: Path, wrong: str) -> None:
    firmware = (edited_after(lambda t: after_lock_outs(t) and t.done == 0,
                             distance_taken_off(2))
                if wrong.startswith("2") else _dropping_steps())
    moved, offs, done, _ = _drive(tmp_path, firmware)
    assert done >= 1
    assert min(offs) <= 0.5 - 2, min(offs)  # the checker: at least 2 mm low somewhere
    verdicts, _ = _distance_verdicts(moved)
    assert not any(verdicts.values()), verdicts
