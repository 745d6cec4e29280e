"""Enum values by their DBC names for the bridge's payloads (``host.mqtt.telemetry``): the
``status`` fields, ``cmd/result``'s reasons and ODOM_SET_POSE's FIELD say ``"OK"``, not 1."""

from __future__ import annotations

from typing import Any

from cantools.database.can import Database, Signal


def named_value(choices: Any, value: Any) -> Any:
    """An enum signal's value by its DBC name (``"OK"``, not 1; ``choices``: the signal's);
    other values as they are."""
    if choices and int(value) in choices:
        return str(choices[int(value)])
    return value


def choice(db: Database, message: str, signal: str, value: int) -> str:
    """``value`` of ``message``'s ``signal`` by its DBC name (the number when it has none)."""
    choices = db.get_message_by_name(message).get_signal_by_name(signal).choices
    return str(choices.get(value, value)) if choices else str(value)


def page_name(db: Database, page: int) -> str:
    """ODOM_STATUS page ``page``'s name, lower case (``e2e_wheel_encoders``)."""
    return choice(db, "ODOM_STATUS", "PAGE", page).lower()


def signal_value(signal: Signal, value: Any) -> Any:
    """A signal's value in a payload: an enum by its DBC name (``named_value``), a CRC
    (``*_CRC``: PROFILE_CRC) as ``0x`` and its hex digits, the one form ``status.profile``'s
    ``profile_crc`` has too (``int(text, 16)`` is the DBC's integer), others as they are."""
    if signal.name.endswith("_CRC"):
        return f"0x{int(value):0{(signal.length + 3) // 4}X}"
    return named_value(signal.choices, value)
