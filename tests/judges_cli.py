"""The CLI's judges on a log, as the fault tests call them: a drive recorded by the Python
firmware under the tests' watch, ``analyze`` whole and streamed, the tests' tamper (X 10 mm off
from a time on) and its FAIL by the position (a FAIL by the heading alone says nothing: a
correct firmware can FAIL by it too), and a log's raw signals decoded by cantools (not the
host's decoder)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import can
import cantools
from cantools.database.can import Database

from odocan.host.cli.app import main
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.contract import DBC_PATH
from odocan.sim.robot import RobotProfile, load
from tests.fw_watch import Watch, watched
from tests.independent_checker import HEADING_LSB_RAD, POSITION_LSB_M
from tests.log_edit import raise_raw, raise_raw_once

STREAMS = ("never", "always")
POSE_X = (2, 4)  # ODOM_POSE_X's X: bytes 2..5, signed, 0.1 mm
TEN_MM_LSB = 100  # 10 mm in ODOM_POSE_X's 0.1 mm LSBs


def analyze(log: Path, stream: str, report: Path | None = None) -> int:
    """``odocan analyze LOG --stream STREAM [--report REPORT]``'s exit code."""
    extra = [] if report is None else ["--report", str(report)]
    return main(["analyze", str(log), "--stream", stream, *extra])


def both_analyses(log: Path) -> list[int]:
    """analyze's exit codes, whole then streamed."""
    return [analyze(log, s) for s in STREAMS]


def reported_analyses(log: Path, work: Path) -> list[tuple[str, int, dict[str, Any]]]:
    """(stream, exit code, JSON report) of analyze's whole and streamed analyses of ``log``, each
    report written to ``work / f"{stream}.json"``."""
    judged: list[tuple[str, int, dict[str, Any]]] = []
    for s in STREAMS:
        code = analyze(log, s, work / f"{s}.json")
        judged.append((s, code, json.loads((work / f"{s}.json").read_text())))
    return judged


def fails_by_position(tampered: Path, work: Path, beyond_m: float = 5e-3) -> list[str]:
    """What is wrong with the tampered log's verdicts (nothing: ``[]``): each analysis must exit
    1 with the position beyond its allowance by more than ``beyond_m``."""
    wrong = []
    for s, code, report in reported_analyses(tampered, work):
        beyond = report["onboard_vs_reference"]["max_position_error_beyond_allowance_m"]
        if code != 1 or beyond <= beyond_m:
            wrong.append(f"--stream {s}: exit {code}, position {beyond * 1e3:.4g} mm beyond")
    return wrong


def raise_x_10_mm(log: Path, tampered: Path, from_s: float) -> int:
    """Copy ``log`` to ``tampered`` with ODOM_POSE_X's X raised 10 mm (``TEN_MM_LSB``) from
    ``from_s`` s after the log's first frame on, each raised frame re-signed by cantools
    (``tests.log_edit.raise_raw``): the number of frames raised."""
    return raise_raw(log, tampered, "ODOM_POSE_X", POSE_X, TEN_MM_LSB, from_s)


def raise_first_x(log: Path, tampered: Path, lsb: int, from_s: float, before_s: float) -> None:
    """Copy ``log`` to ``tampered`` with the X of only the first ODOM_POSE_X at or after
    ``from_s`` s raised by ``lsb`` (0.1 mm), re-signed (``tests.log_edit.raise_raw_once``); that
    pose asserted heard before ``before_s``."""
    times = raise_raw_once(log, tampered, "ODOM_POSE_X", POSE_X, lsb, from_s)
    assert len(times) == 1, times
    assert from_s <= times[0] < before_s, (times, from_s, before_s)


def x_10_mm_off_fails(log: Path, tampered: Path, from_s: float, more_than: int) -> list[str]:
    """What is wrong with the verdicts on ``log`` with X 10 mm off from ``from_s`` s on
    (``raise_x_10_mm`` into ``tampered``, more than ``more_than`` frames raised: asserted), as
    ``fails_by_position`` tells it (its reports beside ``tampered``): ``[]`` when each analysis
    FAILs it by the position."""
    raised = raise_x_10_mm(log, tampered, from_s)
    assert raised > more_than, (raised, more_than)
    return fails_by_position(tampered, tampered.parent)


