"""The commands ``RobotTelemetry`` (``host.mqtt.telemetry``) follows on its robot's bus: the
ODOM_SET_POSE and ODOM_CONFIG frames it hears (another tool's, or the bridge's own through
``command_sent``), staged and applied as the firmware ACKs them (``host.judge.livesetpose``;
``host.judge.liveconfig``, the monitor's follower: what the firmware ACKs, forgotten at a
reboot, is the judges' robot, not what a ``cmd/config`` asked), and the ODOM_ACK answering a
command the bridge sent (its ``cmd/result``). Moved out of ``host.mqtt.telemetry`` (a module
near 500 lines).
"""

from __future__ import annotations

import contextlib
from collections import deque
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

from cantools.database.can import Database
from cantools.database.errors import DecodeError

from odocan.host.judge.liveadopted import TWO_SENDERS_SET_POSE
from odocan.host.judge.liveconfig import ConfigFollower, follow_config_ack
from odocan.host.judge.liveconfigdoubt import ConfigDoubt, doubt_config, settle_config
from odocan.host.judge.livedistance import LiveDistance
from odocan.host.judge.livekept import KeptWatch
from odocan.host.judge.livesetpose import SetPoseFollower, apply_set_pose, set_pose_event
from odocan.host.judge.livesetpose_choice import ApplyChoice
from odocan.host.judge.livetwist import LiveTwist
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.dbcnames import choice, named_value
from odocan.host.mqtt.topics import RESULT_LEAF, stamp

if TYPE_CHECKING:
    from odocan.host.judge.liverobot import PageWait
    from odocan.host.mqtt.liveprofile import ProfileStatus
    from odocan.host.mqtt.liveroutes import Route

Publication = tuple[str, dict[str, Any]]
COMMANDS = ("ODOM_SET_POSE", "ODOM_CONFIG", "NAV_GOAL", "ODOM_AUTH")  # the bridge sends these
FOLLOWED = ("ODOM_SET_POSE", "ODOM_CONFIG", "ODOM_AUTH")  # its own followed when sent
ECHO_FRAMES = 32  # own command frames kept for their echo (``_echo``)


class SentFrame(NamedTuple):
    """A command frame the bridge sent while its frames wait for the PROFILE page: followed
    when they are judged, in their order (``command_sent``)."""

    can_id: int
    data: bytes


@dataclass
class PendingAck:
    """A command frame sent, waiting for its ODOM_ACK."""

    cmd_id: Any
    command: str
    final: bool  # the APPLY / GO frame: its ACK completes the command
    data: bytes = b""  # the frame's 8 bytes: what a ``cmd/result`` names when unanswered
    origin: object | None = None  # the command sent (ids may repeat, or be null, across commands)


