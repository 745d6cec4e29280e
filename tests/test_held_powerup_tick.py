"""The log's own power-up tick held back by the bus is no reboot (issue #11: the verdict's report
must be true).

kobuki random 696, 8 s, ``busoff=1.5:0.2,delay=0.1:150,stall=3.1:0.3``: the firmware's power-up
tick (ODOM_POSE_X COUNTER 0, then the summary COUNTER 0, UPTIME 0, sent at 0.001 s) was held back
150 ms by ``delay`` and heard at 0.151 s, after the poses of COUNTER 1, 3..7 and the summary of
COUNTER 2 (UPTIME 0, 0.101 s). Both broke their message's sequence, the summary 10 ms after its
pose: a power-up tick's signature (``host.judge.bootticks``), which overrode the summary's being
held back (``host.judge.livelatestatus``: it fills a hole of its sender's sequence). Every judge
(run, ``analyze`` whole and streamed, the monitor, the bridge) reported "reboots 1: the firmware
restarted at 0.15 s (power-up)" where none was. Both frames fill a hole of their own sequence:
the old life's frames held back, not a new firmware's (whose COUNTER 0 repeats one heard in
order unless the bus lost the old one too); such a tick is passed over.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from odocan.host.cli.app import main
from odocan.host.judge.sources import SourceWatch
from tests.judges_cli import STREAMS, analyze, x_10_mm_off_fails
from tests.test_live_reboot import bridge_of, monitor_of

HELD = "busoff=1.5:0.2,delay=0.1:150,stall=3.1:0.3"  # tests/test_run_delay_stall.py's drive
POSE, SUMMARY, PAGE = "pose", "summary", "page"
# seed 696's first 0.151 s as heard (kind, bus time s, E2E COUNTER): the power-up tick last
HELD_TICK = [(POSE, 0.021, 1), (POSE, 0.061, 3), (POSE, 0.081, 4), (POSE, 0.101, 5),
             (SUMMARY, 0.101, 2), (PAGE, 0.101, 3), (POSE, 0.121, 6), (POSE, 0.141, 7),
             (POSE, 0.151, 0), (SUMMARY, 0.151, 0)]
# a firmware whose status COUNTER 0 the bus lost, its poses heard in order, reset at 0.15 s
LOST_STATUS_REBOOT = [*[(POSE, 0.001 + 0.02 * c, c) for c in range(8)], (SUMMARY, 0.101, 2),
                      (PAGE, 0.101, 3), (POSE, 0.151, 0), (SUMMARY, 0.151, 0)]


def _watched(heard: list[tuple[str, float, int]]) -> list[str | None]:
    """``SourceWatch`` fed as the monitor and the bridge feed it: what each summary told."""
    watch, kinds = SourceWatch(), []
    for kind, t_s, counter in heard:
        if kind == POSE:
            watch.hear_pose(t_s, counter)
            continue
        watch.hear_status(t_s, counter)
        if kind == SUMMARY:
            kinds.append(watch.observe(t_s, 0, "OK", counter))
    return kinds


def test_a_held_back_power_up_tick_is_no_reboot() -> None:
    assert _watched(HELD_TICK) == [None, None]


def test_a_reboot_whose_old_status_counter_0_was_lost_is_still_one() -> None:
    """Its summary fills a hole of the status sequence, but its pose of COUNTER 0 repeats one
    heard in order: a new firmware."""
    assert _watched(LOST_STATUS_REBOOT) == [None, "reboot"]


def _run(log: Path, seed: int, faults: str) -> tuple[int, dict[str, Any]]:
    """``odocan run`` kobuki random ``seed``, 8 s, ``faults``, Python firmware: exit code and
    report."""
    report = log.with_suffix(".json")
    code = main(["run", "--robot", "kobuki", "--scenario", "random", "--seed", str(seed),
                 "--duration", "8", "--faults", faults, "--firmware", "python", "--log",
                 str(log), "--report", str(report)])
    return code, json.loads(report.read_text())


def reboots_told(log: Path, run_report: dict[str, Any]) -> dict[str, list[float]]:
    """The bus times (s, since the log's first frame, 3 decimals) of the reboots each judge of
    ``log`` reports: run, ``analyze`` whole and streamed, the monitor; the bridge's count as
    that many NaN-free zeros (it keeps no time)."""
    first_s = run_report["first_frame_s"]
    told = {"run": [round(b["t_s"], 3) for b in run_report["reboots"]]}
    for s in STREAMS:
        path = log.with_suffix(f".{s}.json")
        assert analyze(log, s, path) == 0
        told[s] = [round(b["t_s"], 3) for b in json.loads(path.read_text())["reboots"]]
    told["monitor"] = [round(e["t_s"] - first_s, 3)
                       for e in monitor_of(log, "kobuki", "exact").events if e["kind"] == "reboot"]
    told["bridge"] = [0.0] * bridge_of(log, "kobuki", "exact").reboots
    return told


@pytest.fixture(scope="module")
def held_drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, dict[str, Any]]:
    log = tmp_path_factory.mktemp("held") / "d.log"
    return (log, *_run(log, 696, HELD))


def test_no_judge_reports_a_reboot_on_the_held_back_tick(
        held_drive: tuple[Path, int, dict[str, Any]]) -> None:
    log, code, report = held_drive
    assert code == 0
    told = reboots_told(log, report)
    assert told == {"run": [], **{s: [] for s in STREAMS}, "monitor": [], "bridge": []}, told


def test_x_10_mm_off_from_0_2_s_fails(held_drive: tuple[Path, int, dict[str, Any]],
                                      tmp_path: Path) -> None:
    log, _, _ = held_drive
    assert x_10_mm_off_fails(log, tmp_path / "t.log", 0.2, 300) == []
