"""Max RSS of ``odocan analyze --stream always`` against ``--stream never`` on a long drive whose
firmware stalled mid-drive long enough to re-prime, and said so (issue #11/#13,
``host.judge.stallreprime``, ``host.judge.stream_reprime``).

The drive: pmir on the circle for ``--minutes`` (default 60), its MCU halted ``--halt-s``
(default 6 s) from ``--at-min`` minutes in (default: half way; no reboot: its FIFO keeps the
first frames after the halt, as ``tests/test_stall_beyond_window.py``'s ``drive_mid``), it
re-primes on resuming (COUNTER_RESET); ``--bias-lsb`` X LSBs added to every pose from the stall
on (a wrong firmware; E2E re-protected). The log is written as the rig runs (never held in
memory), then ``odocan analyze`` runs both ways as whole processes (GNU time's max RSS and CPU);
prints each one's max RSS, exit code, its stderr lines, and whether the two JSON reports are
equal. Asserts nothing. ``--config``: instead, kobuki with a config applied at 3 s
(``host.judge.configs.ConfigPages``).
Run: ``.venv/bin/python bench/stream_stall.py [--minutes 60] [--halt-s 6] [--keep LOG]``."""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import can  # noqa: E402

from bench.stream_powerup import LateWriter, analyze  # noqa: E402
from odocan.sim.board import TICK_S  # noqa: E402
from odocan.sim.scenarios import get_scenario  # noqa: E402
from tests.fault_rig import FaultRig  # noqa: E402
from tests.test_first_second_reboot import _wrong  # noqa: E402
from tests.test_stall_beyond_window import PMIR  # noqa: E402


class BiasedWriter(LateWriter):
    """``LateWriter`` (nothing late) whose bias starts at the stall's tick."""

    def __init__(self, out: object, bias_lsb: int, from_tick: int) -> None:
        super().__init__(out, 0.0, 0)  # type: ignore[arg-type]
        self.bias, self.from_tick = bias_lsb, from_tick

    def add_at(self, k: int, messages: list[can.Message]) -> None:
        if self.bias and k > self.from_tick:
            messages = list(_wrong(tuple(messages), 0, self.bias, 0))
        self.add(messages)


def make_log(path: Path, minutes: float, at_tick: int, halted: int, bias_lsb: int) -> int:
    """The drive (module docstring) as a candump log; how many frames."""
    with path.open("w") as out, FaultRig(scenario=get_scenario(
            "circle", PMIR, duration_s=minutes * 60 + 10)) as rig:
        writer = BiasedWriter(out, bias_lsb, at_tick)

        def heard(k: int, got: list[can.Message]) -> None:
            writer.add_at(k, got)
            writer.flush(k * TICK_S - 1.0)
        rig.observers.append(heard)
        rig.halted = lambda k: at_tick < k <= at_tick + halted
        rig.run(minutes * 60)
        writer.flush(float("inf"))
    return writer.n


def make_config_log(path: Path, minutes: float) -> int:
    """``--config``: kobuki (seed 3) with a config it ACKs at 3 s (wheelbase 0.25 m:
    ``tests/test_analyze_config.py``'s drive), ``minutes`` long, written as it runs."""
    from odocan.host.protocol.heard import Recorder
    from odocan.host.protocol.session import CommandSession
    from odocan.sim.contract import database
    from odocan.sim.rig import LockstepRig, RigConfig
    from tests.test_analyze_config import KOBUKI, WIDER_M, _config

    n = 0
    with path.open("w") as out:
        class Write(can.Listener):
            def on_message_received(self, msg: can.Message) -> None:
                nonlocal n
                out.write(f"({msg.timestamp:.6f}) vcan0 {msg.arbitration_id:03X}#"
                          f"{bytes(msg.data).hex().upper()}\n")
                n += 1

        heard = Recorder(database())
        rig = LockstepRig(RigConfig(robot=KOBUKI, seed=3, channel="bench-config",
                                    duration_s=minutes * 60 + 10), [heard, Write()])
        try:
            session = CommandSession(heard, rig.send, rig.run_until, ack_timeout_s=0.5)
            rig.run(3.0)
            session.configure(**_config(wheelbase_m=WIDER_M))  # type: ignore[arg-type]
            rig.run(minutes * 60 - 3.0)
        finally:
            rig.close()
    return n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--at-min", type=float, default=None)
    parser.add_argument("--halt-s", type=float, default=6.0)
    parser.add_argument("--bias-lsb", type=int, default=0)
    parser.add_argument("--dir", type=Path, default=Path(tempfile.gettempdir()))
    parser.add_argument("--keep", type=Path, help="write the log here and keep it")
    parser.add_argument("--modes", default="always,never")
    parser.add_argument("--config", action="store_true",
                        help="instead: kobuki with a config applied at 3 s (no stall)")
    args = parser.parse_args()
    at_min = args.minutes / 2 if args.at_min is None else args.at_min
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        log = args.keep or Path(tmp) / "stall.log"
        if not log.exists() and args.config:
            print(f"{log}: {make_config_log(log, args.minutes)} frames", flush=True)
        if not log.exists():
            frames = make_log(log, args.minutes, round(at_min * 60 / TICK_S),
                              round(args.halt_s / TICK_S), args.bias_lsb)
            print(f"{log}: {frames} frames", flush=True)
        print(f"{log}: {log.stat().st_size / 1e6:.1f} MB, {args.minutes:g} min, " + (
            "a config applied at 3 s" if args.config else f"halted {args.halt_s:g} s at "
            f"{at_min:g} min, X +{args.bias_lsb} LSB"), flush=True)
        reports = {}
        for mode in args.modes.split(","):
            analyze(log, mode, Path(tmp) / f"{mode}.json", "kobuki" if args.config else "pmir")
            reports[mode] = json.loads((Path(tmp) / f"{mode}.json").read_text())
        if len(reports) == 2:
            a, b = reports.values()
            print(f"reports equal: {a == b}; passed {b['passed']}; events "
                  f"{[e['kind'] for e in b['events']][:4]}")
            if a != b:
                print(f"    differ in: {[k for k in b if b[k] != a.get(k)]}")


if __name__ == "__main__":
    main()
