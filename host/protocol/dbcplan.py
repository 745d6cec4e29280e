"""The DBC as the bulk judge reads it, without cantools at run time: a *plan* of plain data.

``odocan analyze`` needs of the DBC only each message's identifier, length, cycle time, send type
and attributes (``E2EDataIDs``) and each signal's layout, scale and value names. cantools parses
the DBC (the single source of truth) and ``plan_of`` copies exactly those fields into frozen
dataclasses that carry cantools' own attribute names, so the judge reads a ``DbcPlan`` and a
cantools ``Database`` alike (``DatabaseSpec``, a Protocol both satisfy).

``default_plan`` caches the plan as JSON on disk, keyed like cantools' own ``cache_dir`` by what
could change it: the SHA-256 of the DBC's bytes, this module's ``PLAN_FORMAT`` and the installed
cantools (its package file's path, size and modification time: an upgrade re-derives the plan).
A warm run then imports neither cantools nor python-can (about 0.1 s of CPU at start-up). An
edited DBC has another hash and is parsed again; a cache that cannot be read, does not parse, or
names another DBC is ignored and rewritten; a cache directory that cannot be written costs only
the speed. The directory is ``$ODOCAN_CACHE_DIR``, else ``$XDG_CACHE_HOME/odocan``, else
``~/.cache/odocan``.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import json
import os
from dataclasses import asdict, dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

PLAN_FORMAT = 1  # bump when the plan's fields change: older cache files are then ignored
CACHE_ENV = "ODOCAN_CACHE_DIR"


# --- what the judge reads of a DBC (cantools' names) ----------------------------------------
# (Protocols for mypy only: nothing checks them at run time, so they cost no start-up.)

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from typing import Protocol

    import cantools

    class AttributeSpec(Protocol):
        """A DBC attribute's value (cantools ``Attribute``)."""

        @property
        def value(self) -> Any: ...

    class DbcSpecificsSpec(Protocol):
        """A message's DBC attributes by name (cantools ``DbcSpecifics``)."""

        @property
        def attributes(self) -> Mapping[str, AttributeSpec]: ...

    class SignalSpec(Protocol):
        """One signal's layout, scale and value names (cantools ``Signal``)."""

        @property
        def name(self) -> str: ...
        @property
        def start(self) -> int: ...
        @property
        def length(self) -> int: ...
        @property
        def byte_order(self) -> str: ...
        @property
        def is_signed(self) -> bool: ...
        @property
        def is_float(self) -> bool: ...
        @property
        def scale(self) -> int | float: ...
        @property
        def offset(self) -> int | float: ...
        @property
        def multiplexer_signal(self) -> str | None: ...
        @property
        def multiplexer_ids(self) -> Sequence[int] | None: ...
        @property
        def is_multiplexer(self) -> bool: ...
        @property
        def choices(self) -> Mapping[int, object] | None: ...

    class MessageSpec(Protocol):
        """One message (cantools ``Message``): cycle time in ms, length in bytes."""

        @property
        def name(self) -> str: ...
        @property
        def frame_id(self) -> int: ...
        @property
        def is_extended_frame(self) -> bool: ...
        @property
        def length(self) -> int: ...
        @property
        def cycle_time(self) -> int | None: ...
        @property
        def send_type(self) -> str | None: ...
        @property
        def signals(self) -> Sequence[SignalSpec]: ...
        @property
        def dbc(self) -> DbcSpecificsSpec | None: ...

        def get_signal_by_name(self, name: str) -> SignalSpec: ...

    class DatabaseSpec(Protocol):
        """A DBC's messages (cantools ``Database``, or a ``DbcPlan``)."""

        @property
        def messages(self) -> Sequence[MessageSpec]: ...

        def get_message_by_name(self, name: str) -> MessageSpec: ...


# --- the plan: those fields as plain data -----------------------------------------------------


@dataclass(frozen=True)
class PlanAttribute:
    """A DBC attribute's value."""

    value: int | float | str


@dataclass(frozen=True)
class PlanDbcSpecifics:
    """A message's DBC attributes."""

    attributes: dict[str, PlanAttribute]


@dataclass(frozen=True)
class PlanSignal:
    """A signal as cantools parsed it (start bit in cantools' numbering, length in bits)."""

    name: str
    start: int
    length: int
    byte_order: str
    is_signed: bool
    is_float: bool
    scale: int | float
    offset: int | float
    multiplexer_signal: str | None
    multiplexer_ids: tuple[int, ...] | None
    is_multiplexer: bool
    choices: dict[int, str] | None  # raw value -> its name (VAL_)


@dataclass(frozen=True)
class PlanMessage:
    """A message as cantools parsed it (cycle time in ms, length in bytes)."""

    name: str
    frame_id: int
    is_extended_frame: bool
    length: int
    cycle_time: int | None
    send_type: str | None
    signals: tuple[PlanSignal, ...]
    dbc: PlanDbcSpecifics | None

    def get_signal_by_name(self, name: str) -> PlanSignal:
        """The signal ``name`` (``KeyError`` when the message has none, as cantools)."""
        for signal in self.signals:
            if signal.name == name:
                return signal
        raise KeyError(name)


@dataclass(frozen=True)
class DbcPlan:
    """The messages of a DBC, in cantools' order."""

    messages: tuple[PlanMessage, ...]

    def get_message_by_name(self, name: str) -> PlanMessage:
        """The message ``name`` (``KeyError`` when the DBC has none, as cantools)."""
        for message in self.messages:
            if message.name == name:
                return message
        raise KeyError(name)


def plan_of(db: DatabaseSpec) -> DbcPlan:
    """The plan of a parsed DBC (a cantools ``Database``)."""
    return DbcPlan(tuple(_plan_message(m) for m in db.messages))


