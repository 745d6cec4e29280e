"""The pose uncertainty the firmware ends a drive with (firmware.uncertainty; issue #11 point 5).

Every scenario on kobuki and pmir with no faults (``odocan run``'s default), then an hour's random
drive on each with 1 % of the sim's frames dropped: the uncertainty summed over the steps merged
across lost periods, against the tolerance past which the firmware goes DEGRADED
(POSE_UNCERTAIN). Reads the Python firmware's state after the run (the uncertainty is not on the
bus). Prints figures, asserts nothing.
Run: ``.venv/bin/python bench/uncertainty.py [--hour-seconds S]``.
"""

from __future__ import annotations

import argparse
import time

from odocan.firmware.ecu import OdomEcu
from odocan.firmware.uncertainty import UNCERTAINTY_TOLERANCE_UM
from odocan.sim.faults import FaultSpec
from odocan.sim.faultspec import two_handles
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from odocan.sim.scenarios import SCENARIOS


def _drive(robot: str, scenario: str, duration_s: float | None, drop: float) -> str:
    """One lockstep run; its end state, reason and uncertainty as one line."""
    faults = FaultSpec(drop=drop, seed=1) if drop else None
    config = RigConfig(
        robot=load(robot),
        scenario=scenario,
        duration_s=duration_s,
        faults=None if faults is None else two_handles(faults)[0],
        fw_faults=None if faults is None else two_handles(faults)[1],
    )
    rig = LockstepRig(config)
    started = time.process_time()
    try:
        rig.run(duration_s)
        ecu = rig.board.ecu
        assert isinstance(ecu, OdomEcu)
        lost = ecu.encoders.rx.lost_frames
        return (f"{robot:7s} {scenario:8s} drop {drop:4.2f} {rig.ticks / 100:7.0f} s: "
                f"{ecu.state.name} {ecu.reason.name}, uncertainty "
                f"{ecu.uncertainty.uncertainty_um / 1000:8.3f} mm "
                f"(tolerance {UNCERTAINTY_TOLERANCE_UM / 1000:g} mm), encoder frames lost {lost}"
                f" [{time.process_time() - started:.1f} s CPU]")
    finally:
        rig.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hour-seconds", type=float, default=3600.0)
    args = parser.parse_args()
    for robot in ("kobuki", "pmir"):
        for scenario in SCENARIOS:
            print(_drive(robot, scenario, None, 0.0), flush=True)
    for robot in ("kobuki", "pmir"):
        print(_drive(robot, "random", args.hour_seconds, 0.01), flush=True)


if __name__ == "__main__":
    main()
