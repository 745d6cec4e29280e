"""The live view of a CAN bus (``odocan monitor``): the state model fed frame by frame.

``BusMonitor.feed(msg)`` takes every frame heard, in bus order, and never raises on what a bus
carries: frames of unknown IDs, of the wrong DLC, error and remote frames are counted (the
``unknown`` section of ``host.e2e.E2EMonitor``, plus the unknown IDs themselves), frames that
cantools cannot decode are counted as ``undecodable``. Per DBC message it keeps:

* ``count``, ``rate_hz`` and ``jitter_ms``: frames heard, and the rate and the standard deviation of
  the inter-frame period over the last ``messagestats.RATE_WINDOW`` frames (bus timestamps);
  for a multiplexed message the period jitter is per page (``pages``: count, rate and jitter of
  each multiplexer value), as pages sent together have no common period;
* ``e2e``: the Profile 2 counts (``ok``, ``lost``, ``repeated``, ``crc_errors``,
  ``wrong_sequence``), judged as the firmware judges them (``E2EMonitor``, time-widened window);
* ``last``: the latest value of every signal (physical units, enum names), from accepted frames
  only; a multiplexed message keeps the latest value of each page's signals (and
  ``last_frame``, the signals of its latest frame alone, is what the screen shows).

From the decoded frames it follows the firmware: ``status`` (ODOM_STATUS: STATE, INTEGRATOR,
ERROR_MASK with the bits named after ``firmware.errors.ErrorFlag``, UPTIME, frame totals, the
PROFILE page: CRC, bound, a mismatch with the robot, ``host.judge.profilepage``) and the pose
(``PoseTracker``): the on-board pose (ODOM_POSE_X + ODOM_POSE_Y naming one encoder frame) against
a float64 ``ReferenceOdometry`` fed WHEEL_ENCODERS, compared at the very encoder frame the pose
names (ENC_COUNTER), and against SIM_TRUTH when the bus carries it.

Health (``health`` in the snapshot): the verdict never says OK while the pose shown may be wrong.
A node is **stale** once none of its cyclic messages was heard for ``NODE_TIMEOUT_CYCLES`` times
the fastest one's DBC cycle (opendbc's rule: 10 x 20 ms = 0.2 s for ODOM_MCU); every node carries
its age. UPTIME against bus time tells a **reboot** (UPTIME going back, or INIT after running:
the reference restarts, the node's E2E sequences afresh: an event, not lost frames) from **two
sources** on one ID (two UPTIME offsets interleaving); a motor controller restart the reference
re-primes on is a ``counter_restart`` event, as analyze tells it. The verdict, in order: NO
FIRMWARE, STALE, CONFLICT, the firmware's own state when not OK (its REASON; a POSE WRONG
episode, DISTANCE WRONG or TWIST WRONG, once latched, outrank its DEGRADED), POSE WRONG (the
latest sample vs reference beyond ``analyze``'s limit, one LSB of position after the loss
allowance or of heading: ``livefit.pose_wrong``, the start narrowed as ``analyze`` fits it; or
an episode latched since the pose was last set anew, which the latest sample does not undo:
``livestanding``),
UNVERIFIED (nothing compared yet; or, for good, two firmwares were heard, or the PROFILE
page contradicts the default robot: ``liverobot``), HELD (frames the
stamps cannot decide wait for the evidence: ``livesettle``), DISTANCE WRONG and
TWIST WRONG (ODOM_TWIST's DISTANCE and speeds, latched: ``livedistance``, ``livetwist``), OK
(saying so when the reference was placed again after a stall or a gap: ``livestanding``), or
STALE instead while the firmware's last summary is too old to vouch for (``monitorverdict``).

``bus_load`` (``busstats.LoadWindow``): bits per second over the last second of bus time, from
every frame's exact stuffed length; the load as a fraction when given the bitrate.
``snapshot()`` is the whole model as JSON-ready data (``odocan monitor --json``);
``fleet_snapshot`` the MQTT fleet's (``odocan monitor --mqtt``); ``render`` and ``render_fleet``
are re-exported from ``host.report.live``."""

from __future__ import annotations

import time
from collections import Counter, deque
from collections.abc import Callable
from typing import Any

import can
from cantools.database.can import Database, Message

