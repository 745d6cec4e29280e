"""Why a log fails: the robot profile the logged poses actually fit.

A wrong ``--robot`` makes every sample depart from the reference, and the verdict would read like
a firmware fault (pose and twist out of tolerance). Before blaming the firmware, the judge checks
which profiles — the one given first, then the shipped ones — the logged on-board poses follow
within the tolerance; a log that fits another profile is a robot mismatch, said by name.
"""

from __future__ import annotations

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import Tolerance, analyze
from odocan.sim import robot
from odocan.sim.exceptions import OdocanError
from odocan.sim.robot import RobotProfile, list_profiles


def fitting_profiles(
    log: FrameArrays, given: RobotProfile, integrator: str, tolerance: Tolerance
) -> list[str]:
    """Names of the profiles (``given`` first, then the shipped ones) whose float64 odometry of
    the logged counts the logged on-board poses follow within ``tolerance``."""
    candidates = [given] + [robot.load(n) for n in list_profiles() if n != given.name]
    fits = []
    for candidate in candidates:
        try:
            if analyze(log, candidate, integrator, tolerance=tolerance).passed:
                fits.append(candidate.name)
        except OdocanError:
            continue
    return fits


def robot_mismatch(
    log: FrameArrays, given: RobotProfile, integrator: str, tolerance: Tolerance
) -> str | None:
    """``robot mismatch: ...`` when the log fits another profile and not ``given``; else None
    (the log fits ``given``, or no known profile: nothing to say about the robot)."""
    fits = fitting_profiles(log, given, integrator, tolerance)
    if given.name in fits or not fits:
        return None
    return (f"robot mismatch: the log's poses fit robot {', '.join(map(repr, fits))}, "
            f"not {given.name!r} (--robot)")
