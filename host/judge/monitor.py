"""The live view of a CAN bus (``odocan monitor``): the state model fed frame by frame (its
rendering is ``host.report.live`` and ``host.report.tui``).

``BusMonitor.feed(msg)`` takes every frame heard, in bus order, and never raises on what a bus
carries: frames of unknown IDs, of the wrong DLC, error and remote frames are counted (the
``unknown`` section of ``host.e2e.E2EMonitor``, plus the unknown IDs themselves), frames that
cantools cannot decode are counted as ``undecodable``. Per DBC message it keeps:

* ``count``, ``rate_hz`` and ``jitter_ms``: frames heard, and the rate and the standard deviation of
  the inter-frame period over the last ``RATE_WINDOW`` frames (bus timestamps, ``msg.timestamp``);
* ``e2e``: the Profile 2 counts (``ok``, ``lost``, ``repeated``, ``crc_errors``,
  ``wrong_sequence``), judged as the firmware judges them (``E2EMonitor``, time-widened window);
* ``last``: the latest value of every signal (physical units, enum names), from accepted frames
  only; a multiplexed message keeps the latest value of each page's signals (and
  ``last_frame``, the signals of its latest frame alone, is what the screen shows).

From the decoded frames it follows the firmware: ``status`` (ODOM_STATUS: STATE, INTEGRATOR,
ERROR_MASK with the bits named after ``firmware.errors.ErrorFlag``, UPTIME, frame totals) and the
pose (``PoseTracker``): the on-board pose (ODOM_POSE_X + ODOM_POSE_Y naming one encoder frame)
against a float64 ``ReferenceOdometry`` fed WHEEL_ENCODERS, compared at the very encoder frame the
pose names (ENC_COUNTER), and against SIM_TRUTH when the bus carries it.

``snapshot()`` is the whole model as JSON-ready data (``odocan monitor --json``);
``fleet_snapshot`` is the MQTT fleet's (``odocan monitor --mqtt``). ``render`` and
``render_fleet`` are re-exported from ``host.report.live``, where they now live.
"""

from __future__ import annotations

import json
import statistics
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import can
from cantools.database.can import Database, Message

from odocan.firmware.errors import ErrorFlag
from odocan.host.judge.reference import Geometry
from odocan.host.judge.tracking import PoseTracker
from odocan.host.mqtt.fleetview import RobotState
from odocan.host.protocol.decode import frame_key
from odocan.host.protocol.e2e import UNKNOWN, E2EMonitor
from odocan.host.report.jsonutil import finite
from odocan.sim.contract import database
from odocan.sim.robot import RobotProfile

RATE_WINDOW = 128  # frames per message for rate and jitter (1.28 s of WHEEL_ENCODERS)
STALE_S = 1.0  # a message not heard for this long is shown dimmed
ACCEPTED = frozenset({"ok", "oksomelost", "unprotected"})
MAX_UNKNOWN_IDS = 32  # distinct unknown identifiers listed (all are counted)
_HIDDEN = frozenset({"CHECKSUM", "COUNTER"})


@dataclass
class MessageStats:
    """What the monitor knows of one DBC message."""

    name: str
    frame_id: int
    count: int = 0
    times: deque[float] = field(default_factory=lambda: deque(maxlen=RATE_WINDOW))
    last: dict[str, Any] = field(default_factory=dict)  # every signal's latest value
    last_frame: dict[str, Any] = field(default_factory=dict)  # the latest frame's signals
    heard_monotonic_s: float = 0.0

    def heard(self, timestamp_s: float, now_s: float) -> None:
        """Count one frame of this message (bus timestamp, local monotonic time)."""
        self.count += 1
        self.times.append(timestamp_s)
        self.heard_monotonic_s = now_s

    def rate_hz(self) -> float | None:
        """Frames per second over the window (None before two frames)."""
        if len(self.times) < 2 or self.times[-1] <= self.times[0]:
            return None
        return (len(self.times) - 1) / (self.times[-1] - self.times[0])

    def jitter_ms(self) -> float | None:
        """Standard deviation of the inter-frame period over the window (ms)."""
        if len(self.times) < 3:
            return None
        return 1e3 * statistics.pstdev(b - a for a, b in pairwise(self.times))


