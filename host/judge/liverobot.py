"""The robot the live judges (``odocan monitor``, ``odocan bridge``) judge with when ``--robot``
is not given: the one the firmware's PROFILE page fits (issue #11).

Judging a kobuki firmware as the default pmir FAILs a correct firmware ("pose was wrong ...
1706 mm; judged as robot 'pmir'") where ``analyze`` of the same log PASSes: ``analyze`` takes
the robot from the log's first PROFILE page (``host.cli.robotchoice``). Live, the judges must
not start with the default before they know: so without ``--robot`` the frames heard are
held (``PageWait``) until the first PROFILE page whose E2E CRC holds, or ``PAGE_WAIT_S`` of bus
time (the page comes every 600 ms: ODOM_STATUS every 100 ms, the summary then one of pages
1..6 in rotation, DBC comment of ODOM_STATUS). Then the judges are built for the robot that
page fits, when exactly one shipped profile does (``profilepage.shipped_robots``, the rule
``analyze`` uses), else for the default as today, and every frame held is judged in bus order:
the judges see the whole watch, each with the robot it was decided with, as a watch given
``--robot`` would. ``--robot`` given always wins (no wait; a mismatch is said as before);
with another DBC (``--dbc``) the page does not pick either.

A page that contradicts the default (it fits no shipped robot, or several but not the default),
or a first page heard only after the wait (it cannot choose then: the watch began with the
default) that is not the default's, leaves the watch UNJUDGED (``LiveRobot.unjudged``:
``UNJUDGED_WHY``, ``analyze``'s refusal in the live judges' words): judging a custom robot's
correct firmware as pmir FAILed it for an option the user did not give, and a live judge runs
too long for ``analyze``'s exit 2. Its judges are built anew (a late page: what they judged
with the default is forgotten), their reference blind (``RawReference.blind``: the on-board
pose is still followed, shown and bridged, compared with nothing) and DISTANCE and the twist
speeds not judged: nothing is judged with a robot the firmware does not run. The monitor's
state says why (UNVERIFIED), the JSON's ``robot.unjudged`` and the bridge's
``robot_profile.unjudged`` carry it, and the watch ends UNJUDGED (``--require-firmware``:
FAIL). A robot given (``--robot``) is judged as before.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

from odocan.host.judge.livedistance import LiveDistance, robot_of
from odocan.host.judge.livetwist import LiveTwist
from odocan.host.judge.profilepage import PROFILE_PAGE, RunningProfile, shipped_robots
from odocan.host.judge.reference import Geometry
from odocan.host.judge.robotsource import DEFAULT, DEFAULT_ROBOT, FROM_PAGE, GIVEN, GIVEN_AS
from odocan.host.judge.tracking import PoseTracker
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.e2e import crc8h2f_p02_one, e2e_messages
from odocan.sim import robot as robots
from odocan.sim.robot import MM_PER_M, RobotProfile

if TYPE_CHECKING:
    from cantools.database.can import Database

    from odocan.host.judge.sources import SourceWatch

__all__ = ["DEFAULT", "DEFAULT_ROBOT", "FROM_PAGE", "GIVEN", "UNJUDGED_WHY", "LiveRobot",
           "PageWait", "decide", "late_page"]
PAGE_PERIOD_S = 0.6  # ODOM_STATUS's PROFILE page: every 6th 100 ms status frame
PAGE_WAIT_S = 2.5 * PAGE_PERIOD_S  # frames held at most this long (bus time) for the page

UNJUDGED_WHY = (f"the firmware runs a different profile than the default robot {DEFAULT_ROBOT}: "
                "give --robot")  # analyze's refusal (host.cli.robotchoice), live

Held = TypeVar("Held")


@dataclass(frozen=True)
class LiveRobot:
    """The robot live judges judge with and where it came from (``source``: ``--robot``,
    ``PROFILE page``, ``default``); ``page_fits``: the shipped profiles the first page fits;
    ``awaits_page``: the default taken for want of a page, whose first page may still
    contradict it (``late_page``); ``page_heard``: the page was heard. ``unjudged``: why
    nothing is judged (``UNJUDGED_WHY``: the default, contradicted by the page), else None."""

    profile: RobotProfile
    source: str
    page_fits: tuple[str, ...] = ()
    awaits_page: bool = False
    page_heard: bool = False

    @property
    def unjudged(self) -> str | None:
        """``UNJUDGED_WHY`` when the page contradicts the default taken, else None."""
        contradicted = (self.source == DEFAULT and self.page_heard
                        and DEFAULT_ROBOT not in self.page_fits)
        return UNJUDGED_WHY if contradicted else None

    def as_dict(self) -> dict[str, Any]:
        """``{"name", "source", "page_fits", "unjudged"}``: the JSON status's ``robot``."""
        return {"name": self.profile.name, "source": self.source,
                "page_fits": list(self.page_fits), "unjudged": self.unjudged}

    def said(self, prefix: str) -> str | None:
        """The one stderr line when the page chose a robot other than the default (a watch of
        the default robot reads as before, quietly, as ``analyze``'s), else None."""
        if self.source != FROM_PAGE or self.profile.name == DEFAULT_ROBOT:
            return None
        return f"{prefix}: robot {self.profile.name!r} (from the firmware's PROFILE page)"

    @property
    def given_as(self) -> str:
        """How a mismatch line names the robot, as ``analyze``'s (``robotchoice.GIVEN_AS``):
        ``(--robot)`` only when it was given (a defaulted pmir once read "not 'pmir' (--robot)"
        with no --robot on the command line)."""
        return GIVEN_AS[self.source]

    def judged_as(self) -> str:
        """``; judged as robot 'NAME' (SOURCE)``, beside a wrong pose."""
        why = "from the firmware's PROFILE page" if self.source == FROM_PAGE else self.given_as
        return f"; judged as robot {self.profile.name!r} ({why})"


