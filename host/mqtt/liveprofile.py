"""The firmware's PROFILE page in the MQTT bridge (``host.mqtt.telemetry``), as the monitor
follows it (``host.judge.profilepage``).

Each new PROFILE_CRC heard on a robot's bus: its live judges take the bus's speed bound
(``profilepage.take_page``: the step gates from the next encoder frame on), and the page is
compared with the robot profile the bridge runs (``--robot``; after a config command, the
parameters it sent) with the integrator its reference runs. ``status`` then carries
``profile``::

    {"verdict": "OK" | "MISMATCH", "profile_crc": "0x4D6D1875", "expected_crc": "0x...",
     "max_wheel_speed_m_s": 4.0, "parameters": ["MAX_WHEEL_SPEED"], "robot": null,
     "detail": "profile mismatch: ..."}

``parameters``: the ODOM_CONFIG PARAM names the CRC and the bound tell apart (empty when they
cannot); ``robot``: the shipped profile whose parameters the firmware runs with; ``detail``: the
one line ``analyze`` prints (None when OK). ``max_wheel_speed_m_s`` is the bound the live judges
take: the page's, except from a page with MAX_WHEEL_SPEED 0 (no bound: they keep theirs, and
``detail`` says so with the verdict OK when the other parameters are ``--robot``'s). A mismatch
(or a page without a bound) is also one ``profile`` event. Before any page (an older firmware's
bus) ``profile`` is None and the profile's own bound stays.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from typing import TYPE_CHECKING, Any, Protocol

from odocan.host.judge.livedistance import LiveDistance
from odocan.host.judge.liverobot import PageWait, decide, late_page
from odocan.host.judge.profilepage import (
    GIVEN_AS,
    diagnose_profile,
    profile_crc,
    take_page,
    unbounded_text,
)
from odocan.host.judge.reference import INTEGRATORS
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.livecommands import SentFrame
from odocan.host.mqtt.liveplan import plans
from odocan.sim.robot import MM_PER_M

if TYPE_CHECKING:
    from odocan.host.mqtt.telemetry import Publication, RobotTelemetry


class _Robot(Protocol):
    """What ``ProfileStatus`` needs of ``RobotTelemetry``."""

    tracker: PoseTracker
    distance: LiveDistance
    events: deque[dict[str, Any]]

    @property
    def firmware(self) -> dict[str, Any]:
        """The firmware's last ODOM_STATUS pages, by name (``RobotTelemetry``'s)."""
        ...


class ProfileStatus:
    """One robot's PROFILE page judged (module docstring); ``section`` is its ``status`` entry."""

    def __init__(self, profile_name: str | None = None, given_as: str = GIVEN_AS) -> None:
        """``profile_name``: the name of the robot profile the bridge runs (``--robot``), said
        in the mismatch; None: the robot's own name. ``given_as``: how the mismatch names it,
        as ``analyze`` does (``the default robot`` when no --robot was given)."""
        self.section: dict[str, Any] | None = None
        self._profile_name = profile_name
        self._given_as = given_as
        self._crc: int | None = None  # the page judged last

    def forget(self) -> None:
        """New parameters sent (a config command): the next page is judged against them."""
        self._crc = None

    def on_page(self, robot: _Robot, s: dict[str, Any], t_s: float) -> None:
        """An accepted PROFILE page (decoded signals ``s``) heard at bus time ``t_s`` (s)."""
        crc = int(s["PROFILE_CRC"])
        if crc == self._crc:
            return
        self._crc = crc
        running = take_page(robot, float(s["MAX_WHEEL_SPEED"]), crc)
        given = robot.distance.robot
        if self._profile_name is not None:
            given = dataclasses.replace(given, name=self._profile_name)
        integrator = _integrator(robot)
        said = diagnose_profile(running, given, integrator, self._given_as)
        kept_mm_s = robot.tracker.geometry.max_wheel_speed_mm_s  # the page's, unless it gave none
        texts = [] if said is None else [said.text]
        if not running.bounded:
            texts.insert(0, unbounded_text(given, kept_mm_s, self._given_as))
        self.section = {
            "verdict": "OK" if said is None else "MISMATCH",
            "profile_crc": f"0x{crc:08X}",
            "expected_crc": f"0x{profile_crc(given, integrator):08X}",
            "max_wheel_speed_m_s": kept_mm_s / MM_PER_M,
            "parameters": [] if said is None else list(said.parameters),
            "robot": None if said is None else said.robot,
            "detail": "; ".join(texts) or None,
        }
        if texts:
            robot.events.append({"t_s": t_s, "kind": "profile", "detail": "; ".join(texts)})


def _integrator(robot: _Robot) -> str:
    """The integrator the bridge's reference runs (``--integrator``), else the one the
    firmware's summary reports, else exact."""
    tracker = robot.tracker
    if tracker.forced and tracker.integrator is not None:
        return tracker.integrator
    summary = robot.firmware.get("summary") or {}
    reported = str(summary.get("integrator", "")).lower()
    return reported if reported in INTEGRATORS else tracker.integrator or "exact"


def judge_waited(telemetry: RobotTelemetry) -> list[Publication]:
    """No ``--robot``: the robot decided by the firmware's PROFILE page (``host.judge.liverobot``:
    its judges, its name in a profile mismatch, the plans made for them), then the frames held
    for the page judged in bus order; the publications they make."""
    wait, telemetry.robot_wait = telemetry.robot_wait, None
    if wait is None:
        return []
    held = decide(telemetry, wait, name=telemetry.name)
    telemetry.profile = ProfileStatus(telemetry.robot.profile.name, telemetry.robot.given_as)
    telemetry.plans.update(plans(telemetry, telemetry._routes))  # the bridge's own dict
    published: list[Publication] = []
    for item in held:
        if isinstance(item, SentFrame):  # the bridge's own command, in its place (livecommands)
            telemetry.command_sent(*item)
        else:
            published += telemetry.feed_fields(*item)
    return published


def late_robot_page(telemetry: RobotTelemetry, max_wheel_speed_m_s: float, crc: int) -> None:
    """A PROFILE page heard once the wait is over (``liverobot.late_page``): when it leaves the
    watch unjudged, its judges were built anew, and the plans made for them too."""
    if late_page(telemetry, max_wheel_speed_m_s, crc, name=telemetry.name):
        telemetry.plans.update(plans(telemetry, telemetry._routes))


def wait_page(telemetry: RobotTelemetry, wait: PageWait[Any], t_s: float, can_id: int,
              data: bytes, extended: bool) -> list[Publication]:
    """A frame held for the PROFILE page (``feed_fields``'s); once the wait is over, every frame
    held judged (``judge_waited``)."""
    if wait.hold((t_s, can_id, data, extended), t_s, can_id, data, extended):
        return judge_waited(telemetry)
    return []
