"""A re-prime on an ambiguous step told in the same words whole and streamed (``--help``: "the
report is the same either way").

A robot of 16777216 counts a revolution on 32-bit counters; a bus-off of 0.5 s makes the step
across it too long to read (its bound reaches half the counters' range: ``firmware.ambiguity``),
and the firmware re-primes there (COUNTER_RESET). The whole log's judge said so
(``unseenrestart.AMBIGUOUS``); the streamed judge's reference kept only which re-primes it took
for a controller restart (the reference path lists an ambiguous step among them) and said "the
motor controller restarted (CTRL_UPTIME went back)", which it did not: the bus was off. Both
PASSed, their counter_restart events at 4.16 s differing in ``detail``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROBOT = """name = "big16m"
counts_per_rev = 16777216
wheel_radius_left_m = 0.3
wheel_radius_right_m = 0.2999
wheelbase_m = 0.5
counter_bits = 32
"""


def _cli(*args: str) -> int:
    done = subprocess.run([sys.executable, "-m", "odocan", *args], capture_output=True,
                          text=True, timeout=600, check=False)
    assert "Traceback" not in done.stderr, done.stderr
    return done.returncode


def test_an_ambiguous_re_prime_is_told_alike_whole_and_streamed(tmp_path: Path) -> None:
    robot, log = tmp_path / "big16m.toml", tmp_path / "drive.log"
    robot.write_text(ROBOT)
    assert _cli("run", "--robot", str(robot), "--scenario", "square", "--seed", "8577",
                "--duration", "8", "--faults", "busoff=3.65:0.5", "--log", str(log)) == 0
    events = {}
    for stream in ("always", "never"):
        report = tmp_path / f"{stream}.json"
        assert _cli("analyze", str(log), "--robot", str(robot), "--stream", stream,
                    "--report", str(report)) == 0, stream
        events[stream] = [e for e in json.loads(report.read_text())["events"]
                          if e["kind"] == "counter_restart"]
    assert events["never"], events
    assert all("could not span the silence" in e["detail"] for e in events["never"]), events
    assert events["always"] == events["never"]
