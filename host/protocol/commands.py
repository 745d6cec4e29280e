"""MQTT commands -> E2E-protected CAN frames, validated against a schema and the DBC first.

A command is a JSON object on ``odocan/<robot>/cmd/<name>``; ``"id"`` (string or integer,
optional) is echoed in the answer on ``cmd/result``; ``"sent_unix_s"`` (number, optional: when
the sender sent it, UNIX seconds of its wall clock, as a ROS 2 ``header.stamp``) lets the bridge
refuse a command that waited too long anywhere on its way (``command_sent_unix_s``; the link's
expiry rule, ``host.mqtt.link``). A JSON ``null`` for an optional key is its absence (as most
clients write an unset one). Every key is checked (no unknown keys, no missing required ones,
the right JSON type), then every value against its signal's range in the DBC (``[min|max]`` in
the signal's unit, the key's unit). Only when the whole command is valid are its
frames built (cantools ``encode``, strict; Profile 2 CRC by ``cantools.autosar`` with the
message's ``E2EDataIDs``) and handed back; otherwise ``CommandRejected`` carries the reason and
nothing is sent.

=========  ==============  =================================================================
command    message         keys (unit in the name)
=========  ==============  =================================================================
set_pose   ODOM_SET_POSE   x_m, y_m, heading_rad -> frames X, Y, HEADING, APPLY
config     ODOM_CONFIG     counts_per_rev, wheel_radius_left_m, wheel_radius_right_m,
                           wheelbase_m, counter_bits (16|32), integrator (euler|rk2|exact),
                           [max_wheel_speed_m_s] -> one frame per parameter, then APPLY
nav_goal   NAV_GOAL        x_m, y_m, [heading_rad], [mode], [append], [goal_id]
                           -> X, Y, [HEADING], GO (NO_FINAL_HEADING when no heading_rad)
=========  ==============  =================================================================

Headings are angles: any finite value is wrapped to [0, 2 pi) before the range check, if float64
can place it within half the signal's LSB (|heading| <= scale * 2^51, ~2.2e11 rad for HEADING).
A DBC without the message (or one of its signals) rejects with "unsupported by this DBC".
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final, Literal

import cantools
import cantools.autosar
from cantools.database.can import Database, Message, Signal

from odocan.sim.contract import database

MAX_COMMAND_BYTES: Final = 4096  # a command's JSON payload, at most
MAX_ID_CHARS: Final = 64  # a string id, at most
MAX_ABS_INT_ID: Final = 2**63 - 1  # an integer id fits an int64 (every JSON peer can read it back)
MAX_ABS_NUMBER: Final = 1e300  # an integer value beyond this is out of every signal's range
SENT_KEY: Final = "sent_unix_s"  # optional in every command: its send time (UNIX s)
MAX_SENT_AHEAD_S: Final = 86_400.0  # a sent_unix_s this far ahead of our clock is not seconds

Kind = Literal["float", "angle", "int", "enum", "bool", "absent"]
_TURN = 2.0 * math.pi


class CommandRejected(Exception):
    """A command that may not reach the bus; ``reason`` says why (one line)."""

    def __init__(self, reason: str, cmd_id: Any = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.cmd_id = cmd_id


@dataclass(frozen=True)
class Field:
    """One JSON key -> one signal. ``absent``: the signal is 1 when ``key`` is missing."""

    key: str
    signal: str
    kind: Kind
    required: bool = True
    default: Any = None


@dataclass(frozen=True)
class Step:
    """One frame: the multiplexer value (a VAL_ name) and its fields; skipped without ``when``."""

    mux: str
    fields: tuple[Field, ...] = ()
    when: str | None = None  # the step is sent only when this key is present


@dataclass(frozen=True)
class CommandSpec:
    """A command: its message, multiplexer signal and frames in order (the last one commits)."""

    name: str
    message: str
    mux_signal: str
    steps: tuple[Step, ...]

    @property
    def keys(self) -> frozenset[str]:
        """Every key the command accepts (besides ``id``)."""
        return frozenset(f.key for s in self.steps for f in s.fields)


def _one(mux: str, key: str, signal: str, kind: Kind) -> Step:
    return Step(mux, (Field(key, signal, kind),))


SPECS: Final[dict[str, CommandSpec]] = {
    "set_pose": CommandSpec("set_pose", "ODOM_SET_POSE", "FIELD", (
        _one("X", "x_m", "X", "float"),
        _one("Y", "y_m", "Y", "float"),
        _one("HEADING", "heading_rad", "HEADING", "angle"),
        Step("APPLY"),
    )),
    "config": CommandSpec("config", "ODOM_CONFIG", "PARAM", (
        _one("COUNTS_PER_REV", "counts_per_rev", "COUNTS_PER_REV", "int"),
        _one("WHEEL_RADIUS_LEFT", "wheel_radius_left_m", "WHEEL_RADIUS_LEFT", "float"),
        _one("WHEEL_RADIUS_RIGHT", "wheel_radius_right_m", "WHEEL_RADIUS_RIGHT", "float"),
        _one("WHEELBASE", "wheelbase_m", "WHEELBASE", "float"),
        _one("COUNTER_BITS", "counter_bits", "COUNTER_BITS", "int"),
        _one("INTEGRATOR", "integrator", "INTEGRATOR", "enum"),
        Step("MAX_WHEEL_SPEED", (Field("max_wheel_speed_m_s", "MAX_WHEEL_SPEED", "float",
                                       required=False),), when="max_wheel_speed_m_s"),
        Step("APPLY"),
    )),
    "nav_goal": CommandSpec("nav_goal", "NAV_GOAL", "FIELD", (
        _one("X", "x_m", "X", "float"),
        _one("Y", "y_m", "Y", "float"),
        Step("HEADING", (Field("heading_rad", "HEADING", "angle", required=False),),
             when="heading_rad"),
        Step("GO", (
            Field("mode", "MODE", "enum", required=False, default="GO_TO_GOAL"),
            Field("append", "APPEND", "bool", required=False, default=False),
            Field("goal_id", "GOAL_ID", "int", required=False, default=0),
            Field("heading_rad", "NO_FINAL_HEADING", "absent", required=False),
        )),
    )),
}


@dataclass(frozen=True)
class Frame:
    """One frame to send: CAN ID, 8 data bytes, its E2E COUNTER, True for the committing frame."""

    can_id: int
    data: bytes
    counter: int
    final: bool


@dataclass(frozen=True)
class Command:
    """A validated command: its name, the caller's id, the values (SI units) and its frames."""

    name: str
    cmd_id: Any
    values: dict[str, Any]
    frames: tuple[Frame, ...]