class PageWait(Generic[Held]):
    """Frames held until the first valid PROFILE page or ``PAGE_WAIT_S`` of bus time (module
    docstring). ``hold`` keeps one frame and says whether the wait is over; ``decided`` the
    robot then; ``release`` gives the frames held, in bus order."""

    def __init__(self, db: Database) -> None:
        status = db.get_message_by_name("ODOM_STATUS")
        self._status_id = status.frame_id
        self._status = status
        config = e2e_messages(db).get(status.frame_id)
        self._data_ids = None if config is None else config.data_ids
        self.held: list[Held] = []
        self._first_s = math.nan  # bus time of the first frame held
        self._first_local_s = math.nan  # its local monotonic time (a silent bus's end)
        self.fits: tuple[str, ...] | None = None  # None: no page yet

    def hold(self, item: Held, t_s: float, can_id: int, data: bytes, extended: bool,
             local_s: float = math.nan) -> bool:
        """Keep ``item`` (the frame as its judge takes it: ``t_s`` bus time, its identifier and
        payload); True once the wait is over (its page heard, or ``PAGE_WAIT_S`` passed)."""
        if not self.held:
            self._first_s, self._first_local_s = t_s, local_s
        self.held.append(item)
        if not extended and can_id == self._status_id and self.fits is None:
            running = self._page(data)
            if running is not None:
                self.fits = shipped_robots(running)
                return True
        return t_s - self._first_s > PAGE_WAIT_S

    def quiet(self, local_s: float) -> bool:
        """Whether ``PAGE_WAIT_S`` of local time passed since the first frame held (a bus gone
        silent: what was heard is judged, with the default)."""
        return bool(self.held) and local_s - self._first_local_s > PAGE_WAIT_S

    def _page(self, data: bytes) -> RunningProfile | None:
        """The PROFILE page ``data`` carries when its E2E CRC holds, else None."""
        if len(data) != self._status.length or self._data_ids is None:
            return None
        if data[0] != crc8h2f_p02_one(data, self._data_ids[data[1] & ENC_COUNTER_MASK]):
            return None
        try:
            s: Any = self._status.decode(data, decode_choices=False)
        except Exception:  # cantools: an undefined page (never fatal)
            return None
        if int(s["PAGE"]) != PROFILE_PAGE or "PROFILE_CRC" not in s:
            return None
        return RunningProfile(round(float(s["MAX_WHEEL_SPEED"]) * MM_PER_M),
                              int(s["PROFILE_CRC"]))

    def decided(self) -> LiveRobot:
        """The robot the page fits, when exactly one shipped profile does, else the default
        (``unjudged`` when the page contradicts it; awaiting its page when none was heard)."""
        fits = self.fits or ()
        if len(fits) == 1:
            return LiveRobot(robots.load(fits[0]), FROM_PAGE, fits, page_heard=True)
        heard = self.fits is not None
        return LiveRobot(robots.load(DEFAULT_ROBOT), DEFAULT, fits, awaits_page=not heard,
                         page_heard=heard)

    def release(self) -> list[Held]:
        """The frames held, in bus order; the wait holds nothing more."""
        held, self.held = self.held, []
        return held


