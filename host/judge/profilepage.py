"""What the firmware says it runs with: ODOM_STATUS page 6 (PROFILE), against ``--robot``.

The firmware sends the plausibility bound in use (MAX_WHEEL_SPEED, u16 mm/s) and PROFILE_CRC, the
CRC-32/ISO-HDLC of its 20-byte parameter set (the DBC comment gives the bytes: COUNTS_PER_REV,
WHEEL_RADIUS_LEFT, WHEEL_RADIUS_RIGHT, WHEELBASE as u32, COUNTER_BITS, INTEGRATOR as u8,
MAX_WHEEL_SPEED as u16, little-endian, in ODOM_CONFIG PARAM order). The host computes the same
CRC from a profile here, from the DBC's definition (not from the firmware's code), so a log made
with other parameters than ``--robot`` is said by name, in one line, before any pose is fitted:
which parameter differs when the CRC and the bound tell it (the speed bound, the integrator, a
shipped profile), else "profile hash differs". A log without the page (older firmware) has
nothing to say here: the judges keep the profile's bound and the pose fit keeps diagnosing.

A page with MAX_WHEEL_SPEED 0 (a firmware in FAULT, or one that lost its configuration) gives
no bound: a 0 mm/s gate would refuse every step beyond one count and fail a correct pose. The
judges keep the bound they have (the last page's, else ``--robot``'s), the offline judges take
the last page with a bound, the CRC is compared with the profile's parameters at bound 0, and
``profile_mismatch`` says so (``UNBOUNDED``).
"""

from __future__ import annotations

import dataclasses
import struct
import zlib
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from odocan.host.io.logs import FrameArrays, iter_log
from odocan.host.judge.reference import INTEGRATORS
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.dbcplan import default_plan
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02_one, e2e_messages
from odocan.sim import robot as robots
from odocan.sim.exceptions import OdocanError
from odocan.sim.robot import MM_PER_M, RobotProfile, list_profiles

if TYPE_CHECKING:
    from odocan.host.judge.livedistance import LiveDistance
    from odocan.host.judge.tracking import PoseTracker

PROFILE_PAGE = busfacts.PROFILE_PAGE  # ODOM_STATUS PAGE "PROFILE"
_LAYOUT = "<IIIIBBH"  # the DBC comment's 20 bytes, little-endian
NM_PER_M = 1_000_000_000
GIVEN_AS = "--robot"  # how a mismatch names the robot the log is judged with, given
HEAD_FRAMES = 1 << 13  # frames of a streamed log's head read for the page (~23 s of the rig's bus)
UNBOUNDED = ("the firmware's PROFILE page gives max wheel speed 0 (no bound: a firmware in "
             "FAULT?); the judges keep {kept_m_s:g} m/s (the last page's bound, else {given_as} "
             "{name}'s)")


@dataclass(frozen=True)
class RunningProfile:
    """The last accepted PROFILE page of a log: what the firmware ran with."""

    max_wheel_speed_mm_s: int  # u16
    profile_crc: int  # u32

    @property
    def max_wheel_speed_m_s(self) -> float:
        return self.max_wheel_speed_mm_s / MM_PER_M

    @property
    def bounded(self) -> bool:
        """False for a page with MAX_WHEEL_SPEED 0: no bound (module docstring)."""
        return self.max_wheel_speed_mm_s > 0


def profile_crc(profile: RobotProfile, integrator: str) -> int:
    """PROFILE_CRC of a firmware configured with ``profile`` and ``integrator``, from the DBC."""
    data = struct.pack(
        _LAYOUT,
        profile.counts_per_rev,
        round(profile.wheel_radius_left_m * NM_PER_M),
        round(profile.wheel_radius_right_m * NM_PER_M),
        round(profile.wheelbase_m * NM_PER_M),
        profile.counter_bits,
        INTEGRATORS.index(integrator),
        profile.max_wheel_speed_mm_s,
    )
    return zlib.crc32(data)