class BusMonitor:
    """The state model of ``odocan monitor`` (see the module docstring)."""

    def __init__(
        self, robot: RobotProfile, integrator: str | None = None, db: Database | None = None
    ) -> None:
        self.db = db if db is not None else database()
        self._by_key = {frame_key(m.frame_id, m.is_extended_frame): m for m in self.db.messages}
        self.e2e = E2EMonitor(self.db)
        self.tracker = PoseTracker(Geometry.of(robot), robot.counter_bits, integrator)
        self.messages: dict[str, MessageStats] = {}
        self.unknown_ids: Counter[str] = Counter()
        self.status: dict[str, Any] = {}
        self.frames_total = 0
        self.undecodable = 0
        self.started_monotonic_s = time.monotonic()

    def feed(self, msg: can.Message, now_s: float | None = None) -> None:
        """One frame heard on the bus (``now_s``: local monotonic time, default now)."""
        now_s = time.monotonic() if now_s is None else now_s
        self.frames_total += 1
        if msg.is_error_frame or msg.is_remote_frame:
            self.e2e.count_frame_kind(error=msg.is_error_frame, remote=msg.is_remote_frame)
            return
        data = bytes(msg.data)
        timestamp_s = msg.timestamp
        status = self.e2e.check(msg.arbitration_id, data, extended=msg.is_extended_id,
                                timestamp_s=timestamp_s)
        message = self._by_key.get(frame_key(msg.arbitration_id, msg.is_extended_id))
        if message is None:
            self._count_unknown_id(msg.arbitration_id)
            return
        if len(data) != message.length:
            return  # counted by E2EMonitor as wrong_dlc
        stats = self.messages.get(message.name)
        if stats is None:
            stats = self.messages[message.name] = MessageStats(message.name, message.frame_id)
        stats.heard(timestamp_s, now_s)
        if status in ACCEPTED:
            self._use(message, stats, data)

    def _count_unknown_id(self, can_id: int) -> None:
        key = f"0x{can_id:03X}"
        if key in self.unknown_ids or len(self.unknown_ids) < MAX_UNKNOWN_IDS:
            self.unknown_ids[key] += 1

    def _use(self, message: Message, stats: MessageStats, data: bytes) -> None:
        """Decode an accepted frame, keep its values and follow the firmware."""
        try:
            signals = message.decode(data, decode_choices=False)
        except Exception:  # cantools: unknown multiplexer value, ... (never fatal)
            self.undecodable += 1
            return
        assert isinstance(signals, dict)
        shown = {name: _shown(message, name, value) for name, value in signals.items()
                 if name not in _HIDDEN}
        stats.last.update(shown)
        stats.last_frame = shown
        handler = _HANDLERS.get(message.name)
        if handler is not None:
            try:
                handler(self, signals, shown)
            except (KeyError, TypeError, ValueError):  # a --dbc without the signals it needs
                self.undecodable += 1

    def _on_encoders(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        self.tracker.on_encoders(int(s["COUNTER"]), int(s["LEFT_COUNT"]), int(s["RIGHT_COUNT"]))

    def _on_pose_x(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        self.tracker.on_pose_x(int(s["ENC_COUNTER"]), float(s["X"]), float(s["HEADING"]))

    def _on_pose_y(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        self.tracker.on_pose_y(int(s["ENC_COUNTER"]), float(s["Y"]), int(s["TURNS"]))

    def _on_truth(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        part = int(s["PART"])
        value = s.get({0: "X", 1: "Y", 2: "HEADING"}.get(part, ""))
        if value is not None:
            self.tracker.on_truth(part, int(s["ENC_COUNTER"]), float(value))

    def _on_status(self, s: dict[str, Any], shown: dict[str, Any]) -> None:
        page = str(shown.get("PAGE", s.get("PAGE")))
        if page == "SUMMARY":
            mask = int(s["ERROR_MASK"])
            self.status.update(
                state=shown["STATE"], integrator=shown["INTEGRATOR"], error_mask=mask,
                errors=error_names(mask), uptime_s=int(s["UPTIME"]),
            )
            integrator = str(shown["INTEGRATOR"]).lower()
            if integrator in ("euler", "rk2", "exact"):
                self.tracker.on_integrator(integrator)
        elif page == "FRAME_TOTALS":
            self.status.update({k.lower(): int(v) for k, v in s.items() if k.endswith("_FRAMES")})

    def snapshot(self) -> dict[str, Any]:
        """The whole model as JSON-ready data (``odocan monitor --json``)."""
        e2e = self.e2e.counts()
        messages = {}
        for name in sorted(self.messages, key=lambda n: self.messages[n].frame_id):
            stats = self.messages[name]
            message = self.db.get_message_by_name(name)
            messages[name] = {
                "id": f"0x{stats.frame_id:03X}",
                "count": stats.count,
                "rate_hz": stats.rate_hz(),
                "jitter_ms": stats.jitter_ms(),
                "e2e": e2e.get(name, {}),
                "last": dict(stats.last),
                "units": {sig: _unit(message, sig) for sig in stats.last},
            }
            if message.is_multiplexed():  # the latest page alone
                messages[name]["last_frame"] = dict(stats.last_frame)
        return {
            "duration_s": time.monotonic() - self.started_monotonic_s,
            "frames_total": self.frames_total,
            "messages": messages,
            "status": dict(self.status) or None,
            **self.tracker.snapshot(),
            "unknown": {**e2e[UNKNOWN], "ids": dict(self.unknown_ids),
                        "undecodable": self.undecodable},
        }


_HANDLERS = {
    "WHEEL_ENCODERS": BusMonitor._on_encoders,
    "ODOM_POSE_X": BusMonitor._on_pose_x,
    "ODOM_POSE_Y": BusMonitor._on_pose_y,
    "SIM_TRUTH": BusMonitor._on_truth,
    "ODOM_STATUS": BusMonitor._on_status,
}


def to_json(snapshot: dict[str, Any]) -> str:
    """Indented JSON of a snapshot; non-finite floats become null (JSON has no NaN)."""
    return json.dumps(finite(snapshot), indent=2, default=str)


def error_names(mask: int) -> list[str]:
    """The ``ErrorFlag`` names of the bits set in ``mask`` (``BIT<n>`` for an unnamed bit)."""
    named = {int(flag).bit_length() - 1: str(flag.name) for flag in ErrorFlag if flag}
    return [named.get(bit, f"BIT{bit}") for bit in range(mask.bit_length()) if mask >> bit & 1]


def _shown(message: Message, name: str, value: Any) -> Any:
    """A signal's value as shown: the enum name when it has one, else the number."""
    choices = message.get_signal_by_name(name).choices
    if choices and int(value) in choices:
        return str(choices[int(value)])
    return value


def _unit(message: Message, name: str) -> str:
    unit = message.get_signal_by_name(name).unit
    return "" if unit in (None, "-") else str(unit)


# --- the MQTT fleet -------------------------------------------------------------------------


def fleet_snapshot(table: dict[str, RobotState], db: Database | None = None) -> dict[str, Any]:
    """Per robot: online, pose, error vs reference, firmware status, frame rates."""
    db = db if db is not None else database()
    return {name: _robot_row(table[name], db) for name in sorted(table)}


def _robot_row(state: RobotState, db: Database) -> dict[str, Any]:
    summary = (state.status.get("firmware") or {}).get("summary") or {}
    status_msg = db.get_message_by_name("ODOM_STATUS")
    firmware = None
    if summary:
        mask = int(summary.get("error_mask", 0))
        firmware = {"state": _shown(status_msg, "STATE", summary.get("state", 0)),
                    "integrator": _shown(status_msg, "INTEGRATOR", summary.get("integrator", 0)),
                    "error_mask": mask, "errors": error_names(mask),
                    "uptime_s": summary.get("uptime")}
    hz = state.rates.get("hz") or {}
    pose = {k: state.pose.get(k) for k in ("x_m", "y_m", "heading_rad")} if state.pose else None
    return {
        "online": state.online,
        "pose": pose,
        "error": state.error.get("pose_vs_reference"),
        "status": firmware,
        "rate_hz": round(sum(hz.values()), 3) if hz else None,
        "encoder_hz": hz.get("WHEEL_ENCODERS"),
        "updated_unix_s": state.updated_unix_s,
    }


# Rendering lives in host.report.live; these names stay importable from here.
from odocan.host.report.live import render, render_fleet  # noqa: E402

__all__ = ["BusMonitor", "MessageStats", "error_names", "fleet_snapshot", "render",
           "render_fleet", "to_json"]