from odocan.host.judge import sources as src  # status_frame, start_new_life
from odocan.host.judge.busstats import LoadWindow
from odocan.host.judge.liveahead import LiveAhead
from odocan.host.judge.liveboottick import boot_frame, refused_named
from odocan.host.judge.liveconfig import SAME_TICK_S, ConfigFollower, follow_config_ack, rebooted
from odocan.host.judge.livedistance import LiveDistance
from odocan.host.judge.livegapseen import heard_encoder
from odocan.host.judge.livekept import KeptWatch
from odocan.host.judge.livepace import LivePace
from odocan.host.judge.liverobot import (
    DEFAULT,
    GIVEN,
    LiveRobot,
    PageWait,
    decide,
    late_page,
)
from odocan.host.judge.livesetpose import SetPoseFollower, apply_set_pose, set_pose_event
from odocan.host.judge.livesettle import SettleHold
from odocan.host.judge.livestallfirst import first_after_of
from odocan.host.judge.livestampgate import StampGate
from odocan.host.judge.livetwins import CRC_RIGHT_REFUSED
from odocan.host.judge.livetwist import LiveTwist
from odocan.host.judge.messagestats import MessageStats
from odocan.host.judge.monitorauth import AUTH_COUNTS as AUTH_COUNTS  # re-exported (its API)
from odocan.host.judge.monitorauth import AuthWatch
from odocan.host.judge.monitorvalues import (
    count_unknown_id,
    error_names,
    messages_snapshot,
    node_ages,
    page_of,
    shown_value,
    to_json,
)
from odocan.host.judge.monitorverdict import summary_stale_why, verdict
from odocan.host.judge.profilepage import follow_profile
from odocan.host.judge.reference import Geometry
from odocan.host.judge.sources import CONFLICT_HOLD_S, FIRMWARE_NODE, SourceWatch
from odocan.host.judge.statuslatch import StatusLatch
from odocan.host.judge.tracking import PoseTracker
from odocan.host.judge.twosenders import CommandSenders
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK
from odocan.host.protocol.decode import frame_key
from odocan.host.protocol.e2e import UNKNOWN, e2e_messages
from odocan.host.protocol.e2e_held import HELD
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.sim.contract import database
from odocan.sim.robot import RobotProfile

STALE_S = 1.0  # a message not heard for this long is shown dimmed
ACCEPTED = frozenset({"ok", "oksomelost", "unprotected"})
MAX_UNKNOWN_IDS = 32  # distinct unknown identifiers listed (all are counted)
_HIDDEN = frozenset({"CHECKSUM", "COUNTER"})
MAX_EVENTS = 16  # events kept (the latest)