class CommandEncoder:
    """Validates commands and builds their frames; one per robot (it owns the E2E counters)."""

    def __init__(self, db: Database | None = None) -> None:
        self.db = db if db is not None else database()
        self._counters: dict[int, int] = {}

    def encode(self, name: str, payload: bytes) -> Command:
        """``payload`` of ``cmd/<name>`` -> its frames; ``CommandRejected`` with the reason (and
        the payload's id, whenever it has a valid one, for the answer on ``cmd/result``)."""
        try:
            spec = _spec(name)
        except CommandRejected as exc:
            exc.cmd_id = command_id(payload)
            raise
        obj = _parse(payload)
        cmd_id = obj.pop("id", None)
        if cmd_id is not None and not _valid_id(cmd_id):
            raise CommandRejected(
                f"id must be a string of at most {MAX_ID_CHARS} characters or an integer "
                "within int64"
            )
        sent = obj.pop(SENT_KEY, None)  # null: absent, as a JSON null for "id"
        if sent is not None:  # judged by the link before the command came here
            try:
                _check_sent(sent)
            except CommandRejected as exc:
                exc.cmd_id = cmd_id
                raise
        return self._build(spec, obj, cmd_id)

    def build(self, name: str, values: Mapping[str, Any]) -> Command:
        """The frames of command ``name`` with ``values`` (the keys of its JSON object, already
        Python values: no JSON in between), checked exactly as ``encode`` checks a payload;
        ``CommandRejected`` with the reason."""
        return self._build(_spec(name), dict(values), None)

    def _build(self, spec: CommandSpec, obj: dict[str, Any], cmd_id: Any) -> Command:
        try:
            values = _check_schema(spec, obj)
            message = self._message(spec)
            raw_frames = [self._raw(message, spec, step, values)
                          for step in spec.steps if step.when is None or step.when in values]
        except CommandRejected as exc:
            exc.cmd_id = cmd_id
            raise
        frames = tuple(self._frame(message, raw, i == len(raw_frames) - 1)
                       for i, raw in enumerate(raw_frames))
        return Command(spec.name, cmd_id, values, frames)

    def _message(self, spec: CommandSpec) -> Message:
        try:
            message = self.db.get_message_by_name(spec.message)
        except KeyError:
            raise CommandRejected(f"unsupported by this DBC (no message {spec.message})") from None
        names = {s.name for s in message.signals}
        needed = {spec.mux_signal} | {f.signal for s in spec.steps for f in s.fields}
        missing = sorted(needed - names)
        if missing:
            raise CommandRejected(
                f"unsupported by this DBC ({spec.message} lacks {', '.join(missing)})"
            )
        if _data_ids(message) is None:
            raise CommandRejected(f"unsupported by this DBC ({spec.message} has no E2EDataIDs)")
        return message

    def _raw(
        self, message: Message, spec: CommandSpec, step: Step, values: dict[str, Any]
    ) -> dict[str, int]:
        mux_signal = message.get_signal_by_name(spec.mux_signal)
        raw = {spec.mux_signal: _choice_value(mux_signal, step.mux, spec.message)}
        for f in step.fields:
            signal = message.get_signal_by_name(f.signal)
            if f.kind == "absent":
                raw[f.signal] = int(f.key not in values)
            else:
                raw[f.signal] = _to_raw(signal, f, values.get(f.key, f.default), spec.message)
        return raw

    def _frame(self, message: Message, raw: dict[str, int], final: bool) -> Frame:
        counter = (self._counters.get(message.frame_id, -1) + 1) % _counter_lap(message)
        self._counters[message.frame_id] = counter
        data_ids = _data_ids(message)
        assert data_ids is not None  # checked by _message
        encoded = message.encode(
            {**raw, "CHECKSUM": 0, "COUNTER": counter}, scaling=False, padding=False, strict=True
        )
        data = cantools.autosar.apply_profile2_crc(bytes(encoded), data_ids[counter])
        assert data is not None
        return Frame(message.frame_id, bytes(data), counter, final)


