"""One robot's handling of each CAN ID it hears, fused into one function per ID (its plan).

The bridge's frame handling runs per frame of every robot of a fleet. Routed step by step,
a frame paid for three lookups and a dozen attribute reads before its judge saw it: its route
(``host.mqtt.liveroutes``), whether it is an ODOM_STATUS page, whether its handler advances
the tracker, its name, handler and decoder, the telemetry's counters. A plan reads all of that
once, when the robot's telemetry is made, and keeps it in the closure of one function per
11-bit message of the DBC (``RobotTelemetry.plans``, which the bridge's ``_handle`` calls
without ``feed_fields`` around it): ``plan(t_s, data)`` checks the frame's E2E
(``host.protocol.e2e_live.E2EMonitor.check``, bound), decodes it (the route's compiled
decoder), counts it and gives it to the judge's entry (the route's handler), in the very order
``feed_fields`` took them before (``bench/bridge_frames.py``'s digest of every publication of
a fleet's frames is unchanged; tests/test_mqtt_liveplan.py feeds frames with faults by the
plans alone).

What a plan does not handle itself it gives back to the telemetry as before: a frame its E2E
check refuses (``RobotTelemetry._refused``), one cantools could not decode
(``RobotTelemetry._undecodable``); an ODOM_STATUS page and an ODOM_POSE_X go to the reboot
watch first (``RobotTelemetry._watch_source``: before E2E, a reboot fails it;
``host.judge.bootticks``: a power-up tick's COUNTERs), an ODOM_TWIST is kept for it (its
DISTANCE going back: ``host.judge.distfall``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from cantools.database.errors import DecodeError

from odocan.host.judge.distfall import TWIST_MESSAGE, distance_field
from odocan.host.judge.livegapseen import heard_encoder
from odocan.host.judge.navrestart import NAV_MESSAGE
from odocan.host.mqtt.liveroutes import Route
from odocan.host.protocol.e2e import e2e_messages

if TYPE_CHECKING:
    from odocan.host.mqtt.telemetry import RobotTelemetry

Publication = tuple[str, dict[str, Any]]
Plan = Callable[[float, bytes], list[Publication]]
Check = Callable[[int, bytes, bool, float | None], str]  # ``E2EMonitor.check``'s signature
ACCEPTED_E2E = frozenset({"ok", "oksomelost", "unprotected"})


def plans(telemetry: RobotTelemetry, routes: dict[int, Route],
          check: Check | None = None) -> dict[int, Plan]:
    """Every route's plan for ``telemetry``, by 11-bit identifier; ``check``: the E2E check
    they make (else ``telemetry.e2e.check``: a hold's forced verdict, ``forced_plans``)."""
    return {can_id: plan_of(telemetry, can_id, route, check) for can_id, route in routes.items()}


def plan_of(telemetry: RobotTelemetry, can_id: int, route: Route,
            check: Check | None = None) -> Plan:
    """``route``'s plan: a counted-only message, a watched one (ODOM_STATUS, ODOM_POSE_X), or
    any handled one."""
    plan = (_counted if route.handler is None else _handled)(
        telemetry, can_id, route, check or telemetry.e2e.check)
    if route.name == TWIST_MESSAGE:
        return _twist_kept(telemetry, can_id, route, plan)
    if route.name == NAV_MESSAGE:
        return _nav_kept(telemetry, can_id, plan)
    if route.name == "WHEEL_ENCODERS" and check is None:  # not a hold's forced plan: the
        return _encoder_heard(telemetry, route, plan)  # frame was heard when first fed
    if can_id not in telemetry._watched:
        return plan
    watch = telemetry._watch_source

    def watched_plan(t_s: float, data: bytes) -> list[Publication]:
        watch(route, data, t_s)  # before E2E: a reboot fails it
        return plan(t_s, data)

    return watched_plan


def _encoder_heard(telemetry: RobotTelemetry, route: Route, plan: Plan) -> Plan:
    """WHEEL_ENCODERS' plan, each frame heard first, before its E2E check, by the live gapseen
    (``livegapseen.heard_encoder``: ``gapchecked``'s count of the frames logged)."""
    message = route.message
    if message.name != "WHEEL_ENCODERS":  # (a route of another name: ``heard_encoder`` as is)
        def any_plan(t_s: float, data: bytes) -> list[Publication]:
            heard_encoder(telemetry.tracker, message, data)
            return plan(t_s, data)

        return any_plan
    length = message.length  # ``heard_encoder``'s test, its cantools properties read once

    def encoder_plan(t_s: float, data: bytes) -> list[Publication]:
        if len(data) == length:
            telemetry.tracker.placer.seen.heard_encoder()
        return plan(t_s, data)

    return encoder_plan


def _twist_kept(telemetry: RobotTelemetry, can_id: int, route: Route, plan: Plan) -> Plan:
    """ODOM_TWIST's plan, each frame kept first (bus time, bytes: one append) for the reboot
    watch, which reads its DISTANCE only when a pose may tell a reboot
    (``host.judge.distfall``: DISTANCE going back tells a new firmware)."""
    sources = telemetry.sources
    if sources.twist_field is None:  # once a robot (``forced_plans`` makes them again)
        sources.twist_field = distance_field(route.message, e2e_messages(telemetry.db).get(can_id))
    hear, field = sources.twists.hear, sources.twist_field  # one held back: left out

    def twist_plan(t_s: float, data: bytes) -> list[Publication]:
        hear(field, t_s, data)
        return plan(t_s, data)

    return twist_plan


def _nav_kept(telemetry: RobotTelemetry, can_id: int, plan: Plan) -> Plan:
    """NAV_STATUS's plan, each frame kept first (bus time, bytes) for the reboot watch, which
    reads its COUNTER only when a summary may tell a reboot (``host.judge.navrestart``)."""
    sources = telemetry.sources
    config = e2e_messages(telemetry.db).get(can_id)
    sources.nav_ids = None if config is None else config.data_ids
    keep = sources.navs.append

    def nav_plan(t_s: float, data: bytes) -> list[Publication]:
        keep((t_s, data))
        return plan(t_s, data)

    return nav_plan


def _handled(telemetry: RobotTelemetry, can_id: int, route: Route, check: Check) -> Plan:
    """A message with a handler: E2E, the tracker's advance (unless the handler's own first
    act), decode, counts, the handler, then the samples the tracker settled."""
    tracker, frames = telemetry.tracker, telemetry.frames
    refused, undecodable = telemetry._refused, telemetry._undecodable
    name, decode, handler, advances = route.name, route.decode, route.handler, route.advances
    recent = telemetry.hold.recent.append  # a hold's context (host.mqtt.livehold)
    ahead = telemetry.ahead.hearer(name)  # a pose naming a frame not yet sent (liveahead)

    def plan(t_s: float, data: bytes) -> list[Publication]:
        status = check(can_id, data, False, t_s)  # the window widens with time (by position)
        if ahead is not None and len(data) == route.message.length:
            ahead(t_s, data, status in ACCEPTED_E2E)
        if status not in ACCEPTED_E2E:
            return refused(route, can_id, data, t_s, status)
        recent((t_s, can_id, data, True))
        if not advances:
            tracker.advance(t_s)
        try:  # E2E-valid yet undecodable, e.g. a multiplexer value the DBC does not define
            signals = decode(data)
        except DecodeError:
            return undecodable(route, t_s)
        frames[name] = frames.get(name, 0) + 1  # plain dicts: a Counter's += is slower
        counts = telemetry._window.counts
        counts[name] = counts.get(name, 0) + 1
        publications: list[Publication] = handler(telemetry, signals, t_s)
        if tracker.settled:
            return publications + telemetry._samples() if publications else telemetry._samples()
        return publications

    return plan


def _counted(telemetry: RobotTelemetry, can_id: int, route: Route, check: Check) -> Plan:
    """A message without a handler (another node's, e.g. MOTOR_CMD): checked and counted."""
    tracker, frames = telemetry.tracker, telemetry.frames
    refused, name = telemetry._refused, route.name
    recent = telemetry.hold.recent.append  # a hold's context (host.mqtt.livehold)

    def plan(t_s: float, data: bytes) -> list[Publication]:
        status = check(can_id, data, False, t_s)
        if status not in ACCEPTED_E2E:
            return refused(route, can_id, data, t_s, status)
        recent((t_s, can_id, data, True))
        tracker.advance(t_s)
        frames[name] = frames.get(name, 0) + 1
        counts = telemetry._window.counts
        counts[name] = counts.get(name, 0) + 1
        return telemetry._samples() if tracker.settled else []

    return plan
