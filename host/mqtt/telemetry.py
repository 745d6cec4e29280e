"""One robot's frames -> the telemetry the bridge publishes (synchronous, no I/O).

``RobotTelemetry.feed(msg)`` takes every frame of one robot's bus in bus order and returns the
publications it makes due, as ``(leaf, payload)`` pairs (``host.mqtt.topics``); ``feed_frame``
takes the lockstep fleet's frames as its transport queues them (``(t, id, payload)`` tuples, no
``can.Message`` per frame):

* every frame is E2E-checked (``host.e2e.E2EMonitor``: the DBC's E2EDataIDs, Profile 2 CRC and
  sequence) and decoded with cantools (its decode compiled: ``host.mqtt.livedecode``); frames
  the check rejects, and E2E-valid frames cantools cannot decode (an unknown multiplexer page),
  are counted in ``rejected``, never used (foreign IDs by hex up to ``MAX_UNKNOWN_IDS`` of them,
  then as ``other``);
* ``WHEEL_ENCODERS`` steps the float64 reference (``host.reference.ReferenceOdometry``, 24-bit
  wrapping counts); the reference pose after each frame is kept by the frame's E2E ``COUNTER``;
* ``ODOM_POSE_X`` + ``ODOM_POSE_Y`` with the same ``ENC_COUNTER`` make the on-board pose, compared
  with the reference of that very encoder frame: ``pose``, ``reference`` and ``error`` at most
  ``publish_hz`` times per second (``error.pose_vs_reference``: the firmware's arithmetic;
  ``error.pose_wrong``: beyond ``analyze``'s limit, ``host.judge.livefit.pose_wrong``;
  ``error.since_last``: the worst sample since the previous ``error`` when one was wrong, a hold's
  batch included, ``host.mqtt.errorbatch``), the first ``publish_phase_s`` after the first sample
  (a fleet spreads its robots' publications over a period's ticks);
* ``SIM_TRUTH``'s three parts of one encoder frame make ``truth``, compared with the reference of
  that frame (``error.reference_vs_truth``, the latest: what odometry itself cannot know); the
  latest ``truth`` goes out with the next ``pose`` (so a robot's telemetry of a period leaves in
  one socket write), or alone at most ``publish_hz`` times a second while no pose was published
  for two periods;
* ``ODOM_STATUS`` pages and ``ODOM_ACK`` answers feed ``status`` and ``cmd/result`` (enums by their
  DBC names: ``"state": "OK"``); every STATE change and ERROR_MASK bit newly set
  (``host.judge.statuslatch``), every set-pose applied (``host.judge.livesetpose``, which the
  reference follows), every config the firmware applies, whoever sent it, or loses at a reboot
  (``host.judge.liveconfig``, the monitor's follower) and every counter restart it re-primes on
  (``counter_restart``, a motor controller's told by CTRL_UPTIME, as analyze names it) is an event:
  ``status`` carries the latest ``STATUS_EVENTS`` and ``latched_errors`` (every bit seen set),
  retained, so a short DEGRADED is never lost (not a QoS-1 publication each); likewise
  ``pose_wrongs``, the judge's POSE WRONG episodes latched (``host.judge.posewrongs``),
  ``distance``, ODOM_TWIST DISTANCE judged (``host.judge.livedistance``, latched), and ``twist``,
  LINEAR_VEL and ANGULAR_VEL judged (``host.judge.livetwist``, latched: false is TWIST WRONG).

Headings: ``heading_rad`` wrapped to (-pi, pi] and ``heading_unwrapped_rad`` cumulative, on
``pose``, ``reference`` and ``truth`` (SIM_TRUTH's [0, 2 pi) made cumulative at the reference's
turn); ``dheading_rad`` wrapped to (-pi, pi], plus 2 pi per whole turn TURNS is off (the judged
error: beyond pi only then).

``periodic(now_s)`` returns ``status`` and ``rates`` (frames per second per message, last window).
Times: ``t_s`` the frame's bus timestamp (s), ``unix_s`` the wall clock at publication."""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Any

import can
from cantools.database.can import Database

