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
profile or several: the default (pmir) and today's diagnosis, and once the log is judged one
stderr line says why the default (``judged as robot 'pmir' (the default: its PROFILE page fits
no shipped robot; give --robot)``, or ``no PROFILE page in its first 8192 frames``): a
custom robot's log once FAILed with "not 'pmir' (--robot)" although no --robot was given, and
nothing said the page fit no robot. The mismatch lines name the robot as it came
(``given_as``: ``(the default robot)``, not ``(--robot)``). ``--robot`` given always wins,
and a log made with other parameters is diagnosed by name as before. With ``--dbc`` (another
DBC: the page is read with odocan's) the log does not pick, and nothing is said.

A head page that fits no shipped robot, or several but not the default, is refused: one line,
exit 2 (``the log's firmware runs a different profile than the default robot pmir: give
--robot``). Judging it as pmir FAILed a correct firmware (a custom 32-bit robot's log: 1508 mm
off) for an option the user did not give; a robot GIVEN that the page contradicts is still
judged, the FAIL naming the mismatch (a firmware flashed for another robot). Without a page in
the head nothing tells, and the default is judged as before (its stderr line says why).

Every report records the choice (``inputs.robot.source``: ``--robot``, ``PROFILE page`` or
``default``; ``inputs.robot.page_fits``: the shipped profiles the page fits;
``inputs.robot.page_in_head``: whether the log's head holds a PROFILE page, null when it was not
looked for or could not be read), the JUnit suite as properties (``properties``).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from odocan.host.judge.robotsource import DEFAULT as DEFAULT  # one rule, live and offline
from odocan.host.judge.robotsource import DEFAULT_ROBOT as DEFAULT_ROBOT
from odocan.host.judge.robotsource import FROM_PAGE as FROM_PAGE
from odocan.host.judge.robotsource import GIVEN as GIVEN
from odocan.host.judge.robotsource import GIVEN_AS as GIVEN_AS
from odocan.sim import robot
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.robot import RobotProfile


@dataclass(frozen=True)
class RobotChoice:
    """The profile a log is judged with and where it came from (``source``: ``GIVEN``,
    ``FROM_PAGE``, ``DEFAULT``); ``page_fits``, the shipped profiles the log's first PROFILE
    page fits (empty: no page, or none fits; several: the page cannot choose);
    ``page_in_head``, whether the log's head holds a page (None: not looked for, or the log
    could not be read: its analysis says why)."""

    profile: RobotProfile
    source: str
    page_fits: tuple[str, ...] = ()
    page_in_head: bool | None = None

    @property
    def given_as(self) -> str:
        """How a mismatch line names the robot: ``(--robot)`` only when it was given."""
        return GIVEN_AS[self.source]

    def said(self, command: str, log: Path | str) -> str | None:
        """The one stderr line when the log chose a robot other than the default, else None
        (``said_of_report``), said before the log is judged."""
        return _chosen_line(command, log, self._section())

    def defaulted(self, command: str, log: Path | str) -> str | None:
        """The one stderr line when the default was taken for want of a page that chooses
        (``said_of_report``), said once the log is judged (a log that cannot be judged says
        only why)."""
        return _default_line(command, log, self._section())

    def _section(self) -> dict[str, Any]:
        return {"name": self.profile.name, "source": self.source,
                "page_fits": list(self.page_fits), "page_in_head": self.page_in_head}

    def recorded(self, section: dict[str, Any]) -> dict[str, Any]:
        """A report's ``inputs`` with the choice in its ``robot``."""
        section["robot"].update(source=self.source, page_fits=list(self.page_fits),
                                page_in_head=self.page_in_head)
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
    if not from_log:
        return RobotChoice(robot.load(DEFAULT_ROBOT), DEFAULT)
    in_head, fits = head_page_fits(log)
    if len(fits) == 1:
        return RobotChoice(robot.load(fits[0]), FROM_PAGE, fits, in_head)
    if in_head and DEFAULT_ROBOT not in fits:  # a page, not the default's: refused
        raise ConfigurationError(f"{log}: the log's firmware runs a different profile than "
                                 f"the default robot {DEFAULT_ROBOT}: give --robot")
    return RobotChoice(robot.load(DEFAULT_ROBOT), DEFAULT, fits, in_head)


def head_page_fits(log: Path) -> tuple[bool | None, tuple[str, ...]]:
    """Whether the head of ``log`` (``profilepage.HEAD_FRAMES`` frames) holds a PROFILE page
    (None: the log cannot be read, or holds no frame: the analysis says why), and the shipped
    profiles its first page fits."""
    from odocan.host.io.logs import iter_log
    from odocan.host.judge.profilepage import HEAD_FRAMES, first_page, shipped_robots
    from odocan.sim.exceptions import OdocanError

    try:
        for chunk in iter_log(log, chunk_frames=HEAD_FRAMES, warn=lambda _text: None):
            page = first_page(chunk)
            return page is not None, shipped_robots(page)
    except (OdocanError, OSError):
        pass
    return None, ()


def say(line: str | None) -> None:
    """``line`` on stderr, if there is one (``RobotChoice.said``, ``RobotChoice.defaulted``)."""
    if line is not None:
        print(line, file=sys.stderr)


def said_of_report(command: str, log: Path | str, report: dict[str, Any] | None) -> str | None:
    """The one stderr line for the robot ``report`` records: one the log's PROFILE page chose
    other than the default (a log of the default robot is judged as before, quietly: only its
    report says where the robot came from), or the default taken for want of a page that
    chooses; else None. A batch's log's, from the choice a worker process made."""
    chosen = ((report or {}).get("inputs") or {}).get("robot") or {}
    return _chosen_line(command, log, chosen) or _default_line(command, log, chosen)


def _chosen_line(command: str, log: Path | str, chosen: dict[str, Any]) -> str | None:
    if chosen.get("source") != FROM_PAGE or chosen.get("name") == DEFAULT_ROBOT:
        return None
    return f"odocan {command}: {log}: robot {chosen['name']!r} (from the log's PROFILE page)"


def _default_line(command: str, log: Path | str, chosen: dict[str, Any]) -> str | None:
    """Why the default: no page in the head, a page no shipped robot fits, or several."""
    from odocan.host.judge.profilepage import HEAD_FRAMES

    in_head, fits = chosen.get("page_in_head"), chosen.get("page_fits") or []
    if chosen.get("source") != DEFAULT or in_head is None or len(fits) == 1:
        return None
    why = (f"no PROFILE page in its first {HEAD_FRAMES} frames" if not in_head else
           "its PROFILE page fits no shipped robot" if not fits else
           f"its PROFILE page fits {len(fits)} shipped robots, {', '.join(map(repr, fits))}")
    return (f"odocan {command}: {log}: judged as robot {chosen['name']!r} (the default: {why}; "
            "give --robot)")