class _Judged(Protocol):
    """The live judges of ``BusMonitor`` or ``RobotTelemetry``, and their shared events."""

    tracker: PoseTracker
    distance: LiveDistance
    twist: LiveTwist
    events: deque[dict[str, Any]]
    robot: LiveRobot
    sources: SourceWatch


def decide(model: _Judged, wait: PageWait[Held], name: str | None = None) -> list[Held]:
    """The wait over: ``model.robot`` is the robot decided, its judges built anew for it (they
    have judged nothing yet: the frames were held; ``--integrator`` stays); ``name``: the
    DISTANCE judge's robot name (default: the profile's). Returns the frames held, for the
    model to judge now, in bus order."""
    model.robot = wait.decided()
    rebuild(model, name)
    return wait.release()


def late_page(model: _Judged, max_wheel_speed_m_s: float, crc: int,
              name: str | None = None) -> bool:
    """A PROFILE page heard (MAX_WHEEL_SPEED decoded, in m/s; PROFILE_CRC) once the wait is
    over: when the default still awaits its page (the wait ended without one) and this first
    page is not the default's, the watch is ``unjudged`` from now on and its judges are built
    anew (what they judged with the default is forgotten); True then (``name``: ``decide``'s).
    It cannot choose another robot: the watch began with the default (``analyze``, a page not
    in its log's head: the default)."""
    if not model.robot.awaits_page:
        return False
    fits = shipped_robots(RunningProfile(round(max_wheel_speed_m_s * MM_PER_M), crc))
    model.robot = replace(model.robot, page_fits=fits, awaits_page=False, page_heard=True)
    if model.robot.unjudged is None:
        return False
    rebuild(model, name)
    return True


def rebuild(model: _Judged, name: str | None = None) -> None:
    """``model``'s judges built anew for ``model.robot`` (``--integrator`` stays)."""
    chosen = model.robot
    profile, geometry = chosen.profile, Geometry.of(chosen.profile)
    integrator = model.tracker.integrator if model.tracker.forced else None
    model.tracker = PoseTracker(geometry, profile.counter_bits, integrator)
    model.tracker.restarts.events = model.events
    model.tracker.raw.blind = chosen.unjudged is not None  # nothing compared (module docstring)
    model.sources.first = model.tracker.first  # what the reboot watch tells (livefirst)
    wrongs = model.tracker.wrongs  # no twist judged from a conflict on (follow)
    model.distance = LiveDistance(robot_of(name or profile.name, geometry, profile.counter_bits),
                                  wrongs=wrongs)
    model.twist = LiveTwist(geometry, profile.counter_bits, wrongs)
