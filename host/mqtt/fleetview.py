"""A fleet table's data source: subscribe to every robot's telemetry, yield per-robot state.

For ``odocan monitor --mqtt`` (or any dashboard)::

    async for table in fleet_states(broker=BrokerURL.parse("mqtt://127.0.0.1:1883")):
        for name, state in sorted(table.items()):
            print(name, state.online, state.pose.get("x_m"), state.rates.get("hz"))

Each iteration yields the whole table (robot name -> ``RobotState``) after at most
``min_interval_s`` of updates; it ends when the connection drops (aiomqtt.MqttError).
"""

from __future__ import annotations

import json
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

import aiomqtt
from cantools.database.can import Database

from odocan.host.jsonutil import real
from odocan.host.judge.monitor import error_names, shown_value
from odocan.host.mqtt import topics
from odocan.host.mqtt.broker import BrokerURL
from odocan.sim.contract import database


@dataclass
class RobotState:
    """The latest payload of each of a robot's topics (empty dicts until one arrives)."""

    name: str
    status: dict[str, Any] = field(default_factory=dict)
    pose: dict[str, Any] = field(default_factory=dict)
    reference: dict[str, Any] = field(default_factory=dict)
    truth: dict[str, Any] = field(default_factory=dict)
    error: dict[str, Any] = field(default_factory=dict)
    rates: dict[str, Any] = field(default_factory=dict)
    last_result: dict[str, Any] = field(default_factory=dict)
    updated_unix_s: float = 0.0

    @property
    def online(self) -> bool:
        """True while the retained status says ``online``."""
        return self.status.get("state") == "online"


MAX_TELEMETRY_BYTES = 64 * 1024  # a telemetry payload, at most (a rates payload: ~2 kB)
_LEAF_FIELD = {"status": "status", "pose": "pose", "reference": "reference", "truth": "truth",
               "error": "error", "rates": "rates", topics.RESULT_LEAF: "last_result"}


def apply(
    table: dict[str, RobotState], topic_name: str, payload: bytes, *, retained: bool = False
) -> bool:
    """Fold one message into ``table``; False when it is not a robot topic or not JSON (of at
    most ``MAX_TELEMETRY_BYTES``, nested no deeper than Python's JSON parser goes).

    A live message updates the robot now. A ``retained`` one (the broker's copy, sent to a new
    subscriber) is as old as its payload's ``unix_s`` says (the publisher's wall clock, s), or of
    unknown age (the robot's ``updated_unix_s`` is left as it was): a robot gone for an hour
    must not look alive because its last status is still on the broker."""
    split = topics.split(topic_name)
    if split is None or split[1] not in _LEAF_FIELD or len(payload) > MAX_TELEMETRY_BYTES:
        return False
    try:
        data = json.loads(payload)
    except (ValueError, RecursionError):  # RecursionError: '[' nested thousands deep
        return False
    if not isinstance(data, dict):
        return False
    state = table.setdefault(split[0], RobotState(split[0]))
    setattr(state, _LEAF_FIELD[split[1]], data)
    now_unix_s = time.time()
    if not retained:
        state.updated_unix_s = now_unix_s
    else:
        sent_unix_s = _published_unix_s(data, now_unix_s)
        if sent_unix_s is not None:
            state.updated_unix_s = max(state.updated_unix_s, sent_unix_s)
    return True


def _published_unix_s(data: dict[str, Any], now_unix_s: float) -> float | None:
    """The payload's ``unix_s`` (s since the epoch, at most ``now_unix_s``), None if absent
    or not a finite number."""
    sent = real(data.get("unix_s"))
    return None if sent is None else min(sent, now_unix_s)


async def fleet_states(
    *, broker: BrokerURL, min_interval_s: float = 0.2, identifier: str | None = None
) -> AsyncIterator[dict[str, RobotState]]:
    """Subscribe to ``odocan/+/#`` and yield the table at most every ``min_interval_s``: first
    once subscribed (empty: the broker answered, no robot has published yet), then as messages
    come."""
    table: dict[str, RobotState] = {}
    async with aiomqtt.Client(**broker.client_kwargs(), identifier=identifier) as client:
        await client.subscribe(f"{topics.PREFIX}/+/#", qos=topics.QOS_RELIABLE)
        yield table
        last = 0.0
        async for message in client.messages:
            payload = message.payload
            if not isinstance(payload, bytes | bytearray):
                continue
            if apply(table, message.topic.value, bytes(payload), retained=message.retain):
                now = time.monotonic()
                if now - last >= min_interval_s:
                    last = now
                    yield table


