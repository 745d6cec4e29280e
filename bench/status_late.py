"""Every ODOM_STATUS frame stamped late (a recorder or gateway that delays one message): which
resets the judges PASS for a correct firmware and FAIL for one 2 LSB off; asserts nothing.

pmir on the circle in the lockstep rig (``tests.fault_rig``), 4 s, the MCU reset before tick k
(10 ms ticks), every ODOM_STATUS frame stamped ``late`` ms later and the log re-sorted by time.
Per delay: how many resets ``analyze`` (whole log), the streamed ``analyze`` (97-frame chunks),
the monitor and the bridge PASS (correct firmware) and FAIL (2 LSB off after the reset), and the
worst position error ``analyze`` reported for the correct firmware. (``host.judge.bootnamed``;
the tests assert the cases in ``tests/test_status_stamped_late.py``.)

Run: ``PYTHONPATH=. .venv/bin/python bench/status_late.py [ticks...]``.

Figures (2026-12-02, resets at ticks 60 80 150 230 300 370): with this branch, at 0/15/30/50/70
ms late the correct firmware PASSes 6/6 in all four judges (worst error 0.069 mm) and the 2 LSB
off one FAILs 6/6 in all four. Main for comparison: 0 ms 6/6 PASS; 15/30/50/70 ms 0/6 PASS in
every judge (worst error 6.5/19.2/28.5/37.8 mm), the 2 LSB off one FAILs 6/6.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.stream_analysis import analyze_file
from tests.test_first_second_reboot import PMIR, _live, _written, _wrong, drive
from tests.test_status_stamped_late import _status_late


def verdicts(messages: tuple, folder: Path) -> tuple[bool, bool, bool, bool, float]:
    """(whole PASS, streamed same report and PASS, monitor OK, bridge within 0.1 mm, error m)."""
    path = _written(messages, folder / "late.log")
    whole = analyze(read_log(path), PMIR, "exact")
    streamed = analyze_file(path, PMIR, "exact", chunk_frames=97)
    monitor, bridge = _live(messages)
    return (whole.passed, json.dumps(streamed) == json.dumps(whole.report) and whole.passed,
            monitor.health(messages[-1].timestamp)["state"] == "OK",
            bridge.tracker.vs_reference.max_dpos_m < 1e-4,
            whole.report["onboard_vs_reference"]["max_position_error_m"])


def main() -> None:
    ticks = [int(a) for a in sys.argv[1:]] or [60, 80, 150, 230, 300, 370]
    with tempfile.TemporaryDirectory() as tmp:
        for late_ms in (0, 15, 30, 50, 70):
            good = [verdicts(_status_late(drive(k), late_ms / 1000), Path(tmp)) for k in ticks]
            bad = [verdicts(_status_late(_wrong(drive(k), k), late_ms / 1000), Path(tmp))
                   for k in ticks]
            passed = [sum(v[j] for v in good) for j in range(4)]
            failed = [sum(not v[j] for v in bad) for j in range(4)]
            print(f"status {late_ms:2d} ms late, {len(ticks)} resets: correct PASS "
                  f"whole/stream/monitor/bridge {passed}, 2 LSB off FAIL {failed}, worst "
                  f"error of the correct {max(v[4] for v in good) * 1e3:.3f} mm", flush=True)


if __name__ == "__main__":
    main()
