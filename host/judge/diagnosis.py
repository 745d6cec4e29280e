"""Why a log fails: the robot profile the logged poses actually fit.

A wrong ``--robot`` makes every sample depart from the reference, and the verdict would read like
a firmware fault (pose and twist out of tolerance). Before blaming the firmware, the judge checks
which profiles — the one given first, then the shipped ones — the logged on-board poses follow
within the tolerance; a log that fits another profile is a robot mismatch, said by name. So is
an ``--integrator`` other than the one the log's ODOM_STATUS reports, and that one FAILs the
verdict whatever the poses (``mark_integrator``): a log judged with another integrator than its
firmware's says nothing of that firmware (on a square drive exact and euler agree within the
tolerance, and the PASS read as one of the given integrator).
"""

from __future__ import annotations

from typing import Any

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import AnalysisError, Tolerance, analyze
from odocan.host.judge.samples import pick_integrator
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
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
    log: FrameArrays, given: RobotProfile, integrator: str, tolerance: Tolerance,
    given_as: str = "--robot",
) -> str | None:
    """``robot mismatch: ...`` when the log fits another profile and not ``given`` (named
    ``given_as``: "the default robot" when no ``--robot`` was given); else None (the log fits
    ``given``, or no known profile: nothing to say about the robot)."""
    fits = fitting_profiles(log, given, integrator, tolerance)
    if given.name in fits or not fits:
        return None
    return (f"robot mismatch: the log's poses fit robot {', '.join(map(repr, fits))}, "
            f"not {given.name!r} ({given_as})")


def logged_integrator(log: FrameArrays) -> str | None:
    """The integrator the log's ODOM_STATUS reports (None: none reported)."""
    _, accepted = check_frames(log)
    try:
        return pick_integrator(log, accepted, BulkDecoder(default_plan()), None)[0]
    except AnalysisError:
        return None


def integrator_said(logged: str | None, given: str) -> str | None:
    """``integrator mismatch: ...`` when the log's ODOM_STATUS reports ``logged``, not the
    ``--integrator`` ``given``; None when it reports ``given`` or none."""
    if logged is None or logged == given:
        return None
    return (f"integrator mismatch: the log's ODOM_STATUS reports {logged}, not {given} "
            "(--integrator)")


def mark_integrator(report: dict[str, Any], logged: str | None) -> str | None:
    """``report`` FAILed (``integrator_mismatch``, ``passed`` false; its ``passed_otherwise``
    the verdict before) when its integrator was given (``integrator_source`` "argument") and
    differs from ``logged``, the log's ODOM_STATUS's; the line said, None when nothing was
    marked."""
    if report.get("integrator_source") != "argument":
        return None
    said = integrator_said(logged, report["integrator"])
    if said is not None:  # passed_otherwise: the verdict without it (a batch counts by reason)
        report["integrator_mismatch"] = {"logged": logged, "given": report["integrator"],
                                         "detail": said, "passed_otherwise": report["passed"]}
        report["passed"] = False
    return said


def mismatches(
    log: FrameArrays, given: RobotProfile, integrator: str, source: str, tolerance: Tolerance,
    given_as: str = "--robot",
) -> list[str]:
    """Why a failed log may not be the firmware's fault: an ``--integrator`` (``source``
    "argument") other than the one the log's ODOM_STATUS reports, then ``robot_mismatch``
    with the log's own integrator."""
    hints = []
    logged = logged_integrator(log) if source == "argument" else None
    if (said := integrator_said(logged, integrator)) is not None:
        hints.append(said)
    robot_hint = robot_mismatch(log, given, logged or integrator, tolerance, given_as)
    return hints + ([] if robot_hint is None else [robot_hint])