# --- the fleet table's rows (monitor --mqtt, its --json) ----------------------------------


def fleet_snapshot(table: dict[str, RobotState], db: Database | None = None) -> dict[str, Any]:
    """Per robot: online, pose, error vs reference, firmware status, the bridge's judgement of
    the pose (``_pose_judged``), frame rates."""
    db = db if db is not None else database()
    return {name: _robot_row(table[name], db) for name in sorted(table)}


def _robot_row(state: RobotState, db: Database) -> dict[str, Any]:
    hz = _rates_hz(state.rates)
    keys = ("x_m", "y_m", "heading_rad", "heading_unwrapped_rad")
    pose = {k: state.pose.get(k) for k in keys} if state.pose else None
    return {
        "online": state.online,
        "pose": pose,
        "error": state.error.get("pose_vs_reference"),
        "status": _firmware_row(state.status, db),
        **_pose_judged(state),
        "rate_hz": round(sum(hz.values()), 3) if hz else None,
        "encoder_hz": hz.get("WHEEL_ENCODERS"),
        "updated_unix_s": state.updated_unix_s,
    }


def _pose_judged(state: RobotState) -> dict[str, Any]:
    """What the robot's bridge judged of its pose (issue #11): ``this_life`` (the retained
    status's ``pose_wrongs.this_life``: the episodes of the pose's current life, there while an
    offset stands), ``since_last`` (the latest ``error``'s worst sample since the one before,
    there when one was wrong), each None when absent or no JSON object; ``pose_wrong``: either,
    or the latest ``error``'s own ``pose_wrong`` (the screen's state: never OK then)."""
    wrongs = state.status.get("pose_wrongs")
    this_life = wrongs.get("this_life") if isinstance(wrongs, dict) else None
    this_life = this_life if isinstance(this_life, dict) else None
    since_last = state.error.get("since_last")
    since_last = since_last if isinstance(since_last, dict) else None
    latest = state.error.get("pose_wrong") is True
    return {"pose_wrong": latest or this_life is not None or since_last is not None,
            "this_life": this_life, "since_last": since_last}


def _firmware_row(status: dict[str, Any], db: Database) -> dict[str, Any] | None:
    """The firmware's summary in a retained status; None when there is none or it is not one
    a bridge publishes (a status from anyone allowed to publish must not stop the monitor)."""
    firmware = status.get("firmware")
    summary = firmware.get("summary") if isinstance(firmware, dict) else None
    if not isinstance(summary, dict) or not summary:
        return None
    mask = summary.get("error_mask", 0)
    if not isinstance(mask, int) or not 0 <= mask < 1 << 32:
        return None
    status_msg = db.get_message_by_name("ODOM_STATUS")
    try:
        row = {"state": shown_value(status_msg, "STATE", summary.get("state", 0)),
               "integrator": shown_value(status_msg, "INTEGRATOR", summary.get("integrator", 0)),
               "error_mask": mask, "errors": error_names(mask),
               "uptime_s": summary.get("uptime")}
    except (TypeError, ValueError, OverflowError):  # an enum that is no number nor name
        return None
    return _silence(row, status.get("firmware_heard"))


def _silence(row: dict[str, Any], heard: Any) -> dict[str, Any]:
    """``row`` with the firmware's age (``host.mqtt.firmwareheard``): a firmware silent past its
    timeout is ``STALE``, not the state its last summary said (``reported_state``), so a dead
    firmware behind a live bridge never shows OK; ``firmware_age_s`` None when unknown."""
    if not isinstance(heard, dict):
        return row
    age_s = real(heard.get("age_s"))
    row = {**row, "firmware_age_s": age_s}
    if heard.get("stale") is True:
        row.update(state="STALE", reported_state=row["state"])
    return row


def _rates_hz(rates: dict[str, Any]) -> dict[str, float]:
    """The per-message rates of a rates payload that are finite numbers."""
    hz = rates.get("hz")
    if not isinstance(hz, dict):
        return {}
    return {name: rate for name, v in hz.items() if (rate := real(v)) is not None}