from odocan.host.judge.bootticks import POSE_MESSAGE, pose_heard
from odocan.host.judge.liveahead import LiveAhead
from odocan.host.judge.liveboottick import boot_frame, refused_named
from odocan.host.judge.liveconfig import SAME_TICK_S, rebooted
from odocan.host.judge.livedistance import LiveDistance, robot_of
from odocan.host.judge.livefit import pose_wrong
from odocan.host.judge.livefreshboot import powerup_heard
from odocan.host.judge.livegapseen import heard_status
from odocan.host.judge.livepose import FramePose, difference, pose_dict
from odocan.host.judge.liverobot import DEFAULT, GIVEN, LiveRobot, PageWait
from odocan.host.judge.livestampgate import StampGate, judged
from odocan.host.judge.livestreams import hear_pose_frame
from odocan.host.judge.livetwins import CRC_RIGHT_REFUSED
from odocan.host.judge.livetwist import LiveTwist
from odocan.host.judge.reference import Geometry
from odocan.host.judge.sources import SourceWatch, boot_summary, start_new_life
from odocan.host.judge.statuslatch import StatusLatch
from odocan.host.judge.tracking import PoseTracker
from odocan.host.judge.watchend import end_watch
from odocan.host.mqtt.dbcnames import page_name, signal_value
from odocan.host.mqtt.errorbatch import SinceLast
from odocan.host.mqtt.haltstretch import HaltStretches
from odocan.host.mqtt.livecommands import CommandFollowing
from odocan.host.mqtt.livehold import BridgeHold
from odocan.host.mqtt.liveplan import Plan, plans
from odocan.host.mqtt.liveprofile import ProfileStatus, judge_waited, late_robot_page, wait_page
from odocan.host.mqtt.liveroutes import Route, routes, takes
from odocan.host.mqtt.lsbround import POSE_FIELDS, TRUTH_FIELDS, LsbRounding
from odocan.host.mqtt.statusparts import adopted_sections, unknown_key
from odocan.host.mqtt.topics import stamp, status_payload
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK as MASK
from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_held import HELD
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.sim.contract import database
from odocan.sim.framebatch import Received

Publication = tuple[str, dict[str, Any]]
MAX_UNKNOWN_IDS = 32  # foreign CAN IDs counted by name in ``rejected``; the rest as ``other``
STATUS_EVENTS = 16  # the latest firmware events and set-poses carried by ``status``
TRUTH_PARTS = {0: "X", 1: "Y", 2: "HEADING"}  # SIM_TRUTH's PART: the signal it carries


def _routes(db: Database) -> dict[int, Route]:
    """The routes of ``db``'s 11-bit messages (``host.mqtt.liveroutes``), shared by every robot."""
    return routes(db, _handlers())


@dataclass
class _Window:
    """Frame counts since the last ``rates`` publication."""

    start_s: float
    counts: dict[str, int] = field(default_factory=dict)


