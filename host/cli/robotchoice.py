"""The robot ``analyze`` and ``replay`` judge a log with when ``--robot`` is not given.

A log made by odocan's firmware says what it ran with: ODOM_STATUS page 6 (PROFILE) carries
PROFILE_CRC, a CRC-32 of its parameter set (``host.judge.profilepage``). Judging a kobuki log
as the default pmir only to print "runs with the parameters of robot 'kobuki', not 'pmir'"
next to a FAIL blames a correct firmware for a missing option. So without ``--robot`` the
log's first PROFILE page within its head (``profilepage.HEAD_FRAMES`` frames, the same frames
whether the log is then streamed or read whole; the first page: the firmware's robot where the
log begins, before any config it applies in the log) picks the robot when exactly one shipped
profile's parameters are its CRC (any integrator; its own speed bound, the page's, or none:
``shipped_robots``), and the command says so on stderr in one line (a robot other than the
default: a log of the default robot is judged as before, quietly). No page, no shipped
profile or several: the default (pmir) and today's diagnosis. ``--robot`` given always wins,
and a log made with other parameters is diagnosed by name as before. With ``--dbc`` (another
DBC: the page is read with odocan's) the log does not pick.

Every report records the choice (``inputs.robot.source``: ``--robot``, ``PROFILE page`` or
``default``; ``inputs.robot.page_fits``: the shipped profiles the page fits), the JUnit suite
as properties (``properties``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from odocan.host.judge.robotsource import DEFAULT as DEFAULT  # one rule, live and offline
from odocan.host.judge.robotsource import DEFAULT_ROBOT as DEFAULT_ROBOT
from odocan.host.judge.robotsource import FROM_PAGE as FROM_PAGE
from odocan.host.judge.robotsource import GIVEN as GIVEN
from odocan.sim import robot
from odocan.sim.robot import RobotProfile


@dataclass(frozen=True)
class RobotChoice:
    """The profile a log is judged with and where it came from (``source``: ``GIVEN``,
    ``FROM_PAGE``, ``DEFAULT``); ``page_fits``, the shipped profiles the log's first PROFILE
    page fits (empty: no page, or none fits; several: the page cannot choose)."""

    profile: RobotProfile
    source: str
    page_fits: tuple[str, ...] = ()

    def said(self, command: str, log: Path | str) -> str | None:
        """The one stderr line when the log chose a robot other than the default, else None
        (``said_of_report``)."""
        robot_section = {"name": self.profile.name, "source": self.source}
        return said_of_report(command, log, {"inputs": {"robot": robot_section}})

    def recorded(self, section: dict[str, Any]) -> dict[str, Any]:
        """A report's ``inputs`` with the choice in its ``robot``."""
        section["robot"].update(source=self.source, page_fits=list(self.page_fits))
        return section

    def properties(self) -> dict[str, str]:
        """The choice as JUnit suite properties."""
        return {"robot": self.profile.name, "robot_source": self.source}


def choose_robot(given: str | None, log: Path, *, from_log: bool = True) -> RobotChoice:
    """The robot for ``log``: ``given`` (``--robot``) when set, else the one shipped profile
    its head's first PROFILE page fits (``from_log``: odocan's DBC), else ``DEFAULT_ROBOT``.
    A bad ``given`` raises ``ProfileError`` (one line) before the log is read."""
    if given is not None:
        return RobotChoice(robot.load(given), GIVEN)
    fits = page_fits(log) if from_log else ()
    if len(fits) == 1:
        return RobotChoice(robot.load(fits[0]), FROM_PAGE, fits)
    return RobotChoice(robot.load(DEFAULT_ROBOT), DEFAULT, fits)


def page_fits(log: Path) -> tuple[str, ...]:
    """The shipped profiles the first PROFILE page of ``log``'s head fits (empty: no page, or
    the log cannot be read: the analysis says why)."""
    from odocan.host.judge.profilepage import first_page, head_profile, shipped_robots

    return shipped_robots(head_profile(log, pick=first_page))


def said_of_report(command: str, log: Path | str, report: dict[str, Any] | None) -> str | None:
    """The one stderr line when ``report`` records a robot the log's PROFILE page chose other
    than the default (a log of the default robot is judged as before, quietly: only its
    report says where the robot came from), else None; a batch's log's from the choice a
    worker process made."""
    chosen = ((report or {}).get("inputs") or {}).get("robot") or {}
    if chosen.get("source") != FROM_PAGE or chosen.get("name") == DEFAULT_ROBOT:
        return None
    return f"odocan {command}: {log}: robot {chosen['name']!r} (from the log's PROFILE page)"