class CommandFollowing:
    """``RobotTelemetry``'s command handlers (module docstring); it gives the judges."""

    db: Database
    _routes: dict[int, Route]
    tracker: PoseTracker
    distance: LiveDistance
    twist: LiveTwist
    events: deque[dict[str, Any]]
    profile: ProfileStatus
    robot_wait: PageWait[Any] | None

    @property
    def firmware(self) -> dict[str, Any]:
        """The firmware's last ODOM_STATUS pages, by name (``RobotTelemetry``'s)."""
        raise NotImplementedError

    def _init_commands(self) -> None:
        """The followers' state (``db`` set): nothing staged, no ACK awaited."""
        self.pending: dict[tuple[int, int], PendingAck] = {}
        # ODOM_SET_POSE staged and applied (its ACKs); its own frames followed when sent
        self.set_pose = SetPoseFollower(bus_order=False)
        self.kept = KeptWatch()  # what an APPLY kept: analyze's check, live (livekept)
        self._apply_choice: ApplyChoice | None = None
        set_pose = next((m for m in self.db.messages if m.name == "ODOM_SET_POSE"), None)
        self._set_pose_id = set_pose.frame_id if set_pose is not None else -1
        self._set_pose_fields: Any = set_pose.get_signal_by_name("FIELD").choices or {} \
            if set_pose is not None else {}
        # ODOM_CONFIG staged and applied (its ACKs); its own frames followed when sent, not
        # in the bus's order among another tool's
        self.config = ConfigFollower(bus_order=False)
        self.config_doubt: ConfigDoubt | None = None  # two senders' config: which not known
        self.contested: dict[Any, str] = {}  # cmd id: another tool's frame heard in its flight
        self._own_frame = False  # the frame handled now is the bridge's own (``command_sent``)
        # the bridge's own frames not heard back yet: (message, its signals) (``_echo``)
        self._unechoed: deque[tuple[str, tuple[Any, ...]]] = deque(maxlen=ECHO_FRAMES)
        config = next((m for m in self.db.messages if m.name == "ODOM_CONFIG"), None)
        self._config_id = config.frame_id if config is not None else -1
        self._config_params: Any = config.get_signal_by_name("PARAM").choices or {} \
            if config is not None else {}
        nav_goal = next((m for m in self.db.messages if m.name == "NAV_GOAL"), None)
        self._nav_goal_fields: Any = nav_goal.get_signal_by_name("FIELD").choices or {} \
            if nav_goal is not None else {}

    def _on_set_pose(self, s: dict[str, Any], t_s: float) -> list[Publication]:
        """An ODOM_SET_POSE frame on the bus (another tool's; the bridge's own go through
        ``command_sent``): staged and applied as the firmware ACKs it."""
        if self._echo("ODOM_SET_POSE", s):
            return []
        field = str(named_value(self._set_pose_fields, s["FIELD"]))
        self.set_pose.on_frame(int(s["COUNTER"]), field, s.get(field), self.tracker.enc_seq)
        if not self._own_frame:
            self._foreign("ODOM_SET_POSE", int(s["COUNTER"]), field, t_s)
        return []

    def _on_nav_goal(self, s: dict[str, Any], t_s: float) -> list[Publication]:
        """A NAV_GOAL frame on the bus: another tool's (the bridge's own: ``_echo``)."""
        if self._echo("NAV_GOAL", s):
            return []
        field = str(named_value(self._nav_goal_fields, s["FIELD"]))
        self._foreign("NAV_GOAL", int(s["COUNTER"]), field, t_s)
        return []

    def _on_config(self, s: dict[str, Any], t_s: float) -> list[Publication]:
        """An ODOM_CONFIG frame on the bus (another tool's, or the bridge's own through
        ``command_sent``): staged and applied as the firmware ACKs it."""
        if self._echo("ODOM_CONFIG", s):
            return []
        param = str(named_value(self._config_params, s["PARAM"]))
        self.config.on_frame(int(s["COUNTER"]), param, s.get(param))
        if not self._own_frame:
            self._foreign("ODOM_CONFIG", int(s["COUNTER"]), param, t_s)
        return []

    def _foreign(self, message: str, counter: int, field: str, t_s: float) -> None:
        """Another tool's frame of command ``message`` (ODOM_CONFIG, ODOM_SET_POSE, NAV_GOAL)
        heard while the bridge's own command on it is in flight (its frames sent, not all
        answered): two senders (``host.judge.twosenders``). The ODOM_ACKs name a frame by its
        COUNTER only, the firmware drops the second of two frames of one COUNTER unanswered,
        and both tools' writes share one staged set: the command is answered ``contested``,
        never ``acked`` (``_answered``), and a ``two senders`` event says so."""
        can_id = self.db.get_message_by_name(message).frame_id
        in_flight = {p.cmd_id: p.command for (sent_id, _), p in self.pending.items()
                     if sent_id == can_id and p.cmd_id not in self.contested}
        for cmd_id, command in in_flight.items():
            detail = (f"two senders on {message}: another tool's frame (COUNTER {counter}, "
                      f"{field}) heard while this bridge's {command} {cmd_id!r} was in flight")
            self.contested[cmd_id] = detail
            self.events.append({"t_s": t_s, "kind": "two senders", "detail": detail})

    def _on_auth(self, s: dict[str, Any], t_s: float) -> list[Publication]:
        if self._echo("ODOM_AUTH", s):
            return []
        if int(s["REQUEST"]) == 1:  # ODOM_SET_POSE (the DBC's VAL_): the firmware acts now
            self.set_pose.on_auth(self.tracker.enc_seq)
        return []

    def command_sent(self, can_id: int, data: bytes) -> None:
        """A command frame the bridge itself sent, followed now (``FOLLOWED``), and kept for
        its echo should its bus loop it back (``_echo``). While frames wait for the PROFILE
        page (``host.judge.liverobot``) it waits with them, followed after those heard before
        it: followed now, its APPLY took effect after encoder frame -1 of judges then replaced
        (the reference adopted the next on-board pose, the pose set never checked, the kept
        check not made)."""
        if self.robot_wait is not None and self.robot_wait.held:
            self.robot_wait.held.append(SentFrame(can_id, data))
            return
        route = self._routes.get(can_id)
        if route is None or route.name not in COMMANDS:
            return
        with contextlib.suppress(DecodeError, KeyError, ValueError):
            signals = route.decode(data)
            self._unechoed.append((route.name, tuple(signals.values())))
            if route.name in FOLLOWED:
                self._own_frame = True
                try:
                    route.handler(self, signals, 0.0)
                finally:
                    self._own_frame = False

    def _echo(self, message: str, s: dict[str, Any]) -> bool:
        """Whether a command frame heard is the bridge's own sent frame come back: a bus whose
        observer hears its sends (the fleet's, SocketCAN's loopback to another socket) passes
        them on. Followed when sent, it is not a second sender's, nor staged twice; one echo
        per frame sent (another tool's frame of the very same bytes, which the firmware drops
        as a duplicate, is taken as the echo: harmless)."""
        if self._own_frame:
            return False
        try:
            self._unechoed.remove((message, tuple(s.values())))
        except ValueError:
            return False
        return True

    def _followed_set_pose(self, s: dict[str, Any], t_s: float) -> None:
        """ODOM_ACK of an ODOM_SET_POSE frame: an applied APPLY restarts the reference at
        the set pose (``host.judge.livesetpose``), a ``set_pose`` event in ``status``."""
        applied = self.set_pose.on_ack(int(s["REQUEST_COUNTER"]), int(s["RESULT"]) == 0, t_s)
        if applied is not None and self.set_pose.doubtful:  # two senders: which pose unknown
            pose = apply_set_pose(self.tracker, *applied, doubt=TWO_SENDERS_SET_POSE)
            self.events.append(set_pose_event(t_s, pose, {}))
        elif applied is not None:
            event = set_pose_event(t_s, apply_set_pose(self.tracker, *applied), applied[1])
            self.events.append(self.kept.applied(event, *applied, self.tracker.enc_seq))
            self._apply_choice = ApplyChoice.after_ack(self.tracker, *applied, event)

    def _on_ack(self, s: dict[str, Any], t_s: float) -> list[Publication]:
        request_id = int(s["REQUEST_ID"])
        if request_id == self._set_pose_id:
            self._followed_set_pose(s, t_s)
        elif request_id == self._config_id:
            self._followed_config(s, t_s)
        return self._answered(s, t_s)

    def _followed_config(self, s: dict[str, Any], t_s: float) -> None:
        """ODOM_ACK of an ODOM_CONFIG frame: an applied APPLY makes the staged set the judges'
        robot; one two senders left in doubt waits for the PROFILE page (liveconfigdoubt)."""
        before = (self.tracker.geometry, self.distance.robot.counter_bits,
                  self.tracker.integrator)
        if follow_config_ack(self, self.config, int(s["REQUEST_COUNTER"]),
                             int(s["RESULT"]) == 0, t_s, int(s["REQUEST_FIELD"])):
            self.profile.forget()  # the firmware's next PROFILE page is judged against it
            self.config_doubt = doubt_config(self, self.config, before, t_s)

    def on_profile_page(self, s: dict[str, Any], t_s: float) -> None:
        """An accepted PROFILE page: it settles a config in doubt first, then it is judged."""
        if self.config_doubt is not None:
            settle_config(self, self.config_doubt, s, t_s)
            self.config_doubt = None
        self.profile.on_page(self, s, t_s)

    def _answered(self, s: dict[str, Any], t_s: float) -> list[Publication]:
        """ODOM_ACK of a command the bridge sent: its ``cmd/result``."""
        key = (int(s["REQUEST_ID"]), int(s["REQUEST_COUNTER"]))
        pending = self.pending.pop(key, None)
        if pending is None:
            return []
        nack = int(s["RESULT"]) != 0
        if not nack and not pending.final:
            return []
        if nack:  # forget the rest of this command: one answer per command
            self.pending = {k: p for k, p in self.pending.items() if p.cmd_id != pending.cmd_id}
        reason = choice(self.db, "ODOM_ACK", "REASON", int(s["REASON"]))
        result = "nacked" if nack else "acked"
        unanswered = self._unanswered(pending)
        if unanswered:
            final = self._field(key[0], pending.data) or "last frame"
            result, reason = "unanswered", unanswered_reason(final, unanswered)
        contested = self.contested.pop(pending.cmd_id, None)
        if contested is not None:
            result, reason = "contested", contested_reason(contested, reason, nack)
        payload = {"id": pending.cmd_id, "command": pending.command,
                   "result": result, "reason": reason, "t_s": t_s}
        return [(RESULT_LEAF, stamp(payload))]

    def _unanswered(self, final: PendingAck) -> list[str]:
        """The frames of ``final``'s command still waiting for their ODOM_ACK when its final
        frame's ACK came (the firmware answers in bus order: these never will; it applied
        without them), named ``ODOM_CONFIG WHEELBASE (COUNTER 3)``, and forgotten."""
        if final.origin is None:
            return []
        keys = [k for k, p in self.pending.items() if p.origin is final.origin]
        names = [self._frame_name(k, self.pending.pop(k).data) for k in keys]
        return names

    def _frame_name(self, key: tuple[int, int], data: bytes) -> str:
        """A command frame's message and multiplexer value, by the DBC's names."""
        field = self._field(key[0], data)
        name = self.db.get_message_by_frame_id(key[0]).name
        return f"{name}{' ' + field if field else ''} (COUNTER {key[1]})"

    def _field(self, can_id: int, data: bytes) -> str:
        """A command frame's PARAM or FIELD by its DBC name ('' when it does not decode)."""
        with contextlib.suppress(DecodeError, KeyError, ValueError):
            decoded = self.db.get_message_by_frame_id(can_id).decode(data, decode_choices=True)
            if isinstance(decoded, dict):
                return next((str(decoded[m]) for m in ("PARAM", "FIELD") if m in decoded), "")
        return ""

    def expect_ack(self, can_id: int, counter: int, ack: PendingAck) -> None:
        """A command frame was sent: its ODOM_ACK will answer the command."""
        self.pending[(can_id, counter)] = ack


def contested_reason(detail: str, reason: str, nack: bool) -> str:
    """``cmd/result``'s reason of a ``contested`` command: why its answer proves nothing."""
    heard = f"ODOM_ACK {'NACK' if nack else 'ACK'} {reason}"
    return (f"{detail}: the firmware's {heard} for its last frame's COUNTER may answer the "
            "other tool's frame (a second frame of one COUNTER is dropped unanswered), and "
            "the staged set may mix both: not known to be applied as sent (the firmware's "
            "PROFILE page tells what it runs)")


def unanswered_reason(final: str, frames: list[str]) -> str:
    """``cmd/result``'s reason of an ``unanswered`` command: its ``final`` frame (APPLY, GO)
    ACKed, ``frames`` of it never answered (lost on the bus, or refused unanswered by the
    firmware's E2E check: the firmware committed without them; or their ACK was lost)."""
    return (f"ODOM_ACK ACK for its {final}, but its {', '.join(frames)} "
            f"{'was' if len(frames) == 1 else 'were'} never answered: not known to be applied "
            "as sent (the firmware commits what it staged, without a frame it never took)")
