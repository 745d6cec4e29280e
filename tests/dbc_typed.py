"""cantools' loose types narrowed once, at the tests' boundary.

``cantools.database.load_file`` returns a CAN or a diagnostics database, ``decode_message`` a
signal dict or, for a container message, a list of them, and a DBC attribute's value may be a
string or a number. Each helper below asserts the one case a test relies on, so a surprise fails
the test where it enters instead of somewhere downstream.
"""

from __future__ import annotations

from pathlib import Path

import cantools
from cantools.database.can import Database, Message
from cantools.database.namedsignalvalue import NamedSignalValue

SignalValue = int | float | str | NamedSignalValue


def load_can_dbc(path: Path | str, *, strict: bool = True) -> Database:
    """A fresh CAN database from the DBC at ``path`` (not cached: a test may change it)."""
    db = cantools.database.load_file(path, strict=strict)
    assert isinstance(db, Database), f"{path}: not a CAN database"
    return db


def decode(
    db: Database,
    frame: int | str,
    data: bytes | bytearray,
    *,
    decode_choices: bool = True,
    scaling: bool = True,
) -> dict[str, SignalValue]:
    """The signals of one frame (by ID or name; never a container message in our DBC)."""
    signals = db.decode_message(frame, bytes(data), decode_choices=decode_choices, scaling=scaling)
    assert isinstance(signals, dict), f"{frame}: a container message"
    return signals


def number(value: SignalValue) -> int | float:
    """A decoded signal that must be a number (no choice name)."""
    assert isinstance(value, int | float), value
    return value


def numbers(
    db: Database, frame: int | str, data: bytes | bytearray, *, scaling: bool = True
) -> dict[str, int | float]:
    """The signals of one frame as numbers (choices not decoded)."""
    signals = decode(db, frame, data, decode_choices=False, scaling=scaling)
    return {name: number(value) for name, value in signals.items()}


def dbc_attribute(message: Message, name: str) -> str:
    """A message's string attribute in the DBC (e.g. ``E2EDataIDs``)."""
    assert message.dbc is not None, message.name
    value = message.dbc.attributes[name].value
    assert isinstance(value, str), (message.name, name, value)
    return value


def choices(db: Database, message: str, signal: str) -> dict[int, str]:
    """The VAL_ table of ``signal`` as {raw value: name}."""
    table = db.get_message_by_name(message).get_signal_by_name(signal).choices
    assert table is not None, f"{message}.{signal} has no VAL_ table"
    return {raw: str(name) for raw, name in table.items()}


def integers(message: Message, data: bytes | bytearray, scaling: bool = True) -> dict[str, int]:
    """One frame of ``message`` decoded (scaled unless not ``scaling``, choices not decoded),
    every signal an integer."""
    signals = message.decode(bytes(data), decode_choices=False, scaling=scaling)
    assert isinstance(signals, dict), f"{message.name}: a container message"
    out: dict[str, int] = {}
    for name, value in signals.items():
        assert isinstance(value, int), (message.name, name, value)
        out[name] = value
    return out
