"""How ``odocan monitor`` shows what it heard (``host.judge.monitor``): a frame's multiplexer
page, a message's staleness, signal values by their enum names and units, ERROR_MASK bits by
name, each sending node's age, the snapshot as JSON."""

from __future__ import annotations

import json
import math
from collections import Counter
from typing import TYPE_CHECKING, Any

from cantools.database.can import Database, Message

from odocan.firmware.errors import ErrorFlag
from odocan.host.jsonutil import finite

if TYPE_CHECKING:
    from odocan.host.judge.messagestats import MessageStats

NODE_TIMEOUT_CYCLES = 10  # a node is stale after 10 x its fastest cycle time (opendbc)


def node_ages(db: Database, messages: dict[str, MessageStats], now_s: float
              ) -> dict[str, dict[str, Any]]:
    """Per sending node heard: ``age_s`` since its last cyclic message, ``timeout_s``
    (``NODE_TIMEOUT_CYCLES`` x the fastest cycle among its messages heard), ``stale``."""
    nodes: dict[str, dict[str, Any]] = {}
    for name, stats in messages.items():
        message = db.get_message_by_name(name)
        if message.send_type != "Cyclic" or not message.cycle_time or not message.senders:
            continue
        timeout_s = NODE_TIMEOUT_CYCLES * message.cycle_time / 1e3
        node = nodes.setdefault(message.senders[0], {"age_s": math.inf, "timeout_s": math.inf})
        node["age_s"] = min(node["age_s"], now_s - stats.heard_monotonic_s)
        node["timeout_s"] = min(node["timeout_s"], timeout_s)
    for node in nodes.values():
        node["stale"] = node["age_s"] > node["timeout_s"]
    return nodes


def count_unknown_id(ids: Counter[str], can_id: int, most: int) -> None:
    """Count a frame of an identifier the DBC does not know (at most ``most`` distinct)."""
    key = f"0x{can_id:03X}"
    if key in ids or len(ids) < most:
        ids[key] += 1


def page_of(message: Message, data: bytes) -> str | None:
    """The multiplexer value of a frame of a multiplexed message (its enum name when it has
    one), read from the payload before any decoding; None for a plain message."""
    if not message.is_multiplexed():
        return None
    mux = next((s for s in message.signals if s.is_multiplexer), None)
    if mux is None or mux.byte_order != "little_endian":
        return None
    value = (int.from_bytes(data, "little") >> mux.start) & ((1 << mux.length) - 1)
    choices: dict[Any, Any] = dict(mux.choices or {})
    return str(choices[value]) if value in choices else str(value)


def message_stale(message: Message, age_s: float) -> bool:
    """Not heard for ``NODE_TIMEOUT_CYCLES`` cycles (event messages never go stale)."""
    cycle_ms = message.cycle_time
    return cycle_ms is not None and cycle_ms > 0 and age_s > NODE_TIMEOUT_CYCLES * cycle_ms / 1e3


def to_json(snapshot: dict[str, Any]) -> str:
    """Indented JSON of a snapshot; non-finite floats become null (JSON has no NaN)."""
    return json.dumps(finite(snapshot), indent=2, default=str)


def error_names(mask: int) -> list[str]:
    """The ``ErrorFlag`` names of the bits set in ``mask`` (``BIT<n>`` for an unnamed bit)."""
    named = {int(flag).bit_length() - 1: str(flag.name) for flag in ErrorFlag if flag}
    return [named.get(bit, f"BIT{bit}") for bit in range(mask.bit_length()) if mask >> bit & 1]


def shown_value(message: Message, name: str, value: Any) -> Any:
    """A signal's value as shown: the enum name when it has one, else the number."""
    choices = message.get_signal_by_name(name).choices
    if isinstance(value, str):  # already the name (the bridge publishes enums by name)
        return value
    if choices and int(value) in choices:
        return str(choices[int(value)])
    return value


def unit_of(message: Message, name: str) -> str:
    unit = message.get_signal_by_name(name).unit
    return "" if unit in (None, "-") else str(unit)


def messages_snapshot(db: Database, messages: dict[str, MessageStats], e2e: dict[str, Any],
                      now_s: float) -> dict[str, dict[str, Any]]:
    """The ``messages`` section of the monitor's snapshot, by CAN ID: per message heard its
    count, rate, jitter (a multiplexed one's per page), E2E counts (``e2e``: by name), age and
    staleness at local time ``now_s``, latest values and units."""
    shown = {}
    for name in sorted(messages, key=lambda n: messages[n].frame_id):
        stats = messages[name]
        message = db.get_message_by_name(name)
        shown[name] = {
            "id": f"0x{stats.frame_id:03X}",
            "count": stats.count,
            "rate_hz": stats.rate_hz(),
            "jitter_ms": None if stats.pages else stats.jitter_ms(),
            "e2e": e2e.get(name, {}),
            "age_s": now_s - stats.heard_monotonic_s,
            "stale": message_stale(message, now_s - stats.heard_monotonic_s),
            "last": dict(stats.last),
            "units": {sig: unit_of(message, sig) for sig in stats.last},
        }
        if message.is_multiplexed():  # the latest page alone
            shown[name]["last_frame"] = dict(stats.last_frame)
            shown[name]["pages"] = {k: v.timing() for k, v in stats.pages.items()}
    return shown
