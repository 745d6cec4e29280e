"""An ODOM_STATUS summary the bus held back is no reboot, unless it says one against the summary
its firmware sent before it (issue #11, rule 5; ``host.judge.livelatestatus``).

kobuki, seed 2, ``delay=0.5:100``: the summary of COUNTER 2 (UPTIME 0), sent at 0.90 s, came at
1.00 s after COUNTER 4 and 5 (UPTIME 1). Every judge told a reboot at 1.00 s ("fitted", and the
log's start "fitted to the samples (no power-up in the log)"), and a pose 10 mm off from 2.0 s
PASSed; ``delay=0.5:150`` told one at 1.05 s the same way and FAILed the correct firmware
(65.6 mm). A real reboot whose INIT summary the bus held back behind the new firmware's next
frame is still told when it comes (``delay=0.5:100,reboot=1.5``: at 1.60 s).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.livelatestatus import held_back
from odocan.host.judge.sources import SourceWatch
from odocan.sim.robot import load

KOBUKI = load("kobuki")


def _status_stream(uptime_at: dict[int, int], lap: int, order: list[int],
                   init: tuple[int, ...] = ()) -> tuple[list[int], list[tuple[int, str] | None]]:
    """COUNTERs heard (``order``: send numbers, bus order), and what each says: even sends are
    summaries (UPTIME from ``uptime_at``: the first send number of each second), odd ones other
    pages (a firmware's two frames a cycle); ``lap``: the first send's COUNTER."""
    said: list[tuple[int, str] | None] = []
    for n in order:
        uptime = max(u for start, u in uptime_at.items() if start <= n)
        said.append((uptime, "INIT" if n in init else "OK") if n % 2 == 0 else None)
    return [(lap + n) % 16 for n in order], said


def test_a_summary_held_back_behind_a_newer_second_is_passed_over() -> None:
    # seed 2's: sends 16..21 (COUNTER 0..5); send 18 (COUNTER 2, UPTIME 0) held back behind
    # sends 19..21, the summary of send 20 saying UPTIME 1
    counters, said = _status_stream({0: 0, 20: 1}, 0, [*range(14, 18), 19, 20, 21, 18])
    assert held_back(counters, said) == [False] * 7 + [True]


def test_a_reboot_held_back_is_still_one() -> None:
    # the old firmware's sends up to COUNTER 13 (UPTIME 1); the new one's boot summary
    # (COUNTER 0, INIT, UPTIME 0) comes after its own first page (COUNTER 1)
    old, old_said = _status_stream({0: 1}, 8, list(range(6)))
    new, new_said = _status_stream({0: 0}, 0, [1, 0], init=(0,))
    assert held_back(old + new, old_said + new_said) == [False] * 8
    # UPTIME below the one sent before it, not INIT: a reboot too
    new, new_said = _status_stream({0: 0}, 0, [1, 0])
    assert held_back(old + new, old_said + new_said)[-1] is False


def test_a_new_firmware_repeating_a_counter_heard_is_no_late_frame() -> None:
    # every old send heard (COUNTER 0..5, UPTIME 1), then a new firmware's summary COUNTER 2
    # (its boot frames lost): it repeats a COUNTER heard in order, so it is no held-back frame
    old, old_said = _status_stream({0: 1}, 0, list(range(6)))
    assert held_back([*old, 2], [*old_said, (0, "OK")]) == [False] * 7


def test_the_live_watch_passes_the_held_back_summary_over() -> None:
    """``SourceWatch`` fed as the monitor and the bridge feed it (``hear_status`` then
    ``observe``): the held-back summary is no reboot, the held-back boot summary one."""
    counters, said = _status_stream({0: 0, 20: 1}, 0, [*range(14, 18), 19, 20, 21, 18])
    watch, kinds = SourceWatch(), []
    for k, (counter, summary) in enumerate(zip(counters, said, strict=True)):
        t_s = 0.7 + 0.05 * k
        watch.hear_status(t_s, counter)
        if summary is not None:
            kinds.append(watch.observe(t_s, summary[0], summary[1], counter))
    assert kinds == [None] * len(kinds)
    old, old_said = _status_stream({0: 1}, 8, list(range(6)))
    new, new_said = _status_stream({0: 0}, 0, [1, 0], init=(0,))
    watch, kinds = SourceWatch(), []
    for k, (counter, summary) in enumerate(zip(old + new, old_said + new_said, strict=True)):
        t_s = 1.2 + 0.05 * k
        watch.hear_status(t_s, counter)
        if summary is not None:
            kinds.append(watch.observe(t_s, summary[0], summary[1], counter))
    assert kinds == [None, None, None, "reboot"]


def _drive(tmp_path: Path, faults: str) -> tuple[Path, dict[str, object]]:
    """kobuki, seed 2, 4 s under ``faults`` (the Python firmware): the log and the streamed
    ``analyze``'s report."""
    log = tmp_path / "drive.log"
    subprocess.run([sys.executable, "-m", "odocan", "run", "--robot", "kobuki", "--duration",
                    "4", "--seed", "2", "--faults", faults, "--firmware", "python", "--log",
                    str(log)], check=False, capture_output=True)
    out = subprocess.run([sys.executable, "-m", "odocan", "analyze", str(log), "--stream",
                          "always", "--report", "-"], check=False, capture_output=True,
                         text=True)
    report: dict[str, object] = json.loads(out.stdout)
    return log, report


@pytest.mark.parametrize("faults", ["delay=0.5:100", "delay=0.5:150"])
def test_no_reboot_where_none_was(faults: str, tmp_path: Path) -> None:
    log, streamed = _drive(tmp_path, faults)
    whole = analyze(read_log(log), KOBUKI, "exact").report
    for report in (whole, streamed):
        assert report["reboots"] == []
        assert report["reference_start"] == "power-up"


def test_a_held_back_boot_summary_tells_the_reboot(tmp_path: Path) -> None:
    log, streamed = _drive(tmp_path, "delay=0.5:100,reboot=1.5")
    whole = analyze(read_log(log), KOBUKI, "exact").report
    for report in (whole, streamed):
        reboots = report["reboots"]
        assert isinstance(reboots, list)
        assert [r["t_s"] for r in reboots] == [pytest.approx(1.601)]
