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

from dataclasses import dataclass
from typing import Any

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.analysis import Analysis, AnalysisError, Tolerance, analyze
from odocan.host.judge.configs import config_cuts
from odocan.host.judge.primedon import PRIMED_KIND
from odocan.host.judge.samples import pick_integrator
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder
from odocan.host.protocol.e2e import check_frames
from odocan.sim import robot
from odocan.sim.exceptions import OdocanError
from odocan.sim.robot import RobotProfile, list_profiles


@dataclass(frozen=True)
class Judged:
    """A verdict already made on the log: ``analyze(log, profile, integrator,
    tolerance=tolerance).passed`` is ``passed`` (``judged_before`` says when a caller's own
    analysis proves it). ``fitting_profiles`` takes it instead of analysing that profile again:
    the same call of a deterministic function, one full analysis less on every failed log."""
    profile: RobotProfile
    integrator: str
    tolerance: Tolerance
    passed: bool

    def of(self, profile: RobotProfile, integrator: str, tolerance: Tolerance) -> bool | None:
        """``passed`` when asked for exactly this profile, integrator and tolerance; else None."""
        same = (profile == self.profile and integrator == self.integrator
                and tolerance == self.tolerance)
        return self.passed if same else None


def judged_before(
    log: FrameArrays, profile: RobotProfile, integrator: str | None, tolerance: Tolerance,
    analysis: Analysis,
) -> Judged | None:
    """What ``analysis``, made as ``analyze(log, profile, integrator, tolerance=tolerance)``
    (odocan's DBC, the whole log, its verdict before any mark made on it later), proves of an
    analysis with the integrator its report names; None when it proves nothing.

    Given (``integrator`` not None), it is the same call. Without one, ``analyze`` resolves the
    log's (``pick_integrator``: the last ODOM_STATUS summary of the frames it is given) and
    judges with it exactly as when given, the report's ``integrator_source`` aside, unless an
    applied config (``first_integrator`` then reads the one before it: ``config_cuts``) or a
    stall at power-up judged from each frame it may have primed on (its re-runs resolve their
    own frames': a ``PRIMED_KIND`` event) make it read another's; and the whole log's (what
    ``logged_integrator`` reads) must be the report's. A one-source cut FAILs either way."""
    report = analysis.report
    if integrator is not None:
        return Judged(profile, integrator, tolerance, analysis.passed)
    if (any(event.get("kind") == PRIMED_KIND for event in report.get("events", []))
            or config_cuts(log, BulkDecoder(default_plan()), profile.counter_bits)
            or logged_integrator(log) != report["integrator"]):
        return None
    return Judged(profile, report["integrator"], tolerance, analysis.passed)


def fitting_profiles(
    log: FrameArrays, given: RobotProfile, integrator: str, tolerance: Tolerance,
    judged: Judged | None = None, analyses: dict[str, Analysis] | None = None,
) -> list[str]:
    """Names of the profiles (``given`` first, then the shipped ones) whose float64 odometry of
    the logged counts the logged on-board poses follow within ``tolerance``; ``judged``: a
    verdict already made (not made again), ``analyses``: filled with those made here, by name."""
    candidates = [given] + [robot.load(n) for n in list_profiles() if n != given.name]
    fits = []
    for candidate in candidates:
        known = None if judged is None else judged.of(candidate, integrator, tolerance)
        try:
            if known is None:
                made = analyze(log, candidate, integrator, tolerance=tolerance)
                known = made.passed
                if analyses is not None:
                    analyses[candidate.name] = made
        except OdocanError:
            continue
        if known:
            fits.append(candidate.name)
    return fits


def robot_mismatch(
    log: FrameArrays, given: RobotProfile, integrator: str, tolerance: Tolerance,
    given_as: str = "--robot", judged: Judged | None = None,
) -> str | None:
    """``robot mismatch: ...`` when the log fits another profile and not ``given`` (named
    ``given_as``: "the default robot" when no ``--robot`` was given); else None (the log fits
    ``given``, or no known profile: nothing to say about the robot). ``judged``:
    ``fitting_profiles``'."""
    fits = fitting_profiles(log, given, integrator, tolerance, judged)
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
    given_as: str = "--robot", judged: Judged | None = None,
) -> list[str]:
    """Why a failed log may not be the firmware's fault: an ``--integrator`` (``source``
    "argument") other than the one the log's ODOM_STATUS reports, then ``robot_mismatch``
    with the log's own integrator (``judged``: a verdict already made, ``judged_before``)."""
    hints = []
    logged = logged_integrator(log) if source == "argument" else None
    if (said := integrator_said(logged, integrator)) is not None:
        hints.append(said)
    robot_hint = robot_mismatch(log, given, logged or integrator, tolerance, given_as, judged)
    return hints + ([] if robot_hint is None else [robot_hint])