def watched_run(log: Path, robot: str, scenario: str, seed: object, duration: object,
                faults: str) -> tuple[Watch, int]:
    """``odocan run`` of the drive with the Python firmware, every step watched
    (``tests.fw_watch``), into ``log``: the watch and run's exit code."""
    with watched(robot) as watch:
        code = main(["run", "--robot", robot, "--scenario", scenario, "--seed", str(seed),
                     "--duration", str(duration), "--faults", faults, "--firmware", "python",
                     "--log", str(log)])
    return watch, code


def correct_drive(log: Path, robot: str, scenario: str, seed: object, duration: object,
                  faults: str) -> Path:
    """``log``, recorded by ``watched_run`` and asserted right: run exits 0, and its firmware
    integrated over 300 steps, each within 1/1000 LSB of the float64 check."""
    watch, code = watched_run(log, robot, scenario, seed, duration, faults)
    assert code == 0
    assert watch.steps > 300
    assert watch.within_a_thousandth_lsb(), (watch.worst_m, watch.worst_rad)
    return log


def named_drive(name: str, drives: dict[str, tuple[Any, ...]], tmp_dir: Path
                ) -> tuple[str, Path]:
    """(``name``, its log in ``tmp_dir``): ``drives[name]``'s first five (robot, scenario,
    seed, duration, faults) recorded by ``correct_drive``, as the tests' module-wide drive
    fixtures take them."""
    return name, correct_drive(tmp_dir / "drive.log", *drives[name][:5])


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    """``odocan ARGS`` in a process of its own, this tree first on its path (a replay's state
    left in no module of the test process)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, env=env, check=False)


def raw_signals(log: Path, names: tuple[str, ...]) -> list[tuple[float, str, dict[str, Any]]]:
    """(time s, message, raw signal values, choices as numbers) of the frames of the messages
    ``names`` in ``log``, in order, decoded by cantools."""
    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, Database)
    wanted = {db.get_message_by_name(n).frame_id: n for n in names}
    out: list[tuple[float, str, dict[str, Any]]] = []
    with can.LogReader(str(log)) as reader:
        for msg in reader:
            if msg.arbitration_id in wanted:
                name = wanted[msg.arbitration_id]
                signals = db.get_message_by_name(name).decode(bytes(msg.data), scaling=False,
                                                              decode_choices=False)
                assert isinstance(signals, dict)
                out.append((msg.timestamp, name, signals))
    return out


def live_judges(robot: str, log: Path) -> tuple[BusMonitor, RobotTelemetry]:
    """The monitor and the bridge's judge for ``robot``, each fed ``log`` frame by frame."""
    with can.LogReader(str(log)) as reader:
        return fed_judges(load(robot), reader)


def fed_judges(profile: RobotProfile, messages: Iterable[can.Message],
               integrator: str | None = None) -> tuple[BusMonitor, RobotTelemetry]:
    """The monitor (told ``integrator``, None: from the bus) and the bridge's judge for
    ``profile``, each fed ``messages`` one by one at their bus time."""
    monitor = BusMonitor(profile) if integrator is None else BusMonitor(profile, integrator)
    bridge = RobotTelemetry("r1", Geometry.of(profile), "exact",
                            counter_bits=profile.counter_bits)
    for msg in messages:
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(msg)
    return monitor, bridge


def assert_live_pass(robot: str, log: Path, starts: int = 2) -> None:
    """The monitor and the bridge fed ``log`` (a correct firmware's) started the reference at
    least ``starts`` times and judged every pose within 1 LSB beyond the allowance and in
    heading."""
    for judge in live_judges(robot, log):
        tracker = judge.tracker
        assert tracker.reference_starts >= starts
        assert tracker.max_beyond_allowance_m <= POSITION_LSB_M, tracker.max_beyond_allowance_m
        assert tracker.vs_reference.max_dheading_rad <= HEADING_LSB_RAD


def assert_tamper_wrong_live(robot: str, log: Path, tampered: Path, from_s: float) -> None:
    """``log`` with X raised 10 mm from ``from_s`` on (``raise_x_10_mm``, over 100 frames) is
    more than 9 mm beyond the allowance for the monitor and the bridge."""
    assert raise_x_10_mm(log, tampered, from_s) > 100
    for judge in live_judges(robot, tampered):
        assert judge.tracker.max_beyond_allowance_m > 9e-3