def _plan_message(message: MessageSpec) -> PlanMessage:
    dbc = message.dbc
    return PlanMessage(
        name=message.name, frame_id=message.frame_id,
        is_extended_frame=message.is_extended_frame, length=message.length,
        cycle_time=message.cycle_time, send_type=message.send_type,
        signals=tuple(_plan_signal(s) for s in message.signals),
        dbc=None if dbc is None else PlanDbcSpecifics(
            {name: PlanAttribute(_plain(a.value)) for name, a in dbc.attributes.items()}),
    )


def _plan_signal(signal: SignalSpec) -> PlanSignal:
    ids = signal.multiplexer_ids
    return PlanSignal(
        name=signal.name, start=signal.start, length=signal.length,
        byte_order=signal.byte_order, is_signed=signal.is_signed, is_float=signal.is_float,
        scale=signal.scale, offset=signal.offset,
        multiplexer_signal=signal.multiplexer_signal,
        multiplexer_ids=None if ids is None else tuple(int(i) for i in ids),
        is_multiplexer=signal.is_multiplexer,
        choices=None if signal.choices is None else {
            int(value): str(name) for value, name in signal.choices.items()},
    )


def _plain(value: object) -> int | float | str:
    """An attribute's value as JSON keeps it exactly (int, float or text)."""
    return value if isinstance(value, int | float) and not isinstance(value, bool) else str(value)


# --- JSON ------------------------------------------------------------------------------------


def plan_to_json(plan: DbcPlan, key: str) -> str:
    """The plan as JSON, with the cache ``key`` it was derived under."""
    return json.dumps({"key": key, "messages": [asdict(m) for m in plan.messages]})


def plan_from_json(text: str, key: str) -> DbcPlan | None:
    """The plan of ``plan_to_json``'s text, or None when it was derived under another key."""
    data = json.loads(text)
    if data.get("key") != key:
        return None
    return DbcPlan(tuple(_message_from(m) for m in data["messages"]))


def _message_from(data: dict[str, Any]) -> PlanMessage:
    dbc = data["dbc"]
    return PlanMessage(
        name=data["name"], frame_id=data["frame_id"],
        is_extended_frame=data["is_extended_frame"], length=data["length"],
        cycle_time=data["cycle_time"], send_type=data["send_type"],
        signals=tuple(_signal_from(s) for s in data["signals"]),
        dbc=None if dbc is None else PlanDbcSpecifics(
            {name: PlanAttribute(a["value"]) for name, a in dbc["attributes"].items()}),
    )


def _signal_from(data: dict[str, Any]) -> PlanSignal:
    ids, choices = data["multiplexer_ids"], data["choices"]
    return PlanSignal(
        name=data["name"], start=data["start"], length=data["length"],
        byte_order=data["byte_order"], is_signed=data["is_signed"], is_float=data["is_float"],
        scale=data["scale"], offset=data["offset"], multiplexer_signal=data["multiplexer_signal"],
        multiplexer_ids=None if ids is None else tuple(ids),
        is_multiplexer=data["is_multiplexer"],
        choices=None if choices is None else {int(v): n for v, n in choices.items()},
    )


# --- the cache --------------------------------------------------------------------------------


def cache_dir() -> Path:
    """Where plans are cached (module docstring)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "odocan"


def plan_key(dbc_bytes: bytes) -> str:
    """The cache key of a DBC's bytes: their SHA-256, ``PLAN_FORMAT`` and the installed
    cantools (path, size and modification time of its package file)."""
    spec = importlib.util.find_spec("cantools")  # found, not imported
    origin = spec.origin if spec is not None and spec.origin else ""
    try:
        stat = os.stat(origin)
        stamp = f"{origin}:{stat.st_size}:{stat.st_mtime_ns}"
    except OSError:
        stamp = origin
    return f"{PLAN_FORMAT}:{hashlib.sha256(dbc_bytes).hexdigest()}:{stamp}"


def load_plan(path: Path, directory: Path | None = None) -> DbcPlan:
    """The plan of the DBC at ``path`` (read strictly by cantools when not cached under its
    key in ``directory``, default ``cache_dir()``; then cached there if it can be)."""
    key = plan_key(path.read_bytes())
    where = (directory or cache_dir()) / f"dbc-{hashlib.sha256(key.encode()).hexdigest()}.json"
    try:
        cached = plan_from_json(where.read_text(encoding="utf-8"), key)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        cached = None  # missing or damaged: derived again below
    if cached is not None:
        return cached
    plan = plan_of(_parse(path))
    _write_atomically(where, plan_to_json(plan, key))
    return plan


def _parse(path: Path) -> cantools.database.can.Database:
    """The DBC parsed by cantools, strictly (as ``sim.contract.database``)."""
    import cantools

    db = cantools.database.load_file(path, strict=True)
    assert isinstance(db, cantools.database.can.Database)
    return db


def _write_atomically(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename (readers see the old
    file or the new one, never half of one); nothing when it cannot be written."""
    import tempfile  # here: a warm run writes nothing

    temporary: str | None = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(
            "w", encoding="utf-8", dir=path.parent, prefix=".dbc-", suffix=".tmp", delete=False
        ) as file:
            temporary = file.name
            file.write(text)
        os.replace(temporary, path)
    except OSError:
        if temporary is not None:
            with contextlib.suppress(OSError):
                os.unlink(temporary)


@cache
def default_plan() -> DbcPlan:
    """The plan of odocan's DBC (``sim.contract.DBC_PATH``), loaded once."""
    from odocan.sim.contract import DBC_PATH

    return load_plan(DBC_PATH)