class RobotTelemetry(CommandFollowing):
    """The bridge's view of one robot, built only from its bus."""

    def __init__(
        self, name: str, geometry: Geometry, integrator: str, *,
        counter_bits: int,
        publish_hz: float = 10.0,
        publish_phase_s: float = 0.0,
        db: Database | None = None,
        now_s: float = 0.0,
        profile_name: str | None = None,
        from_page: bool = False,
    ) -> None:
        """``geometry``/``integrator``/``counter_bits``: the robot's parameters for the float64
        reference (a 16-bit hardware counter wraps at 16 bits within the 24 on the bus; no
        default: the robot profile's width, or the expected PROFILE CRC is another robot's);
        ``profile_name``: their robot profile's name (``--robot``), said when the firmware's
        PROFILE page differs (default: ``name``); ``from_page``: the page picks (``liverobot``)."""
        self.name = name
        self.db = db if db is not None else database()
        self._by_id = {m.frame_id: m for m in self.db.messages}
        self._lsb = LsbRounding(self.db, POSE_FIELDS)  # float noise off, raw kept (lsbround)
        self._truth_lsb = LsbRounding(self.db, TRUTH_FIELDS)
        self._routes = _routes(self.db)
        self.e2e = E2EMonitor(self.db)
        self.e2e.holds = True  # frames the stamps cannot decide wait for the evidence
        self.hold = BridgeHold(self)  # ... held here (host.mqtt.livehold)
        self.tracker = PoseTracker(geometry, counter_bits, integrator)
        self.tracker.boot_tick.bind(self.e2e, self._on_encoders)  # (livefreshboot)
        wrongs = self.tracker.wrongs  # none judged from a conflict on: LiveDistance.follow
        self.distance = LiveDistance(robot_of(name, geometry, counter_bits), wrongs=wrongs)
        self.twist = LiveTwist(geometry, counter_bits, wrongs)  # LINEAR_VEL, ANGULAR_VEL
        self.ahead = LiveAhead(self.db)  # a pose naming a frame not yet sent (liveahead)
        self.publish_period_s = 1.0 / publish_hz if publish_hz > 0 else math.inf
        self._publish_phase_s = publish_phase_s  # the first pose waits this long (bus time)
        self.frames: dict[str, int] = {}  # accepted frames by message name
        self.rejected: Counter[str] = Counter()
        self._unknown_ids: set[str] = set()
        self._window = _Window(now_s)
        self._twist: dict[str, float] = {}
        self._last_pub_t = -math.inf
        self._truth_error: dict[str, Any] | None = None
        self._truth: dict[str, Any] | None = None  # the latest truth not published yet
        self._truth_pub_t = -math.inf  # bus time of the last truth published (s)
        self._since = SinceLast()  # the samples since the last ``error`` (host.mqtt.errorbatch)
        self._pages: dict[str, dict[str, Any]] = {}  # each ODOM_STATUS page's latest signals
        self.status_seq = 0
        self._status_id = self.db.get_message_by_name("ODOM_STATUS").frame_id
        self._status_ids = e2e_messages(self.db).get(self._status_id)
        pose = self.db.get_message_by_name(POSE_MESSAGE)  # its COUNTER tells power-up ticks
        self._pose_id, self._pose_ids = pose.frame_id, e2e_messages(self.db)[pose.frame_id]
        self._watched = {self._status_id, self._pose_id}  # heard before E2E (_watch_source)
        status = self._by_id[self._status_id]  # per signal: its key in ``firmware``, its enum
        self._status_signals = {sig.name: (sig.name.lower(), sig)
                                for sig in status.signals}
        self._page_names = {int(v): str(n).lower()
                            for v, n in (status.get_signal_by_name("PAGE").choices or {}).items()}
        self.sources = SourceWatch(first=self.tracker.first)  # reboots (host.judge.sources)
        self.latch = StatusLatch()  # the firmware's states and ERROR_MASK bits, latched
        # ... set-poses and the counter restarts the reference follows (its ``RestartLog``)
        self.events = self.tracker.restarts.events = deque[dict[str, Any]](maxlen=STATUS_EVENTS)
        self.stamps: StampGate[can.Message] | None = StampGate(self.events)  # livestampgate
        self._init_commands()  # set-poses, configs, the ACKs awaited (host.mqtt.livecommands)
        self.reboots = 0
        self.stretches: HaltStretches | None = None  # an overloaded fleet's (host.mqtt.overload)
        # per 11-bit identifier (host.mqtt.liveplan): ``plans[id](t_s, data)`` is
        # ``feed_fields(t_s, id, data, False)`` (the bridge calls it without that call)
        self.robot = LiveRobot(robot_of(profile_name or name, geometry, counter_bits),
                               DEFAULT if from_page else GIVEN)  # odocan's DBC: the page picks
        self.profile = ProfileStatus(profile_name, self.robot.given_as)  # ODOM_STATUS PROFILE
        self.robot_wait = PageWait[Any](self.db) if from_page and db is None else None
        self.plans = plans(self, self._routes) if self.robot_wait is None else {}
        self._ended = False  # ``end_watch`` ran

    # --- frames ---
    def feed(self, msg: can.Message) -> list[Publication]:
        """One frame of this robot's bus; returns the publications it makes due (one stamped
        more than 1 s off the one before held to its next, set aside if a glitched stamp:
        ``livestampgate``; ``stamps`` None: none held, the lockstep fleet's simulated clock)."""
        stamps = self.stamps
        if stamps is None or stamps.passes(msg.timestamp):
            return self._heard(msg)
        return judged(stamps.take(msg.timestamp, msg), self._heard)

    def _heard(self, msg: can.Message) -> list[Publication]:
        if msg.is_error_frame or msg.is_remote_frame:
            self.e2e.count_frame_kind(error=msg.is_error_frame, remote=msg.is_remote_frame)
            return []
        return self.feed_fields(msg.timestamp, msg.arbitration_id, bytes(msg.data),
                                msg.is_extended_id)

    def feed_frame(self, frame: Received) -> list[Publication]:
        """``feed`` of a frame as the lockstep transport queues it (``sim.framebatch``): a
        ``DataFrame`` ``(t s, 11-bit id, payload)`` is taken as it is (no ``Message`` built), a
        ``Message`` goes to ``feed``."""
        if type(frame) is tuple:
            t_s, can_id, data = frame
            return self.feed_fields(t_s, can_id, data, False)
        assert isinstance(frame, can.Message)
        return self.feed(frame)

    def feed_fields(self, t_s: float, can_id: int, data: bytes, extended: bool
                    ) -> list[Publication]:
        """One data frame given by its fields (bus timestamp ``t_s`` s, identifier, payload;
        the bridge's ``_handle`` gives a fleet's ``(t, id, payload)`` tuples here directly).

        Runs per frame of every robot (the fleet's hot path): one lookup of the frame's plan
        (``host.mqtt.liveplan``: E2E, decode, counts and handler made for its identifier); a
        frame of no 11-bit message of the DBC is checked (counted) and refused."""
        if self.robot_wait is not None:  # held for the PROFILE page (host.judge.liverobot)
            return wait_page(self, self.robot_wait, t_s, can_id, data, extended)
        plan = None if extended else self.plans.get(can_id)
        if plan is not None:
            return plan(t_s, data)
        if self.hold.settle.held and not extended:  # a hold waits (host.mqtt.livehold)
            return self.hold.hold(t_s, can_id, data)
        status = self.e2e.check(can_id, data, extended=extended, timestamp_s=t_s)
        return self._refused(None, can_id, data, t_s, status)

    def _refused(self, route: Route | None, can_id: int, data: bytes, t_s: float,
                 status: str) -> list[Publication]:
        """A frame refused (its E2E ``status``, or no route): counted in ``rejected``; a
        CRC-right WHEEL_ENCODERS one may be a twin of the latest accepted (``livetwins``); one
        the stamps cannot decide is held (``livehold``)."""
        if status == HELD:
            return self.hold.open(can_id, data, t_s)
        if route is not None:  # a hold's context (livehold)
            self.hold.recent.append((t_s, can_id, data, False))
        tracker = self.tracker  # ``advance``: settles the pose halves heard half a cycle before
        tracker.advance(t_s)
        if status in CRC_RIGHT_REFUSED and route is not None:  # a twin? a pose sent? (liveboottick)
            refused_named(tracker, can_id, route.name, lambda: route.signals(data), t_s, status)
        message = self._by_id.get(can_id)
        self.rejected[message.name if message else unknown_key(  # (statusparts)
            self._unknown_ids, can_id, MAX_UNKNOWN_IDS)] += 1
        return self._samples() if tracker.settled else []

    def end_watch(self) -> list[Publication]:
        """The watch ends (the bridge stops, the fleet's report): the frame the stamp gate held
        (livestampgate), the frames a hold kept (``livehold``) judged, then what the live judges
        still wait with (``host.judge.watchend``); the publications the frames held make. Once:
        a second call judges nothing again."""
        if self._ended:
            return []
        self._ended = True
        held = self.stamps.flush() if self.stamps is not None else []  # (livestampgate)
        published = judged(held, self._heard) + judge_waited(self) + self.hold.release(ends=True)
        end_watch(self.tracker, self.distance)
        return published

    def forced_plans(self, hold: BridgeHold) -> dict[int, Plan]:
        """Plans whose E2E check gives an encoder frame held the verdict ``hold.verdict``
        (``E2EMonitor.check_as``; ``livehold``): made when a hold is judged."""
        check_as = self.e2e.check_as

        def check(can_id: int, data: bytes, extended: bool = False,
                  timestamp_s: float | None = None) -> str:
            assert hold.verdict is not None and timestamp_s is not None
            return check_as(can_id, data, timestamp_s, hold.verdict)

        return plans(self, self._routes, check)  # (not patched onto e2e: mypyc's is final)

    def _undecodable(self, route: Route, t_s: float) -> list[Publication]:
        """An E2E-valid frame cantools cannot decode (an undefined multiplexer value)."""
        if route.advances:
            self.tracker.advance(t_s)
        self.rejected[route.name] += 1
        return self._samples() if self.tracker.settled else []

    def _watch_source(self, route: Route, data: bytes, t_s: float) -> None:
        """A reboot (UPTIME going back, INIT after running, a power-up tick's COUNTERs) starts
        the firmware's new life at its power-up pose, as the monitor and ``analyze`` do
        (``host.judge.sources``); every page to the live gapseen (``livegapseen.heard_status``);
        an ODOM_POSE_X's COUNTER to the watch's pose run (``SourceWatch.hear_pose``)."""
        if route.name == POSE_MESSAGE:
            if (counter := pose_heard(data, self._pose_ids.data_ids)) is not None:
                self.sources.hear_pose(t_s, counter)
                hear_pose_frame(self.sources, route.name, data, t_s, self.tracker)  # two poses
                powerup_heard(self.tracker, counter, lambda: route.signals(data), t_s)  # bootnamed
            return
        if route.status_page is None:
            return
        ids = self._status_ids.data_ids if self._status_ids is not None else None
        if (counter := pose_heard(data, ids)) is not None:  # CRC holding, any sequence
            self.sources.hear_status(t_s, counter)
        heard_status(self.tracker, route.message, data, ids, t_s, route.signals)  # compiled
        summary = (boot_summary(route.message, data, ids, route.signals)
                   if route.is_summary(data) else None)
        if summary is not None and (told := self.sources.told_ahead(
                t_s, summary[0], data[1] & MASK)) is not None:
            self._new_life(t_s, *told[1:])
        kind = None if summary is None else self.sources.observe(
            t_s, *summary, data[1] & MASK, seq=self.tracker.enc_seq)
        if kind == "two sources":  # no pose judged from the second's first summary (monitor)
            self.tracker.wrongs.unjudgeable_from(self.sources.conflict_from_s or t_s)
        if kind == "reboot" and summary is not None:
            self._new_life(t_s, *summary)

    def _new_life(self, t_s: float, uptime_s: int, state: str, seq: int | None = None) -> None:
        """A reboot told at bus time ``t_s`` (``seq``: the encoder frame latest heard at its
        summary, when told by the first pose after it, ``bootticks.boot_ahead``)."""
        self.reboots += 1
        lost = rebooted(self, self.config, t_s)  # its staging and configs were in its RAM
        self.config_doubt = None  # and the config in doubt with them
        boot_frame(self.tracker, self.e2e, (uptime_s, state, seq, t_s), self._on_encoders,
                   self.sources.held_tick_s)
        start_new_life(self.tracker, self.e2e, self.db, uptime_s, state, seq, self.sources)
        # its first ticks' (bootticks; its power-up pose's, its summary held back: bootnamed)
        since_s = self.tracker.powerup.life_from_s(self.sources.life_from_s) - SAME_TICK_S
        self.distance.new_life(since_s)  # its first ticks' twists not the old life's
        self.tracker.withdraw_from(since_s)  # its poses vs the old reference
        self.twist.new_life(since_s)  # its first ticks' twists: the new one's
        self.set_pose.forget(since_s)  # what the new firmware ACKed: kept
        self.kept.forget()
        if lost is not None:
            self.events.append({"t_s": t_s, "kind": "config", "detail": lost})
            self.profile.forget()  # its next PROFILE page is judged against the build's robot

    @takes("COUNTER", "LEFT_COUNT", "RIGHT_COUNT", "CTRL_UPTIME", advances=True)
    def _on_encoders(self, s: tuple[Any, ...], t_s: float) -> list[Publication]:
        counter, left, right, uptime = int(s[0]), int(s[1]), int(s[2]), int(s[3])  # (no *args)
        self.tracker.on_encoders(counter, left, right, t_s, uptime)
        if self.robot.page_heard and self.robot.unjudged is not None:  # a page said (liverobot)
            return []  # (``unjudged`` only after a page: the property read only then)
        self.distance.on_encoders(self.tracker, counter, left, right, t_s, uptime)
        self.twist.on_encoders(self.tracker, counter, left, right, t_s, uptime)
        return []

    @takes("ENC_COUNTER", "X", "HEADING", "COUNTER", advances=True)
    def _on_pose_x(self, s: tuple[Any, ...], t_s: float) -> list[Publication]:
        if self._apply_choice is not None and self._apply_choice.on_pose_x(
                self.tracker, int(s[0]), s[1], s[2]):  # (host.judge.livesetpose_choice)
            self._apply_choice = None
        self.tracker.on_pose_x(int(s[0]), s[1], s[2], int(s[3]), t_s)  # (by position)
        return []

    @takes("ENC_COUNTER", "LINEAR_VEL", "ANGULAR_VEL", "DISTANCE", "COUNTER")
    def _on_twist(self, s: tuple[Any, ...], t_s: float) -> list[Publication]:
        enc_counter, linear, angular, distance, counter = s
        self._twist = {"linear_vel_m_s": linear, "angular_vel_rad_s": angular,
                       "distance_m": distance}
        if self.robot.page_heard and self.robot.unjudged is not None:  # published, not judged
            return []
        self.distance.on_twist(self.tracker, int(enc_counter), round(distance * 1e3), t_s,
                               int(counter))
        self.twist.on_twist(self.distance.named, round(linear * 1e3), round(angular * 1e3), t_s)
        return []

    @takes("ENC_COUNTER", "Y", "TURNS", "COUNTER", advances=True)
    def _on_pose_y(self, s: tuple[Any, ...], t_s: float) -> list[Publication]:
        self.tracker.on_pose_y(int(s[0]), s[1], int(s[2]), int(s[3]), t_s)  # (by position)
        return []

    def pose_waits(self, t_s: float) -> bool:
        """A sample at bus time ``t_s`` publishes no pose (``_samples``): its frames may be held
        (``host.mqtt.framehold``); false before the first pose, after the clock went back."""
        return self._last_pub_t <= t_s < self._last_pub_t + self.publish_period_s - 1e-6

    def _samples(self) -> list[Publication]:
        """The on-board samples the tracker settled on this frame: the latest published, at
        most ``publish_hz`` times per second of bus time (its ODOM_POSE_Y's)."""
        samples = self.kept.heard(self.tracker, self.tracker.take_samples())
        if not samples:
            return []
        if self.stretches is not None:
            self.stretches.on_samples(samples)
        self._since.add(samples, self.tracker.allowance_m)  # a held batch: its worst (errorbatch)
        sample = samples[-1]
        t_s = sample.t_s
        if t_s < self._last_pub_t:  # the bus clock went back (a restart, a replay): follow it
            self._last_pub_t = -math.inf
        if self._last_pub_t == -math.inf and self._publish_phase_s > 0:  # the first sample
            self._last_pub_t = t_s + self._publish_phase_s - self.publish_period_s
        if t_s - self._last_pub_t < self.publish_period_s - 1e-6:
            return []
        self._last_pub_t = t_s
        return self._pose_publications(sample.pose, sample.reference, sample.enc_counter,
                                       sample.counter, t_s)

    def _pose_publications(
        self, pose: FramePose, ref: FramePose | None, enc: int, counter: int, t_s: float
    ) -> list[Publication]:
        head = {"t_s": t_s, "counter": counter, "enc_counter": enc, "enc_seq": pose.seq}
        pubs: list[Publication] = [("pose", stamp(self._lsb({**head, **pose_dict(pose),
                                                              **self._twist})))]
        if ref is None or ref.seq != pose.seq:
            return self._with_truth(pubs, t_s)
        pubs.append(("reference", stamp({**head, **pose_dict(ref)})))
        vs_ref = difference(pose, ref)
        error: dict[str, Any] = {**head, "pose_vs_reference": vs_ref, "pose_wrong": pose_wrong(
            vs_ref["dpos_m"], vs_ref["dheading_rad"], self.tracker.allowance_m(pose.seq))}
        if self._truth_error is not None:
            error["reference_vs_truth"] = self._truth_error
        if (since := self._since.take()) is not None:  # a wrong sample since the last error
            error["since_last"] = since
        pubs.append(("error", stamp(error)))
        return self._with_truth(pubs, t_s)

    def _on_truth(self, s: dict[str, Any], t_s: float) -> list[Publication]:
        enc, part = int(s["ENC_COUNTER"]), int(s["PART"])
        value = s.get(TRUTH_PARTS.get(part, ""), 0.0)
        sample = self.tracker.on_truth(part, enc, float(value))
        if sample is None:
            return []
        truth, ref = sample
        if ref is not None:  # sampled at that very encoder frame (difference: the tracker's)
            self._truth_error = {"enc_seq": ref.seq, **self.tracker.reference_vs_truth.latest}
        self._truth = {"t_s": t_s, "counter": int(s["COUNTER"]), "enc_counter": enc,
                       "enc_seq": truth.seq, **self._truth_lsb(pose_dict(truth))}
        if t_s < self._truth_pub_t:  # the bus clock went back (a restart, a replay): follow it
            self._truth_pub_t = -math.inf
        period_s = self.publish_period_s
        if t_s - self._last_pub_t < 2 * period_s or t_s - self._truth_pub_t < period_s - 1e-6:
            return []  # it goes with the next pose (``_with_truth``)
        return self._with_truth([], t_s)  # no pose published lately: the truth goes alone

    def _with_truth(self, pubs: list[Publication], t_s: float) -> list[Publication]:
        """``pubs`` and the latest ``truth`` not published yet, if any (bus time ``t_s``): the
        truth rides with the pose's publications, so a robot's telemetry of one publication
        period leaves in one socket write, at most ``publish_hz`` times a second."""
        truth, self._truth = self._truth, None
        if truth is not None:
            pubs.append(("truth", stamp(truth)))
            self._truth_pub_t = t_s
        return pubs

    def _on_status(self, s: dict[str, Any], t_s: float) -> list[Publication]:
        page = int(s["PAGE"])
        name = self._page_names.get(page) or page_name(self.db, page)
        self._pages[name] = s  # named when read (``firmware``)
        proven = self.sources.on_page(name, s, self.tracker)  # the power-up rule
        self.tracker.on_status(t_s, s)  # alive (livefirst); a summary: livereprime
        if name == "e2e_wheel_encoders":  # frames the firmware lost: the judge's allowance
            counts = (int(s["ENC_E2E_OK"]), int(s["ENC_E2E_LOST"]), proven)
            self.distance.on_counts(self.tracker, *counts)
            self.tracker.on_enc_counts(*counts)
        elif name == "summary":  # a short DEGRADED or a new ERROR_MASK bit: never lost
            self.events += self.latch.observe(t_s, int(s["STATE"]), int(s["REASON"]),
                                              int(s["ERROR_MASK"]))
        elif name == "profile":  # the bus's speed bound judges; a mismatch is said
            late_robot_page(self, float(s["MAX_WHEEL_SPEED"]), int(s["PROFILE_CRC"]))
            self.on_profile_page(s, t_s)  # (it settles a config two senders left in doubt)
        return []

    # --- periodic ---
    def rates(self, now_s: float) -> Publication:
        """``rates``: frames/s per message since the previous call (wall clock ``now_s``)."""
        window = self._window
        span = max(now_s - window.start_s, 1e-9)
        self._window = _Window(now_s)
        payload = {
            "window_s": round(span, 6),
            "hz": {name: round(n / span, 3) for name, n in sorted(window.counts.items())},
            "frames": dict(sorted(self.frames.items())),
            "rejected": dict(sorted(self.rejected.items())),
            "e2e": self.e2e.counts(),
        }
        return ("rates", stamp(payload))

    @property
    def firmware(self) -> dict[str, Any]:
        """The firmware's last ODOM_STATUS pages by name, each signal by its lower-case name
        (enums by DBC name): made when read (``status``, once a second), not per page heard."""
        signals = self._status_signals
        return {name: {signals[k][0]: signal_value(signals[k][1], v) for k, v in s.items()
                       if k not in ("CHECKSUM", "COUNTER", "PAGE")}
                for name, s in self._pages.items()}

    def status(self, state: str = "online") -> Publication:
        """``status`` (retained): online, the firmware's last ODOM_STATUS pages, a sequence."""
        self.status_seq += 1
        return ("status", status_payload(
            self.name, state, seq=self.status_seq, firmware=self.firmware,
            latched_errors=self.latch.latched_names(), events=list(self.events),
            pose_wrongs=self.tracker.wrongs.as_dict(), frames_total=sum(self.frames.values()),
            distance=self.distance.as_dict(), twist=self.twist.as_dict(),
            profile=self.profile.section, robot_profile=self.robot.as_dict(), **adopted_sections(
                self.tracker.adopted, self.ahead),
        ))


def _handlers() -> dict[str, Any]:
    """``RobotTelemetry``'s handler of each message (a compiled class names none itself)."""
    t, c = RobotTelemetry, CommandFollowing
    return {"WHEEL_ENCODERS": t._on_encoders, "ODOM_POSE_X": t._on_pose_x,
            "ODOM_POSE_Y": t._on_pose_y, "ODOM_TWIST": t._on_twist, "SIM_TRUTH": t._on_truth,
            "ODOM_STATUS": t._on_status, "ODOM_ACK": c._on_ack, "ODOM_SET_POSE": c._on_set_pose,
            "ODOM_CONFIG": c._on_config, "NAV_GOAL": c._on_nav_goal, "ODOM_AUTH": c._on_auth}
