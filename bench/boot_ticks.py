"""Which first-second reboots the judges tell, and that one life makes none; asserts nothing.

pmir on the circle in the lockstep rig (``tests.fault_rig``), 4 s, the MCU reset before tick k
(10 ms ticks) of its first second, the boot tick's ODOM_STATUS frames stamped ``hold`` ms late
(a loaded bus, a recorder); and, for false reboots, one life whose motor controller is silent
for its first m ticks (the firmware INIT meanwhile sends no pose), its summary of COUNTER 0 at
0.8 s held 0..150 ms. For each: the reboots ``analyze`` (whole log) and the bridge's telemetry
count, and analyze's verdict. (``host.judge.bootticks``; the tests assert the cases in
``tests/test_first_second_reboot.py``.)

Run: ``.venv/bin/python bench/boot_ticks.py [--quick]`` (a few minutes of CPU in full).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import can

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.board import TICK_S
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig

PMIR = load("pmir")
STATUS_ID = 0x380  # ODOM_STATUS (dbc/odocan.dbc)


def drive(reboot_at: int | None, muted: int = 0, run_s: float = 4.0) -> list[can.Message]:
    """Every frame of ``run_s`` on the circle; the MCU reset before tick ``reboot_at``."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario("circle", PMIR, duration_s=60.0)) as rig:
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(lambda k: rig.board.reboot() if k == reboot_at else None)
        if muted:
            rig.mute_sim(range(muted))
        rig.run(run_s)
    return heard


def held(messages: list[can.Message], from_s: float, by_s: float) -> list[can.Message]:
    """The ODOM_STATUS frames of the first status tick from ``from_s`` stamped ``by_s`` late."""
    tick_s = min(m.timestamp for m in messages
                 if m.arbitration_id == STATUS_ID and m.timestamp >= from_s)
    out = [can.Message(arbitration_id=m.arbitration_id, data=m.data, is_extended_id=False,
                       timestamp=m.timestamp + by_s)
           if m.arbitration_id == STATUS_ID and m.timestamp == tick_s else m for m in messages]
    return sorted(out, key=lambda m: m.timestamp)


def judged(messages: list[can.Message], folder: Path) -> tuple[int, bool, int]:
    """(analyze's reboots, its verdict, the bridge's reboots)."""
    path = folder / "drive.log"
    path.write_text("".join(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#"
                            f"{bytes(m.data).hex().upper()}\n" for m in messages))
    result = analyze(read_log(path), PMIR, "exact")
    bridge = RobotTelemetry("r1", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits)
    for msg in messages:
        bridge.feed(msg)
    return len(result.report["reboots"]), result.passed, bridge.reboots


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="every 8th reset tick")
    args = parser.parse_args()
    ticks = range(1, 100, 8 if args.quick else 1)
    holds_ms = (0, 15, 40, 70)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        told = {hold: 0 for hold in holds_ms}
        missed: dict[int, list[int]] = {hold: [] for hold in holds_ms}
        for k in ticks:
            messages = drive(k)
            for hold in holds_ms:
                whole, passed, bridge = judged(held(messages, k * TICK_S, hold / 1000), folder)
                if whole == bridge == 1 and passed:
                    told[hold] += 1
                else:
                    missed[hold].append(k)
        for hold in holds_ms:
            print(f"reset in the first second, boot summary {hold:3d} ms late: told and PASS "
                  f"{told[hold]}/{len(ticks)}; not: ticks {missed[hold]}")
        for muted in (0, 8, 10, 12, 14, 16, 18):
            life = drive(None, muted=muted, run_s=2.0)
            false = [hold for hold in (0, 50, 100, 150)
                     if judged(held(life, 0.8 - TICK_S / 2, hold / 1000), folder)[::2] != (0, 0)]
            print(f"one life, controller {muted * 10:3d} ms late, 0.8 s summary held 0..150 ms: "
                  f"false reboots at holds {false or 'none'}")


if __name__ == "__main__":
    main()