def running_profile(
    frames: FrameArrays, decoder: BulkDecoder | None = None
) -> RunningProfile | None:
    """The last PROFILE page of ``frames`` whose E2E CRC holds and that gives a bound, else the
    last one that holds (MAX_WHEEL_SPEED 0: no bound); None: the log has none. Raw values,
    MAX_WHEEL_SPEED in its 1 mm/s LSB. Only these pages are checked (a handful per minute), so a
    caller need not run the whole log's E2E check for it."""
    pages = _pages(frames, decoder)
    return next((page for page in reversed(pages) if page.bounded), pages[-1] if pages else None)


def running_profile_of(chunks: Iterable[FrameArrays]) -> RunningProfile | None:
    """``running_profile`` of the frames ``chunks`` gives, chunk by chunk (a page is judged by
    its own frame: the same pages at any chunking; ``configs.ConfigPages``)."""
    decoder = BulkDecoder(default_plan())
    last: RunningProfile | None = None
    bounded: RunningProfile | None = None
    for chunk in chunks:
        pages = _pages(chunk, decoder)
        last = pages[-1] if pages else last
        bounded = next((page for page in reversed(pages) if page.bounded), bounded)
    return bounded if bounded is not None else last


def first_page(frames: FrameArrays, decoder: BulkDecoder | None = None) -> RunningProfile | None:
    """The first PROFILE page of ``frames`` whose E2E CRC holds (None: none): what the firmware
    ran with where the log begins, before any config it applies in the log (``shipped_robots``)."""
    pages = _pages(frames, decoder)
    return pages[0] if pages else None


def _pages(frames: FrameArrays, decoder: BulkDecoder | None) -> list[RunningProfile]:
    """The PROFILE pages of ``frames`` whose E2E CRC holds, in log order."""
    decoder = decoder if decoder is not None else BulkDecoder(default_plan())
    try:
        page = decoder.decode_page(frames, "ODOM_STATUS", PROFILE_PAGE)
        data_ids = _status_data_ids()
    except (DecodeError, KeyError):
        return []
    if "PROFILE_CRC" not in page or data_ids is None:
        return []
    pages = []
    for row, position in enumerate(page["index"]):
        data = bytes(frames.data[int(position)])
        if frames.dlc[int(position)] == 8 and data[0] == crc8h2f_p02_one(
                data, data_ids[data[1] & ENC_COUNTER_MASK]):
            pages.append(RunningProfile(int(page["MAX_WHEEL_SPEED"][row]),
                                        int(page["PROFILE_CRC"][row])))
    return pages


def head_profile(
    path: Path, head_frames: int = HEAD_FRAMES,
    pick: Callable[[FrameArrays], RunningProfile | None] = running_profile,
) -> RunningProfile | None:
    """``pick`` (``running_profile``, ``first_page``) of a log's first ``head_frames`` frames (a
    streamed analysis: the page comes every 600 ms, so the head of a log holds it); None when
    they hold none or the log cannot be read (the analysis says why)."""
    return head_read(path, pick, head_frames)


_Read = TypeVar("_Read")


def head_read(path: Path, pick: Callable[[FrameArrays], _Read | None],
              head_frames: int = HEAD_FRAMES) -> _Read | None:
    """``pick`` of a log's first ``head_frames`` frames, the whole log left unread; None when
    it picks nothing or the log cannot be read (the analysis says why)."""
    try:
        for chunk in iter_log(path, chunk_frames=head_frames, warn=lambda _text: None):
            return pick(chunk)
    except (OdocanError, OSError):
        return None
    return None


def _status_data_ids() -> tuple[int, ...] | None:
    """ODOM_STATUS's E2EDataIDs, from the contract."""
    for message in e2e_messages(default_plan()).values():
        if message.name == "ODOM_STATUS":
            return message.data_ids
    raise KeyError("ODOM_STATUS")


def with_bus_speed(profile: RobotProfile, running: RunningProfile | None) -> RobotProfile:
    """``profile`` with the bus's speed bound when the log reports one (the judges' bound on
    what a gap or a stall may hide is the firmware's, not the command line's); a page without a
    bound (MAX_WHEEL_SPEED 0) leaves ``profile``'s."""
    if running is None or not running.bounded or \
            running.max_wheel_speed_mm_s == profile.max_wheel_speed_mm_s:
        return profile
    return dataclasses.replace(profile, max_wheel_speed_m_s=running.max_wheel_speed_m_s)