def _spec(name: str) -> CommandSpec:
    spec = SPECS.get(name)
    if spec is None:
        raise CommandRejected(f"unknown command {_short(name)!r} (known: {', '.join(SPECS)})")
    return spec


def command_id(payload: bytes) -> Any:
    """The ``"id"`` of a command that will not be run (expired, busy), None when there is no
    valid one; never raises (the same checks as ``encode``)."""
    try:
        obj = _parse(payload)
    except CommandRejected:
        return None
    cmd_id = obj.get("id")
    return cmd_id if cmd_id is not None and _valid_id(cmd_id) else None


def command_sent_unix_s(payload: bytes) -> float | None:
    """A command's ``sent_unix_s`` (its sender's wall clock, UNIX s), None when it has none or
    not a finite number (``encode`` then rejects it); never raises."""
    try:
        obj = _parse(payload)
    except CommandRejected:
        return None
    sent = obj.get(SENT_KEY)
    if isinstance(sent, bool) or not isinstance(sent, int | float) or \
            abs(sent) > MAX_ABS_NUMBER or not math.isfinite(sent):
        return None
    return float(sent)


def _check_sent(sent: Any) -> None:
    """``sent_unix_s`` is a number, and not a day or more ahead of this host's clock: such a
    stamp is in other units (JavaScript's ``Date.now()`` is ms: 1000 times the seconds), and
    counted as age 0 it would never expire. A stamp less ahead is a clock a little off."""
    _check_type(SENT_KEY, "float", sent)
    ahead_s = float(sent) - time.time()
    if ahead_s >= MAX_SENT_AHEAD_S:
        raise CommandRejected(
            f"{SENT_KEY} is {ahead_s:.3g} s ahead of this host's clock: not UNIX seconds? "
            "(in JavaScript: Date.now() / 1000)")


def _data_ids(message: Message) -> list[int] | None:
    """The message's E2EDataIDs attribute (a data ID per COUNTER value), None when absent or
    malformed."""
    attribute = message.dbc.attributes.get("E2EDataIDs") if message.dbc else None
    if attribute is None or not isinstance(attribute.value, str):
        return None
    ids = [int(v) for v in attribute.value.split(",") if v.strip().isdigit()]
    return ids if len(ids) == _counter_lap(message) else None


def _counter_lap(message: Message) -> int:
    """The values of the message's E2E COUNTER: 2 ** its bits in the DBC."""
    return 1 << int(message.get_signal_by_name("COUNTER").length)


def _parse(payload: bytes) -> dict[str, Any]:
    if len(payload) > MAX_COMMAND_BYTES:
        raise CommandRejected(f"payload too large ({len(payload)} > {MAX_COMMAND_BYTES} bytes)")
    try:
        obj = json.loads(payload)
    except RecursionError:
        raise CommandRejected("malformed JSON: nested too deeply") from None
    except ValueError as exc:  # UnicodeDecodeError and over-long integers included
        raise CommandRejected(f"malformed JSON: {_short(str(exc))}") from None
    if not isinstance(obj, dict):
        raise CommandRejected("payload must be a JSON object")
    return obj


