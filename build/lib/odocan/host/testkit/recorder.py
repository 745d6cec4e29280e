"""What the host heard: every frame, kept for the analysis and decoded per message on demand."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import can
import cantools
from cantools.database.namedsignalvalue import NamedSignalValue

from odocan.host.io.logs import FrameArrays, FrameCollector
from odocan.host.protocol.e2e import OK, OKSOMELOST, UNPROTECTED, E2EMonitor
from odocan.host.testkit.options import TestkitError

_ACCEPTED = (OK, OKSOMELOST, UNPROTECTED)  # E2E statuses of frames a host may use

# --- what the host heard ----------------------------------------------------------------------


class Recorder(can.Listener):
    """Every frame heard: kept for the analysis, and decoded per message on demand.

    Thread safe: a real-time backend feeds it from its own thread. ``restamp`` (a clock) makes
    every timestamp relative to that clock, whatever time base the interface stamps with.
    """

    def __init__(
        self, db: cantools.database.can.Database, restamp: Callable[[], float] | None = None
    ) -> None:
        self.db = db
        self._restamp = restamp
        self._lock = threading.Lock()
        self._offset: float | None = None
        self.reset()

    def reset(self, origin_s: float = 0.0) -> None:
        """Forget everything heard so far: the recording starts again, at ``origin_s`` of the
        ``restamp`` clock."""
        with self._lock:
            self._origin_s = origin_s
            self._collector = FrameCollector()
            self._raw: dict[int, list[tuple[float, bytes]]] = {}
            self._decoded: dict[int, list[dict[str, Any]]] = {}
            self._monitor = E2EMonitor(self.db)

    def on_message_received(self, msg: can.Message) -> None:
        """Keep one frame (python-can ``Listener``)."""
        with self._lock:
            if self._restamp is not None:
                if self._offset is None:
                    self._offset = msg.timestamp - self._restamp()
                msg.timestamp -= self._offset + self._origin_s
            self._collector.on_message_received(msg)
            if not (msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id):
                self._raw.setdefault(msg.arbitration_id, []).append(
                    (msg.timestamp, bytes(msg.data))
                )

    def arrays(self) -> FrameArrays:
        """Every frame heard, as arrays (``host.logio``)."""
        with self._lock:
            return self._collector.arrays()

    def __len__(self) -> int:
        with self._lock:
            return len(self._collector)

    def decoded(self, name: str) -> list[dict[str, Any]]:
        """The frames of message ``name`` that passed their E2E check, decoded (a copy)."""
        try:
            message = self.db.get_message_by_name(name)
        except KeyError:
            known = ", ".join(sorted(m.name for m in self.db.messages))
            raise TestkitError(f"the DBC has no message {name!r} (known: {known})") from None
        with self._lock:
            done = self._decoded.setdefault(message.frame_id, [])
            raw = self._raw.get(message.frame_id, [])
            for timestamp, data in raw[len(done) :]:
                done.append(self._decode(message, timestamp, data))
            return [d for d in done if d]

    def _decode(self, message: Any, timestamp: float, data: bytes) -> dict[str, Any]:
        """One frame's signals (choices by name) and ``timestamp_s``; {} when it is rejected."""
        status = self._monitor.check(message.frame_id, data, timestamp_s=timestamp)
        if status not in _ACCEPTED:
            return {}
        try:
            signals = message.decode(data, decode_choices=True)
        except (cantools.database.DecodeError, ValueError):
            return {}
        plain = {k: str(v) if isinstance(v, NamedSignalValue) else v for k, v in signals.items()}
        plain["timestamp_s"] = timestamp
        return plain


