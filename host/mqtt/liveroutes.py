"""What the bridge's ``RobotTelemetry`` does with each 11-bit message of the DBC (its routes),
built once per database and shared by every robot of a fleet.

A handler marked ``@takes(*names)`` is given the tuple of those signals' values (a frame's
values without a dict: ``livedecode.values_decoder``, made from the DBC), any other the dict of
all its signals (``livedecode.LiveDecoder``). Its most frequent frames (WHEEL_ENCODERS, the
pose halves, ODOM_TWIST: some 2.5 a robot each 10 ms tick) are handled so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from cantools.database.can import Database, Message

from odocan.host.mqtt.livedecode import LiveDecoder, values_decoder

DEFAULTS = {"CTRL_UPTIME": 0}  # a signal a DBC may lack (not reported): its value
F = TypeVar("F", bound=Callable[..., Any])


def takes(*names: str, advances: bool = False) -> Callable[[F], F]:
    """Mark a handler as given the values of ``names``, a tuple in that order; ``advances``:
    its first act is the tracker's ``advance`` to the frame's time (``PoseTracker.on_encoders``,
    ``on_pose_x``, ``on_pose_y``), so ``RobotTelemetry`` does not advance it before as well."""
    def mark(handler: F) -> F:
        _TAKES[handler.__qualname__] = (names, advances)  # not on the handler: a mypyc-compiled
        return handler  # method takes no attributes (host.accel)
    return mark


_TAKES: dict[str, tuple[tuple[str, ...], bool]] = {}  # ``takes``'s marks by handler qualname


@dataclass(frozen=True, slots=True)
class Route:
    """One message's route: its name, its handler (None: counted only, never decoded), what
    the handler is given (``decode``: a tuple for a ``takes`` handler, else ``signals``), its
    signals by name (``signals``: the compiled dict decoder); for ODOM_STATUS the PAGE signal's
    place (``status_page``: shift, mask, SUMMARY's value) to pass only its summaries to the
    reboot watch (``host.judge.sources.boot_summary`` reads nothing else); ``advances``: the
    handler advances the tracker itself (``takes``)."""

    message: Message
    name: str
    handler: Any
    decode: Any
    signals: Any
    status_page: tuple[int, int, int] | None
    advances: bool

    @classmethod
    def of(cls, message: Message, handler: Any) -> Route:
        page = None
        if message.name == "ODOM_STATUS":
            signal = message.get_signal_by_name("PAGE")
            summary = next((v for v, n in (signal.choices or {}).items() if str(n) == "SUMMARY"),
                           None)
            if signal.byte_order == "little_endian" and summary is not None:
                page = (signal.start, (1 << signal.length) - 1, int(summary))
            else:  # another layout: every frame goes to the reboot watch
                page = (0, 0, 0)
        signals = LiveDecoder(message).decode
        names, advances = _TAKES.get(getattr(handler, "__qualname__", ""), (None, False))
        decode = signals if names is None else values_decoder(message, names, DEFAULTS)
        return cls(message, message.name, handler, decode, signals, page, advances)

    def is_summary(self, data: bytes) -> bool:
        """Whether an ODOM_STATUS payload may be a SUMMARY page (its raw PAGE says so)."""
        assert self.status_page is not None
        shift, mask, summary = self.status_page
        return (int.from_bytes(data, "little") >> shift) & mask == summary


_ROUTES: dict[int, tuple[Database, dict[int, Route]]] = {}  # by id(db), with db kept alive


def routes(db: Database, handlers: dict[str, Any]) -> dict[int, Route]:
    """The routes of ``db``'s 11-bit messages by identifier (``handlers`` by message name),
    built once per database and shared by every robot (read only: a fleet's robots share one
    compiled decoder per message, not one each, which keeps a worker's working set small)."""
    entry = _ROUTES.get(id(db))
    if entry is None or entry[0] is not db:
        by_id = {m.frame_id: Route.of(m, handlers.get(m.name))
                 for m in db.messages if not m.is_extended_frame}
        entry = _ROUTES[id(db)] = (db, by_id)
    return entry[1]