def _short(text: str, limit: int = 80) -> str:
    """``text`` cut to ``limit`` characters (a reason stays one short line)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _valid_id(cmd_id: Any) -> bool:
    if isinstance(cmd_id, bool):
        return False
    if isinstance(cmd_id, int):
        return abs(cmd_id) <= MAX_ABS_INT_ID
    return isinstance(cmd_id, str) and len(cmd_id) <= MAX_ID_CHARS


def _check_schema(spec: CommandSpec, obj: dict[str, Any]) -> dict[str, Any]:
    """Keys and JSON types; returns the values given. A JSON null for an optional field is
    its absence (as most clients write an unset optional field); for a required one, wrong."""
    unknown = sorted(set(obj) - spec.keys)
    if unknown:
        raise CommandRejected(f"unknown field {_short(repr(unknown[0]), 40)} (accepted: id, "
                              f"{SENT_KEY}, "
                              f"{', '.join(sorted(spec.keys))})")
    fields = {f.key: f for s in spec.steps for f in s.fields if f.kind != "absent"}
    obj = {k: v for k, v in obj.items() if v is not None or (k in fields and fields[k].required)}
    for key, f in fields.items():
        if key not in obj:
            if f.required:
                raise CommandRejected(f"missing field {key!r}")
            continue
        _check_type(key, f.kind, obj[key])
    return dict(obj)


def _check_type(key: str, kind: Kind, value: Any) -> None:
    if kind in ("float", "angle"):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CommandRejected(f"{key} must be a number")
        if isinstance(value, int) and abs(value) > MAX_ABS_NUMBER:  # float() would overflow
            raise CommandRejected(f"{key} out of range ({len(str(abs(value)))}-digit integer)")
        if not math.isfinite(value):
            raise CommandRejected(f"{key} must be finite")
    elif kind == "int" and (isinstance(value, bool) or not isinstance(value, int)):
        raise CommandRejected(f"{key} must be an integer")
    elif kind == "bool" and not isinstance(value, bool):
        raise CommandRejected(f"{key} must be true or false")
    elif kind == "enum" and (isinstance(value, bool) or not isinstance(value, str | int)):
        raise CommandRejected(f"{key} must be a name or an integer")


def _check_angle_resolution(signal: Signal, key: str, value_rad: float) -> None:
    """An angle so large that float64 cannot place it within half the signal's LSB (its ulp
    beyond scale / 2: |value| > scale * 2^51) wraps to an arbitrary heading: rejected."""
    limit_rad = signal.scale * 2.0**51
    if abs(value_rad) > limit_rad:
        raise CommandRejected(f"{key}={_short(str(value_rad), 24)} too large to wrap to the "
                              f"signal's resolution (|{key}| <= {limit_rad:.3g} rad)")


def _to_raw(signal: Signal, f: Field, value: Any, message: str) -> int:
    """A checked JSON value -> the signal's raw integer, within the DBC's [min|max]."""
    if f.kind == "enum":
        return _choice_value(signal, value, message, key=f.key)
    if f.kind == "bool":
        value = int(value)
    if f.kind == "angle":
        _check_angle_resolution(signal, f.key, float(value))
        value = float(value) % _TURN
        raw: int = round(value / signal.scale) % (1 << signal.length)
        return raw
    lo, hi = signal.minimum, signal.maximum
    unit = f" {signal.unit}" if signal.unit and signal.unit != "-" else ""
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise CommandRejected(
            f"{f.key}={_short(str(value), 24)} out of range [{lo}, {hi}]{unit} "
            f"({message}.{signal.name} in the DBC)"
        )
    scaled: int = round((value - signal.offset) / signal.scale)
    return scaled


def _choice_value(signal: Signal, value: Any, message: str, *, key: str | None = None) -> int:
    """A VAL_ name (any case) or integer -> its value; rejected when the DBC has no such choice."""
    choices = {str(v).upper(): int(k) for k, v in (signal.choices or {}).items()}
    if isinstance(value, str) and value.upper() in choices:
        return choices[value.upper()]
    if isinstance(value, int) and value in choices.values():
        return value
    if key is None:  # a multiplexer value the spec needs
        raise CommandRejected(f"unsupported by this DBC ({message}.{signal.name} lacks {value})")
    names = ", ".join(sorted(n.lower() for n in choices))
    raise CommandRejected(f"{key}={_short(repr(value), 24)} is not one of {names}")
