"""What the host heard: every frame, kept for the analysis and decoded per message on demand.

A python-can ``Listener`` on the host's bus handle. Every frame is kept (``arrays``, for
``host.judge.analysis``); a message's frames are checked (E2E, ``host.protocol.e2e``) and decoded by
cantools only when asked for (``decoded``), once each, in the order heard. Frames that fail their
E2E check (or do not decode) are left out, as a host must: only what it may use is handed on. The
command session (``host.protocol.session``) and the on-board pose (``latest_pose``) read it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import can
import cantools
from cantools.database.namedsignalvalue import NamedSignalValue

from odocan.host.io.logs import FrameArrays, FrameCollector
from odocan.host.protocol.e2e import OK, OKSOMELOST, UNPROTECTED
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.host.protocol.pose import Pose, latest_pose
from odocan.sim.exceptions import OdocanError

_ACCEPTED = (OK, OKSOMELOST, UNPROTECTED)  # E2E statuses of frames a host may use


class UnknownMessageError(OdocanError):
    """A message name the DBC does not have."""


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
            self._checked: dict[int, int] = {}  # raw frames of each ID checked so far
            self._decoded: dict[int, list[dict[str, Any]]] = {}  # the accepted ones
            self._refused: dict[int, dict[str, int]] = {}  # the others: E2E status -> count
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
        """Every frame heard, as arrays (``host.io.logs``)."""
        with self._lock:
            return self._collector.arrays()

    def __len__(self) -> int:
        with self._lock:
            return len(self._collector)

    def decoded(self, name: str, start: int = 0) -> list[dict[str, Any]]:
        """The frames of message ``name`` that passed their E2E check, decoded (signals with
        choices by name, and ``timestamp_s``), from the ``start``-th such frame on (a copy);
        ``UnknownMessageError`` for a name the DBC lacks."""
        try:
            message = self.db.get_message_by_name(name)
        except KeyError:
            known = ", ".join(sorted(m.name for m in self.db.messages))
            raise UnknownMessageError(f"the DBC has no message {name!r} (known: {known})") from None
        with self._lock:
            frame_id = message.frame_id
            done = self._decoded.setdefault(frame_id, [])
            raw = self._raw.get(frame_id, [])
            checked = self._checked.get(frame_id, 0)
            for timestamp, data in raw[checked:]:
                signals = self._decode(message, timestamp, data)
                if signals:
                    done.append(signals)
            self._checked[frame_id] = len(raw)
            return done[start:]

    def refused(self, name: str) -> dict[str, int]:
        """The frames of message ``name`` checked so far (``decoded``) that failed their E2E
        check, by status (``REPEATED``, ...): a command's missing ACK may be one refused
        (a firmware whose E2E COUNTER does not advance), said, not "no ODOM_ACK"."""
        frame_id = self.db.get_message_by_name(name).frame_id
        with self._lock:
            return dict(self._refused.get(frame_id, {}))

    def latest_pose(self) -> Pose | None:
        """The latest on-board pose heard (``host.protocol.pose``: ODOM_POSE_X and ODOM_POSE_Y
        naming one encoder frame, X first within a tick); None before the first pair."""
        halves = [(name, f) for name in ("ODOM_POSE_X", "ODOM_POSE_Y") for f in self.decoded(name)]
        halves.sort(key=lambda half: (half[1]["timestamp_s"], half[0]))  # X first within a tick
        return latest_pose(halves)

    def _decode(self, message: Any, timestamp: float, data: bytes) -> dict[str, Any]:
        """One frame's signals (choices by name) and ``timestamp_s``; {} when it is rejected."""
        status = self._monitor.check(message.frame_id, data, timestamp_s=timestamp)
        if status not in _ACCEPTED:
            refused = self._refused.setdefault(message.frame_id, {})
            refused[status] = refused.get(status, 0) + 1
            return {}
        try:
            signals = message.decode(data, decode_choices=True)
        except (cantools.database.DecodeError, ValueError):
            return {}
        plain = {k: str(v) if isinstance(v, NamedSignalValue) else v for k, v in signals.items()}
        plain["timestamp_s"] = timestamp
        return plain
