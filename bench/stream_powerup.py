"""Max RSS of ``odocan analyze --stream always`` against ``--stream never`` on a long drive whose
first second holds a power-up the firmware primed late on (issue #11, ``host.judge.primedrange``).

The drive: pmir on the circle for ``--minutes`` (default 60), the MCU halted for its first
second and its FIFO drained at its first tick (it primes on the log's frame 1:
``tests/test_powerup_primed_range.py``'s ``moving``), every ODOM_STATUS stamped ``--late-ms``
late (a gateway's; default 20 ms: the first count page says frame 3, the first pose frame 2),
``--bias-lsb`` X LSBs added to every pose (a wrong firmware; E2E re-protected). The log is
written as the rig runs (never held in memory), then ``odocan analyze`` runs both ways as whole
processes (GNU time's max RSS and CPU); prints each one's max RSS,
exit code, its stderr lines, and whether the two JSON reports are equal. Asserts nothing.
Run: ``.venv/bin/python bench/stream_powerup.py [--minutes 60] [--late-ms 20]``."""

from __future__ import annotations

import argparse
import heapq
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import IO

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import can  # noqa: E402

from odocan.firmware import frames as fr  # noqa: E402
from odocan.sim.board import TICK_S  # noqa: E402
from odocan.sim.scenarios import get_scenario  # noqa: E402
from tests.fault_rig import FaultRig  # noqa: E402
from tests.test_first_second_reboot import _wrong  # noqa: E402
from tests.test_stall_beyond_window import PMIR  # noqa: E402

POWER_UP_TICK = 100  # the MCU's first tick, 1 s into the circle


class LateWriter:
    """Candump lines in stamp order, ODOM_STATUS ``late_s`` later (a min-heap a second deep)."""

    def __init__(self, out: IO[str], late_s: float, bias_lsb: int) -> None:
        self.out, self.late_s, self.bias_lsb = out, late_s, bias_lsb
        self.heap: list[tuple[float, int, str]] = []
        self.n = 0

    def add(self, messages: list[can.Message]) -> None:
        if self.bias_lsb:
            messages = list(_wrong(tuple(messages), 0, self.bias_lsb, 0))
        for m in messages:
            t = m.timestamp + (self.late_s if m.arbitration_id == fr.ODOM_STATUS_ID else 0.0)
            line = f"vcan0 {m.arbitration_id:03X}#{bytes(m.data).hex().upper()}\n"
            heapq.heappush(self.heap, (t, self.n, line))
            self.n += 1

    def flush(self, before_s: float) -> None:
        while self.heap and self.heap[0][0] < before_s:
            t, _, line = heapq.heappop(self.heap)
            self.out.write(f"({t:.6f}) {line}")


def make_log(path: Path, minutes: float, late_s: float, bias_lsb: int) -> int:
    """The drive (module docstring) as a candump log; how many frames."""
    with path.open("w") as out, FaultRig(scenario=get_scenario(
            "circle", PMIR, duration_s=minutes * 60 + 10)) as rig:
        writer = LateWriter(out, late_s, bias_lsb)

        def drain(k: int) -> None:
            if k == POWER_UP_TICK:
                while rig.fw_bus.recv(0) is not None:
                    pass

        def heard(k: int, got: list[can.Message]) -> None:
            if k >= POWER_UP_TICK:
                writer.add(got)
                writer.flush(k * TICK_S - 1.0)
        rig.observers.append(heard)
        rig.before_board.append(drain)
        rig.halted = lambda k: k < POWER_UP_TICK
        rig.run(POWER_UP_TICK * TICK_S + minutes * 60)
        writer.flush(float("inf"))
    return writer.n


def analyze(log: Path, mode: str, report: Path,
            robot: str = "pmir") -> tuple[float, int, list[str]]:
    """Max RSS MB, exit code and stderr lines of ``odocan analyze LOG --stream MODE``."""
    argv = [sys.executable, "-m", "odocan", "analyze", str(log), "--robot", robot,
            "--integrator", "exact", "--stream", mode, "--report", str(report)]
    with tempfile.NamedTemporaryFile("r", suffix=".rss") as rss:
        done = subprocess.run(["/usr/bin/time", "-f", "%M %U %S", "-o", rss.name, *argv],
                              capture_output=True, text=True, env=dict(os.environ,
                                                                       PYTHONPATH=str(ROOT)))
        kb, user_s, sys_s = Path(rss.name).read_text().split()[-3:]
    rss_mb, code, lines = int(kb) / 1024, done.returncode, done.stderr.splitlines()
    cpu = float(user_s) + float(sys_s)
    print(f"--stream {mode:<6} {rss_mb:7.0f} MB max RSS {cpu:7.1f} s CPU exit {code}", flush=True)
    for line in lines:
        print(f"    stderr: {line}")
    return rss_mb, code, lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--late-ms", type=float, default=20.0)
    parser.add_argument("--bias-lsb", type=int, default=0)
    parser.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()))
    parser.add_argument("--keep", type=Path, help="write the log here and keep it")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        log = args.keep or Path(tmp) / "powerup.log"
        if not log.exists():
            frames = make_log(log, args.minutes, args.late_ms * 1e-3, args.bias_lsb)
            print(f"{log}: {frames} frames", flush=True)
        print(f"{log}: {log.stat().st_size / 1e6:.1f} MB, {args.minutes:g} min, ODOM_STATUS "
              f"{args.late_ms:g} ms late, X +{args.bias_lsb} LSB", flush=True)
        reports = {}
        for mode in ("always", "never"):
            analyze(log, mode, Path(tmp) / f"{mode}.json")
            reports[mode] = json.loads((Path(tmp) / f"{mode}.json").read_text())
        same = reports["always"] == reports["never"]
        print(f"reports equal: {same}; passed {reports['never']['passed']}; events "
              f"{[e['kind'] for e in reports['never']['events']][:4]}")
        if not same:
            diff = [k for k in reports["never"] if reports["never"][k] != reports["always"].get(k)]
            print(f"    differ in: {diff}")


if __name__ == "__main__":
    main()