@dataclass(frozen=True)
class Mismatch:
    """How the firmware's parameters differ from a profile: ``text``, one line; ``parameters``,
    the ODOM_CONFIG PARAM names the CRC and the bound tell (empty when they cannot tell);
    ``robot``, the shipped profile whose parameters the firmware runs with (None: none)."""

    text: str
    parameters: tuple[str, ...] = ()
    robot: str | None = None


def profile_mismatch(
    running: RunningProfile | None, given: RobotProfile, integrator: str,
    given_as: str = GIVEN_AS,
) -> str | None:
    """One line naming how the firmware's parameters differ from ``given`` (``--robot``; the
    line names it ``given_as``: "the default robot" when none was given) run with
    ``integrator``, or that its page gives no bound (``UNBOUNDED``); None when they are the
    same or the log has no PROFILE page."""
    said = diagnose_profile(running, given, integrator, given_as)
    texts = [] if said is None else [said.text]
    if running is not None and not running.bounded:
        texts.insert(0, unbounded_text(given, given.max_wheel_speed_mm_s, given_as))
    return "; ".join(texts) or None


def unbounded_text(given: RobotProfile, kept_mm_s: int, given_as: str = GIVEN_AS) -> str:
    """``UNBOUNDED`` said for ``given`` (``--robot``; named ``given_as``), the judges keeping
    ``kept_mm_s``."""
    return UNBOUNDED.format(kept_m_s=kept_mm_s / MM_PER_M, name=given.name, given_as=given_as)


def diagnose_profile(
    running: RunningProfile | None, given: RobotProfile, integrator: str,
    given_as: str = GIVEN_AS,
) -> Mismatch | None:
    """``profile_mismatch``'s line with the parameters it names; None when the firmware's
    parameters are ``given``'s run with ``integrator`` or the log has no PROFILE page."""
    if running is None or running.profile_crc == profile_crc(given, integrator):
        return None
    if not running.bounded and running.profile_crc == profile_crc(
            dataclasses.replace(given, max_wheel_speed_m_s=0.0), integrator):
        return None  # given's parameters, without a bound (``profile_mismatch`` says that)
    bus_speed = with_bus_speed(given, running)
    speed = () if bus_speed is given else ("MAX_WHEEL_SPEED",)
    speed_said = (f"the log's firmware runs with max wheel speed {running.max_wheel_speed_m_s:g}"
                  f" m/s, {given_as} {given.name} says {given.max_wheel_speed_m_s:g} m/s")
    if running.profile_crc == profile_crc(bus_speed, integrator):
        return Mismatch(f"profile mismatch: {speed_said}", speed)
    for other in INTEGRATORS:
        if running.profile_crc == profile_crc(bus_speed, other):
            extra = "" if bus_speed is given else f"; {speed_said}"
            return Mismatch(f"profile mismatch: the log's firmware runs with integrator {other}, "
                            f"not {integrator}{extra}", ("INTEGRATOR", *speed))
    fits = _shipped_fits(running, given)
    if fits:
        return Mismatch(f"profile mismatch: profile hash differs: the log's firmware runs with "
                        f"the parameters of robot {fits!r}, not {given.name!r} ({given_as})",
                        robot=fits)
    return Mismatch(f"profile mismatch: profile hash differs (log 0x{running.profile_crc:08X}, "
                    f"{given_as} {given.name} 0x{profile_crc(given, integrator):08X})"
                    + ("" if bus_speed is given else f"; {speed_said}"), speed)


def _shipped_fits(running: RunningProfile, given: RobotProfile) -> str | None:
    """The shipped profile (any integrator, the bus's speed bound or its own) whose CRC is the
    log's; None when none is."""
    for name in list_profiles():
        if name == given.name:
            continue
        shipped = robots.load(name)
        for candidate in (shipped, with_bus_speed(shipped, running)):
            if any(running.profile_crc == profile_crc(candidate, i) for i in INTEGRATORS):
                return name
    return None


