"""``FrameCollector``: a python-can ``Listener`` that keeps frames as ``FrameArrays``.

Its own module (``host.io.frames`` hands it out on first use) because it subclasses python-can's
``Listener``: what reads a candump log imports no python-can."""

from __future__ import annotations

from array import array
from typing import cast

import can
import numpy as np

from odocan.host.io.frames import (
    FLAG_ERROR,
    FLAG_EXTENDED,
    FLAG_FD,
    FLAG_REMOTE,
    MAX_DLC,
    FrameArrays,
)
from odocan.sim.framebatch import DataFrame, FrameBatchListener, Received

_FULL_DLC = bytes([MAX_DLC])
_FLUSH_FRAMES = 4096  # batched frames (``FrameCollector.on_frames``) held before the arrays


class FrameCollector(FrameBatchListener):
    """A python-can ``Listener`` that keeps every frame, cheaply, for ``arrays()``.

    No ``can.Message`` is kept: each one costs a few appends to typed arrays. The lockstep rig's
    batches (``on_frames``, ``sim.tickloop.deliver``) wait in a list and go into the arrays
    ``_FLUSH_FRAMES`` at a time, column by column. Passive (``FrameBatchListener.passive``):
    ``arrays()`` is read after a run, so a run may hand it a simulated second of frames at once.
    """

    passive = True

    def __init__(self) -> None:
        self._timestamp = array("d")
        self._can_id = array("I")
        self._dlc = array("B")
        self._flags = array("B")
        self._data = bytearray()
        self._pending: list[Received] = []  # batched frames not yet in the arrays, in bus order

    def on_message_received(self, msg: can.Message) -> None:
        """Append one frame (payloads longer than 8 bytes are cut to 8)."""
        if self._pending:
            self._flush()
        self._append(msg.timestamp, msg.arbitration_id, msg.dlc, _message_flags(msg), msg.data)

    def on_frames(self, frames: list[Received]) -> None:
        """Append a batch of frames (``OdocanBus.drain``'s): kept, then flushed in bulk."""
        pending = self._pending
        pending += frames
        if len(pending) >= _FLUSH_FRAMES:
            self._flush()

    def _append(
        self, timestamp_s: float, can_id: int, dlc: int, flags: int, data: bytes | bytearray
    ) -> None:
        """One frame into the arrays (payload cut to 8 bytes, zero padded)."""
        payload = bytes(data[:MAX_DLC])
        self._timestamp.append(timestamp_s)
        self._can_id.append(can_id)
        self._dlc.append(min(dlc, MAX_DLC))
        self._flags.append(flags)
        self._data += payload
        if len(payload) < MAX_DLC:
            self._data += bytes(MAX_DLC - len(payload))

    def _flush(self) -> None:
        """The pending batches into the arrays: all classic 8-byte data frames (the rig's) a
        column at a time, else frame by frame."""
        pending, self._pending = self._pending, []
        if not pending:
            return
        if set(map(type, pending)) == {tuple}:
            frames = cast("list[DataFrame]", pending)
            stamps, can_ids, payloads = zip(*frames, strict=True)  # the columns, at once
            if set(map(len, payloads)) == {MAX_DLC}:
                self._timestamp.extend(stamps)
                self._can_id.extend(can_ids)
                self._dlc.frombytes(_FULL_DLC * len(frames))
                self._flags.frombytes(bytes(len(frames)))
                self._data += b"".join(payloads)
                return
        for frame in pending:
            if isinstance(frame, tuple):
                stamp_s, can_id, data = frame
                self._append(stamp_s, can_id, len(data), 0, data)
            else:
                self._append(frame.timestamp, frame.arbitration_id, frame.dlc,
                             _message_flags(frame), frame.data)

    def __len__(self) -> int:
        return len(self._timestamp) + len(self._pending)

    def arrays(self) -> FrameArrays:
        """The frames collected so far (copies)."""
        self._flush()
        n = len(self._timestamp)
        return FrameArrays(
            timestamp_s=np.array(self._timestamp, dtype=np.float64),
            can_id=np.array(self._can_id, dtype=np.uint32),
            dlc=np.array(self._dlc, dtype=np.uint8),
            data=np.frombuffer(bytes(self._data), dtype=np.uint8).reshape(n, MAX_DLC).copy(),
            flags=np.array(self._flags, dtype=np.uint8),
        )


def _message_flags(msg: can.Message) -> int:
    """The ``FrameArrays.flags`` bits of one python-can message."""
    return (
        (FLAG_EXTENDED if msg.is_extended_id else 0)
        | (FLAG_REMOTE if msg.is_remote_frame else 0)
        | (FLAG_ERROR if msg.is_error_frame else 0)
        | (FLAG_FD if msg.is_fd else 0)
    )
