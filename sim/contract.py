"""The bus contract as the sim and the host read it: dbc/odocan.dbc through cantools.

Cycle times, frame IDs and signal layouts come from the DBC (the single source of truth); the
firmware carries the same numbers as constants, and tests prove the two agree.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from odocan.sim import SHIPPED_DBC

if TYPE_CHECKING:  # imported when the DBC is read: odocan analyze reads a plan of it instead
    from typing import Protocol

    from cantools.database.can import Database, Message

    class _CycleMessage(Protocol):
        @property
        def cycle_time(self) -> int | None: ...

    class CycleSource(Protocol):
        """What ``cycle_time_s`` reads of a DBC (cantools' ``Database``, the host's plan)."""

        def get_message_by_name(self, name: str) -> _CycleMessage: ...

DBC_PATH = Path(os.environ.get("ODOCAN_DBC", SHIPPED_DBC))
# The DBC at DBC_PATH as read already (``read_as``), for the cycle times (None: by cantools)
_read: CycleSource | None = None


@cache
def database(path: Path = DBC_PATH) -> Database:
    """The DBC, loaded once (strict)."""
    import cantools
    from cantools.database.can import Database

    db = cantools.database.load_file(path, strict=True)
    assert isinstance(db, Database)
    return db


def message(name: str) -> Message:
    """One message of the contract by name."""
    return database().get_message_by_name(name)


@contextmanager
def read_as(db: CycleSource) -> Iterator[None]:
    """Inside, the cycle times of the DBC at ``DBC_PATH`` are read from ``db``, the same DBC as
    the caller already read it (``odocan run``: the judge's cached plan of it,
    ``host.protocol.dbcplan``), instead of parsing it again with cantools (whose import alone
    costs a run 0.15 s of start-up)."""
    global _read
    before, _read = _read, db
    try:
        yield
    finally:
        _read = before


def source() -> Any:
    """The DBC at ``DBC_PATH``: as the caller read it already (``read_as``), else cantools'."""
    return database() if _read is None else _read


def cycle_time_s(name: str) -> float:
    """A cyclic message's ``GenMsgCycleTime`` in seconds."""
    source = database() if _read is None else _read
    cycle_ms = source.get_message_by_name(name).cycle_time
    if not cycle_ms:
        raise ValueError(f"{name} has no GenMsgCycleTime in the DBC")
    return cycle_ms / 1000.0


def cycle_ticks(name: str, tick_s: float) -> int:
    """A cyclic message's period in whole ticks of ``tick_s`` (at least 1)."""
    return max(1, round(cycle_time_s(name) / tick_s))