def shipped_robots(running: RunningProfile | None) -> tuple[str, ...]:
    """The shipped profiles whose parameters ``running``'s PROFILE_CRC is, run with any
    integrator, with their own speed bound, the page's, or none (a page without a bound):
    the robot ``analyze`` and ``replay`` take when ``--robot`` is not given and exactly one
    fits (``host.cli.robotchoice``). Empty without a page."""
    if running is None:
        return ()
    fits = []
    for name in list_profiles():
        shipped = robots.load(name)
        unbounded = dataclasses.replace(shipped, max_wheel_speed_m_s=0.0)
        candidates = (shipped, with_bus_speed(shipped, running),
                      *(() if running.bounded else (unbounded,)))
        if any(running.profile_crc == profile_crc(candidate, integrator)
               for candidate in candidates for integrator in INTEGRATORS):
            fits.append(name)
    return tuple(fits)


class _Judges(Protocol):
    """The live judges of a monitor's model or a bridge's robot."""

    tracker: PoseTracker
    distance: LiveDistance


class _Named(Protocol):
    """How the monitor's robot is named in a mismatch (``liverobot.LiveRobot``)."""

    @property
    def given_as(self) -> str:
        """``--robot``, ``the default robot`` or ``its PROFILE page's robot``."""
        ...


class _Model(_Judges, Protocol):
    """What ``follow_profile`` needs of ``host.judge.monitor.BusMonitor``."""

    status: dict[str, Any]
    events: deque[dict[str, Any]]

    @property
    def robot(self) -> _Named:
        """The robot the judges judge with (``liverobot.LiveRobot``)."""
        ...


def take_page(model: _Judges, max_wheel_speed_m_s: float, crc: int) -> RunningProfile:
    """A PROFILE page heard live (MAX_WHEEL_SPEED decoded, in m/s; PROFILE_CRC): the live
    judges take its bound, their step gates from the next encoder frame on
    (``PoseTracker.take_speed_bound``, ``LiveDistance.take_speed_bound``), as the firmware's
    gate runs with it; returns the page's raw values. A page without a bound (0) is not taken:
    the judges keep theirs (module docstring)."""
    running = RunningProfile(round(max_wheel_speed_m_s * MM_PER_M), crc)
    if running.bounded:
        model.tracker.take_speed_bound(running.max_wheel_speed_mm_s)
        model.distance.take_speed_bound(model.tracker.geometry)
    return running


def follow_profile(model: _Model, t_s: float, max_wheel_speed_m_s: float, crc: int) -> None:
    """The live side (monitor): a PROFILE page heard at ``t_s`` (MAX_WHEEL_SPEED decoded, in
    m/s; PROFILE_CRC). When it says something new, the status shows the firmware's CRC and
    the bound the live judges take (``take_page``: the page's, unless it gives none), and a
    page without a bound (said first) or a mismatch with the robot the
    model was built for, run with the integrator the firmware reports (``--integrator`` is the
    judge's choice), becomes one ``profile`` event and ``status["profile_mismatch"]``."""
    shown = f"0x{crc:08X}"
    if model.status.get("profile_crc") == shown:
        return
    running = take_page(model, max_wheel_speed_m_s, crc)
    tracker = model.tracker
    kept_mm_s = tracker.geometry.max_wheel_speed_mm_s  # the page's, unless it gave none
    model.status.update(profile_crc=shown, max_wheel_speed_m_s=kept_mm_s / MM_PER_M)
    reported = str(model.status.get("integrator", "")).lower()  # the firmware's own: a judge's
    integrator = reported if reported in INTEGRATORS else tracker.integrator or "exact"  # choice
    found = diagnose_profile(running, model.distance.robot, integrator,  # is no mismatch
                             model.robot.given_as)  # (the default robot): analyze's words
    texts = [] if found is None else [found.text]
    if not running.bounded:
        texts.insert(0, unbounded_text(model.distance.robot, kept_mm_s, model.robot.given_as))
    said = "; ".join(texts) or None
    model.status["profile_mismatch"] = said
    if said is not None:
        model.events.append({"t_s": t_s, "kind": "profile", "detail": said})