class BusMonitor:
    """The state model of ``odocan monitor`` (see the module docstring)."""

    def __init__(self, robot: RobotProfile, integrator: str | None = None,
                 db: Database | None = None, bitrate: int | None = None, *,
                 from_page: bool = False) -> None:
        """``from_page``: no ``--robot``; the PROFILE page picks the robot (``liverobot``)."""
        self.db = db if db is not None else database()
        self.bitrate = bitrate  # bit/s, for bus_load's fraction (None: bits/s only)
        self.load = LoadWindow()
        self.pace = LivePace(self.db)  # a sped-up replay's bus time to the drive's (livepace)
        self._by_key = {frame_key(m.frame_id, m.is_extended_frame): m for m in self.db.messages}
        self.e2e = E2EMonitor(self.db)
        self.e2e.holds = True  # frames the stamps cannot decide wait for the evidence
        self.settle = SettleHold(self.e2e, self.db)
        self._e2e_configs = e2e_messages(self.db)
        self.tracker = PoseTracker(Geometry.of(robot), robot.counter_bits, integrator)
        self.tracker.boot_tick.bind(self.e2e, self._take_encoders)  # (livefreshboot)
        self.first_after = first_after_of(self.tracker, robot, self.db)  # livestallfirst
        self.ahead = LiveAhead(self.db)  # a pose naming a frame not yet sent (liveahead)
        wrongs = self.tracker.wrongs  # no twist judged from a conflict on (follow)
        self.distance = LiveDistance(robot, wrongs=wrongs)  # ODOM_TWIST DISTANCE (livedistance)
        self.twist = LiveTwist(Geometry.of(robot), robot.counter_bits, wrongs)  # (livetwist)
        self.messages: dict[str, MessageStats] = {}
        self.unknown_ids: Counter[str] = Counter()
        self.status: dict[str, Any] = {}
        self.summary_heard_s: float | None = None  # local monotonic time of the last summary
        self.frames_total = 0
        self.undecodable = 0
        self.started_monotonic_s = time.monotonic()
        self.sources = SourceWatch(first=self.tracker.first)
        self.events = self.tracker.restarts.events = deque[dict[str, Any]](maxlen=MAX_EVENTS)
        self.stamps = StampGate[tuple[can.Message, float]](self.events)  # (livestampgate)
        self.latch = StatusLatch()  # the firmware's states and ERROR_MASK bits, latched
        self.set_pose = SetPoseFollower()  # ODOM_SET_POSE staged and applied (its ACKs)
        self.kept = KeptWatch()  # what an APPLY kept: analyze's check, live (livekept)
        self.config = ConfigFollower()  # ODOM_CONFIG likewise
        self._config_id = next((m.frame_id for m in self.db.messages
                                if m.name == "ODOM_CONFIG"), -1)
        self.senders = CommandSenders(self.db)  # two tools on a command message (twosenders)
        self._set_pose_id = next((m.frame_id for m in self.db.messages
                                  if m.name == "ODOM_SET_POSE"), -1)  # -1: a DBC without it
        self.firmware_events: deque[dict[str, Any]] = deque(maxlen=4 * MAX_EVENTS)
        self._bus_time_s = 0.0  # the latest bus timestamp heard
        self.secoc = AuthWatch()  # SecOC (docs/secoc.md): commands awaiting ODOM_AUTH, AUTH_*
        self.auth = self.secoc.counts  # the firmware's AUTH_* refusals, ODOM_AUTH without command
        self.robot = LiveRobot(robot, DEFAULT if from_page else GIVEN)  # odocan's DBC: the page
        self.robot_wait = PageWait[Any](self.db) if from_page and db is None else None  # picks
        self.replayed: Callable[[can.Message], None] = lambda _msg: None  # each held, judged

    def feed(self, msg: can.Message, now_s: float | None = None) -> None:
        """One frame heard on the bus (``now_s``: local monotonic time, default now), stamped
        on the drive's clock (a sped-up replay's: ``livepace``); held while an encoder frame's
        verdict waits for the firmware's evidence (``livesettle``); one stamped more than 1 s
        off the frame before held to its next, set aside if a glitched stamp (livestampgate)."""
        now_s = time.monotonic() if now_s is None else now_s
        for held, held_now_s in self.stamps.through(msg.timestamp, (msg, now_s)):
            self._take(self.pace.stamped(held), held_now_s)

    def _take(self, msg: can.Message, now_s: float) -> None:
        """``feed`` of a frame on the drive's clock (the held frames given back come here)."""
        if self.robot_wait is not None:  # no --robot: held for the PROFILE page (liverobot)
            if self.robot_wait.hold((msg, now_s), msg.timestamp, msg.arbitration_id,
                                    bytes(msg.data), msg.is_extended_id, now_s):
                self._judge_waited()
            return
        if self.settle.held:
            self.settle.held.append((msg, now_s))
            if self.settle.due(msg.timestamp):  # (or its evidence is in: liveearly)
                self.settle.release(self._feed, self._take)
            return
        self._feed(msg, now_s, None)

    def release_held(self) -> None:
        """The watch ends: the frames held are judged now (livestampgate, liverobot, livesettle)."""
        for held, now_s in self.stamps.flush():  # (none or one)
            self._take(self.pace.stamped(held), now_s)
        self._judge_waited()
        self.settle.release(self._feed)

    def _judge_waited(self) -> None:
        """The robot decided (``liverobot``): the frames held for its page judged now, each
        then given to ``replayed`` (live Foxglove publishes what the model made of it)."""
        wait, self.robot_wait = self.robot_wait, None
        for msg, now_s in decide(self, wait) if wait is not None else ():
            self._take(msg, now_s)
            self.replayed(msg)

    def _feed(self, msg: can.Message, now_s: float, verdict: bool | None) -> None:
        """``feed`` one frame; an encoder frame held given back with its ``verdict``."""
        if msg.is_error_frame or msg.is_remote_frame:
            self.frames_total += 1
            self.load.add(msg)
            self.e2e.count_frame_kind(error=msg.is_error_frame, remote=msg.is_remote_frame)
            return
        data, self._now_s = bytes(msg.data), now_s
        timestamp_s = self._bus_time_s = msg.timestamp
        if self.tracker.wrongs.origin_s is None:  # the verdict's times count from here
            self.tracker.wrongs.origin_s = self.ahead.origin_s = timestamp_s
        message = self._by_key.get(frame_key(msg.arbitration_id, msg.is_extended_id))
        if message is not None and self.settle.unheard(msg, verdict):  # heard once, in bus
            heard_encoder(self.tracker, message, data)  # order: livegapseen, gapchecked's count
        summary = self._summary(message, data) if message is not None else None
        if summary is not None:  # before its E2E check, which a reboot or a second source fails
            self._watch_source(*summary, counter=data[1] & ENC_COUNTER_MASK)
        if verdict is None:
            status = self.e2e.check(msg.arbitration_id, data, extended=msg.is_extended_id,
                                    timestamp_s=timestamp_s)
        else:
            status = self.e2e.check_as(msg.arbitration_id, data, timestamp_s, verdict)
        if status == HELD:  # not judged yet: the frames from it wait (livesettle)
            self.settle.open(msg, now_s)
            return
        self.settle.recent.append((msg, status in ACCEPTED))  # a hold's context (livesettle)
        self.frames_total += 1
        self.load.add(msg)
        if message is None:
            count_unknown_id(self.unknown_ids, msg.arbitration_id, MAX_UNKNOWN_IDS)
            return
        if len(data) != message.length:
            return  # counted by E2EMonitor as wrong_dlc
        stats = self.messages.get(message.name)
        if stats is None:
            stats = self.messages[message.name] = MessageStats(message.name, message.frame_id)
        stats.heard(timestamp_s, now_s, page_of(message, data))
        self.tracker.advance(timestamp_s)  # settles the pose halves heard half a cycle before
        self._judge(message, stats, data, status, timestamp_s)
        self.kept.heard(self.tracker, self.tracker.take_samples())  # judged in vs_reference

    def _judge(self, message: Message, stats: MessageStats, data: bytes, status: str,
               timestamp_s: float) -> None:
        """A known frame of the right length by its E2E ``status``: an accepted one used, a
        CRC-right refused encoder frame kept for the twins and gaps, a command message
        (ODOM_CONFIG, ODOM_SET_POSE, NAV_GOAL) watched for a second sender."""
        self.ahead.heard(message.name, timestamp_s, data, status in ACCEPTED)
        crc_right = status in ACCEPTED or status in CRC_RIGHT_REFUSED
        if crc_right and message.frame_id in self.senders.watches:
            self.senders.told(self.events, message.frame_id, data, timestamp_s)
        if status in ACCEPTED:
            self._use(message, stats, data)
        elif crc_right:  # an encoder frame: a twin, a gap's, a boot's; a pose: sent
            refused_named(self.tracker, message.frame_id, message.name, lambda: message.decode(
                data, decode_choices=False), timestamp_s, status)

    def _use(self, message: Message, stats: MessageStats, data: bytes) -> None:
        """Decode an accepted frame, keep its values and follow the firmware."""
        try:
            signals = message.decode(data, decode_choices=False)
        except Exception:  # cantools: unknown multiplexer value, ... (never fatal)
            self.undecodable += 1
            return
        assert isinstance(signals, dict)
        shown = {name: shown_value(message, name, value) for name, value in signals.items()
                 if name not in _HIDDEN}
        stats.last.update(shown)
        stats.last_frame = shown
        handler = _HANDLERS.get(message.name)
        if handler is not None:
            try:
                handler(self, signals, shown)
            except (KeyError, TypeError, ValueError):  # a --dbc without the signals it needs
                self.undecodable += 1

    def _on_command(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        """ODOM_SET_POSE or ODOM_CONFIG: its ODOM_AUTH may follow; staged and applied as the
        firmware acknowledges it (``host.judge.livesetpose``, ``host.judge.liveconfig``)."""
        self.secoc.command("ODOM_SET_POSE" if "FIELD" in shown else "ODOM_CONFIG")
        if "FIELD" in shown:
            field = str(shown["FIELD"])
            self.set_pose.on_frame(int(s["COUNTER"]), field, s.get(field), self.tracker.enc_seq)
            return
        param = str(shown.get("PARAM"))
        self.config.on_frame(int(s["COUNTER"]), param, s.get(param))

    def _on_nav_goal(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        self.secoc.command("NAV_GOAL")

    def _on_auth(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        """ODOM_AUTH: it authenticates the last command frame of the message it names (as the
        firmware's held slot does), or none: counted as an ODOM_AUTH without a command."""
        request = str(shown.get("REQUEST", "?"))
        if self.secoc.authenticates(request) and request == "ODOM_SET_POSE":
            self.set_pose.on_auth(self.tracker.enc_seq)  # the firmware acts on it now

    def _on_ack(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        """ODOM_ACK: of an ODOM_SET_POSE frame, to ``set_pose`` (an applied APPLY restarts
        the reference at the set pose: a ``set_pose`` event); a NACK with an AUTH_* reason is an
        authentication failure (an event)."""
        if int(s["REQUEST_ID"]) == self._set_pose_id:
            applied = self.set_pose.on_ack(int(s["REQUEST_COUNTER"]), int(s["RESULT"]) == 0,
                                           self._bus_time_s)
            if applied is not None:
                pose = apply_set_pose(self.tracker, *applied)
                self.first_after.new_life()
                event = set_pose_event(self._bus_time_s, pose, applied[1])
                self.events.append(self.kept.applied(event, *applied, self.tracker.enc_seq))
        elif int(s["REQUEST_ID"]) == self._config_id:
            follow_config_ack(self, self.config, int(s["REQUEST_COUNTER"]),  # the firmware's
                              int(s["RESULT"]) == 0, self._bus_time_s,  # robot: the judges'
                              int(s["REQUEST_FIELD"]))
        if (refused := self.secoc.refusal(shown, self._bus_time_s)) is not None:
            self.events.append(refused)

    def _on_encoders(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        self._take_encoders((int(s["COUNTER"]), int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]),
                             int(s.get("CTRL_UPTIME", 0))), self._bus_time_s)

    def _take_encoders(self, s: tuple[int, int, int, int], t_s: float) -> None:
        """An accepted WHEEL_ENCODERS frame (COUNTER, counts, CTRL_UPTIME; bus time s: a boot's
        refused frame taken, ``liveboottick``, is the one before the summary heard now)."""
        frame = (s[0], s[1], s[2], t_s, s[3])
        self.tracker.on_encoders(*frame)
        self.first_after.on_encoders(*frame[:4])
        if self.robot.unjudged:  # the page contradicts the default: not judged (liverobot)
            return
        self.distance.on_encoders(self.tracker, *frame)
        self.twist.on_encoders(self.tracker, *frame)

    def _on_twist(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        if self.robot.unjudged:  # (liverobot: nothing judged)
            return
        self.distance.on_twist(self.tracker, int(s["ENC_COUNTER"]), round(s["DISTANCE"] * 1000),
                               self._bus_time_s, int(s["COUNTER"]))
        self.twist.on_twist(self.distance.named, round(s["LINEAR_VEL"] * 1000),
                            round(s["ANGULAR_VEL"] * 1000), self._bus_time_s)

    def _on_pose_x(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        self.tracker.on_pose_x(int(s["ENC_COUNTER"]), float(s["X"]), float(s["HEADING"]),
                               counter=int(s["COUNTER"]), t_s=self._bus_time_s)
        self.first_after.on_pose_x(int(s["ENC_COUNTER"]), float(s["X"]), float(s["HEADING"]),
                                   self._bus_time_s)

    def _on_pose_y(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        self.tracker.on_pose_y(int(s["ENC_COUNTER"]), float(s["Y"]), int(s["TURNS"]),
                               counter=int(s["COUNTER"]), t_s=self._bus_time_s)
        self.first_after.on_pose_y(int(s["ENC_COUNTER"]), float(s["Y"]), int(s["TURNS"]))

    def _on_truth(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        part = int(s["PART"])
        value = s.get({0: "X", 1: "Y", 2: "HEADING"}.get(part, ""))
        if value is not None:
            self.tracker.on_truth(part, int(s["ENC_COUNTER"]), float(value))

    def _on_status(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        page = str(shown.get("PAGE", s.get("PAGE")))
        proven = self.sources.on_page(page.lower(), s, self.tracker)  # the power-up rule
        self.tracker.on_status(self._bus_time_s, s)  # alive; a summary: livereprime
        if page == "SUMMARY":
            self.summary_heard_s = self._now_s  # an OK needs a fresh one (monitorverdict)
            mask = int(s["ERROR_MASK"])
            self.firmware_events += self.latch.observe(self._bus_time_s, int(s["STATE"]),
                                                       int(s["REASON"]), mask)
            self.status.update(
                state=shown["STATE"], integrator=shown["INTEGRATOR"], error_mask=mask,
                errors=error_names(mask), latched_errors=self.latch.latched_names(),
                uptime_s=int(s["UPTIME"]), reason=str(shown.get("REASON", "NONE")),
            )
            integrator = str(shown["INTEGRATOR"]).lower()
            if integrator in ("euler", "rk2", "exact"):
                self.tracker.on_integrator(integrator)
        elif page == "E2E_WHEEL_ENCODERS":
            counts = (int(s["ENC_E2E_OK"]), int(s["ENC_E2E_LOST"]), proven)
            self.distance.on_counts(self.tracker, *counts)  # before the tracker moves on
            self.tracker.on_enc_counts(*counts)
        elif page == "FRAME_TOTALS":
            self.status.update({k.lower(): int(v) for k, v in s.items() if k.endswith("_FRAMES")})
        elif page == "PROFILE":  # what the firmware runs with, against --robot (profilepage)
            late_page(self, s["MAX_WHEEL_SPEED"], int(s["PROFILE_CRC"]))  # (liverobot)
            follow_profile(self, self._bus_time_s, s["MAX_WHEEL_SPEED"], int(s["PROFILE_CRC"]))

    def _watch_source(self, uptime_s: int, state: str, counter: int) -> None:
        """Reboots and a second source, from the summary's UPTIME, STATE and E2E COUNTER
        (module docstring)."""
        before = self.status.get("uptime_s")
        if (told := self.sources.told_ahead(self._bus_time_s, uptime_s, counter)) is not None:
            self._new_life(f"UPTIME {told[1]} s, state {told[2]}, no pose in its tick", *told[1:])
        if (kind := self.sources.observe(self._bus_time_s, uptime_s, state, counter,
                                         seq=self.tracker.enc_seq)) is None:
            return
        detail = f"UPTIME {before} s -> {uptime_s} s, state {state}"
        if kind == "reboot":
            self._new_life(detail, uptime_s, state)
            return
        if kind == "two sources":  # no pose is judged from the second one's first summary
            self.tracker.wrongs.unjudgeable_from(self.sources.conflict_from_s or self._bus_time_s)
            detail = f"two senders of ODOM_STATUS interleave (UPTIME {before} s and {uptime_s} s)"
            last = self.events[-1] if self.events else None
            if last and last["kind"] == kind and self._bus_time_s - last["t_s"] < CONFLICT_HOLD_S:
                last["t_s"] = self._bus_time_s  # one event while the conflict lasts
                return
        self.events.append({"t_s": self._bus_time_s, "kind": kind, "detail": detail})

    def _new_life(self, detail: str, uptime_s: int, state: str, seq: int | None = None) -> None:
        """A reboot told (``seq``: the encoder frame latest heard at its summary, when told by
        the first pose after it): its counters restarted, not frames lost or out of sequence."""
        lost = rebooted(self, self.config, self._bus_time_s)  # its configs were in its RAM
        boot_frame(self.tracker, self.e2e, (uptime_s, state, seq, self._bus_time_s),
                   self._take_encoders, self.sources.held_tick_s)
        detail += ": " + src.start_new_life(self.tracker, self.e2e, self.db, uptime_s, state, seq,
                                            self.sources)
        self.first_after.new_life()
        # its first ticks' (bootticks; its power-up pose's, its summary held back: bootnamed)
        since_s = self.tracker.powerup.life_from_s(self.sources.life_from_s) - SAME_TICK_S
        self.distance.new_life(since_s)  # its first ticks' twists not the old life's
        self.tracker.withdraw_from(since_s)  # its poses vs the old reference
        # its first pose is no resume (livestallfirst): from its boot, UPTIME's whole seconds
        self.first_after.withdraw_from(min(since_s, self._bus_time_s - uptime_s - 1.0))
        self.twist.new_life(since_s)  # its first ticks' twists
        self.set_pose.forget(since_s)  # the new firmware's kept
        self.kept.forget()
        if lost is not None:
            self.events.append({"t_s": self._bus_time_s, "kind": "config", "detail": lost})
        self.events.append({"t_s": self.sources.life_from_s if seq is not None
                            else self._bus_time_s, "kind": "reboot", "detail": detail})

    def _summary(self, message: Message, data: bytes) -> tuple[int, str] | None:
        """(UPTIME, STATE) of a summary whose CRC holds, any sequence (``src.status_frame``)."""
        config = self._e2e_configs.get(frame_key(message.frame_id, message.is_extended_frame))
        src.pose_frame(self.sources, message, data, config, self._bus_time_s,  # power-up
                       self.tracker)  # ticks, poses
        return src.status_frame(self.tracker, message, data, config, self._bus_time_s)

    @property
    def bus_time_s(self) -> float:  # the latest bus timestamp heard (s)
        return self._bus_time_s

    def health(self, now_s: float | None = None) -> dict[str, Any]:
        """The verdict on the firmware and its pose (module docstring), why, node ages, events."""
        now_s = time.monotonic() if now_s is None else now_s
        if self.robot_wait is not None and self.robot_wait.quiet(now_s):  # a silent bus
            self._judge_waited()  # without the page: the default's judges (liverobot)
        if self.settle.quiet(now_s):  # nothing heard for a hold's time: judged now (livesettle)
            self.release_held()
        self.first_after.untie(self.events)  # its re-primes after a stall (livestallfirst)
        nodes = node_ages(self.db, self.messages, now_s)
        state, why = verdict(self, nodes.get(FIRMWARE_NODE))  # (monitorverdict)
        if state == "OK" and (stale := summary_stale_why(self, now_s)):
            state, why = "STALE", stale
        return {"state": state, "why": why, "nodes": nodes, "events": list(self.events),
                "firmware_events": list(self.firmware_events),
                "pose_wrongs": self.tracker.wrongs.as_dict()}  # latched: host.judge.posewrongs

    def snapshot(self, now_s: float | None = None) -> dict[str, Any]:
        """The whole model as JSON-ready data (``odocan monitor --json``); ``now_s``: local
        monotonic time (default now) for the ages."""
        now_s = time.monotonic() if now_s is None else now_s
        e2e = self.e2e.counts()
        messages = messages_snapshot(self.db, self.messages, e2e, now_s)
        return {
            "duration_s": now_s - self.started_monotonic_s,
            "frames_total": self.frames_total,
            "bus_load": self.load.snapshot(self.bitrate),
            "robot": self.robot.as_dict(),  # the judges' robot, where from (liverobot)
            "messages": messages,
            "status": dict(self.status) or None,
            "health": self.health(now_s),
            **self.tracker.snapshot(),
            "distance": self.distance.as_dict(),
            "twist": self.twist.as_dict(),
            "unknown": {**e2e[UNKNOWN], "ids": dict(self.unknown_ids),
                        "undecodable": self.undecodable},
            "auth": dict(self.auth),
            "pace": self.pace.as_dict(),
        }


_HANDLERS = {
    "ODOM_SET_POSE": BusMonitor._on_command,
    "ODOM_CONFIG": BusMonitor._on_command,
    "NAV_GOAL": BusMonitor._on_nav_goal,
    "ODOM_AUTH": BusMonitor._on_auth,
    "ODOM_ACK": BusMonitor._on_ack,
    "WHEEL_ENCODERS": BusMonitor._on_encoders,
    "ODOM_POSE_X": BusMonitor._on_pose_x,
    "ODOM_POSE_Y": BusMonitor._on_pose_y,
    "ODOM_TWIST": BusMonitor._on_twist,
    "SIM_TRUTH": BusMonitor._on_truth,
    "ODOM_STATUS": BusMonitor._on_status,
}


__all__ = ["BusMonitor", "MessageStats", "error_names", "shown_value", "to_json"]
