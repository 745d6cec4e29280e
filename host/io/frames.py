"""CAN frames as numpy arrays (``FrameArrays``), collected live from python-can
(``FrameCollector``) or read from a log (``host.io.logs``), and back to python-can messages."""

from __future__ import annotations

from array import array
from dataclasses import dataclass
from typing import cast

import can
import numpy as np
import numpy.typing as npt

from odocan.sim.exceptions import OdocanError
from odocan.sim.framebatch import DataFrame, FrameBatchListener, Received

FLAG_EXTENDED = 0x01  # 29-bit identifier
FLAG_REMOTE = 0x02  # remote transmission request
FLAG_ERROR = 0x04  # error frame (can_id 0, no data)
FLAG_FD = 0x08  # CAN FD frame (of at most 8 bytes)
MAX_DLC = 8  # classic CAN payload; longer frames are refused

U8Array = npt.NDArray[np.uint8]
_FULL_DLC = bytes([MAX_DLC])
_FLUSH_FRAMES = 4096  # batched frames (``FrameCollector.on_frames``) held before the arrays


class LogFormatError(OdocanError):
    """A log file that cannot be read: ``LOG:LINE: what is wrong`` (one line)."""


@dataclass(frozen=True)
class FrameArrays:
    """N CAN frames in bus order, one numpy array per field.

    Attributes:
        timestamp_s: float64 (N,), seconds (simulated seconds for the lockstep rig).
        can_id: uint32 (N,), the 11- or 29-bit identifier (0 for error frames).
        dlc: uint8 (N,), payload length in bytes, 0..8.
        data: uint8 (N, 8), the payload, zero padded after ``dlc`` bytes.
        flags: uint8 (N,): bit 0 extended ID, bit 1 remote, bit 2 error frame, bit 3 CAN FD.
    """

    timestamp_s: npt.NDArray[np.float64]
    can_id: npt.NDArray[np.uint32]
    dlc: U8Array
    data: U8Array
    flags: U8Array

    def __len__(self) -> int:
        return int(self.timestamp_s.shape[0])

    @property
    def arbitration_id(self) -> npt.NDArray[np.uint32]:
        """Alias of ``can_id`` (python-can's name)."""
        return self.can_id

    def select(
        self, mask: npt.NDArray[np.bool_] | npt.NDArray[np.intp] | slice
    ) -> FrameArrays:
        """The frames picked by a boolean mask, an index array or a slice (a view), in the order
        given."""
        return FrameArrays(
            self.timestamp_s[mask], self.can_id[mask], self.dlc[mask], self.data[mask],
            self.flags[mask],
        )


class FrameCollector(FrameBatchListener):
    """A python-can ``Listener`` that keeps every frame, cheaply, for ``arrays()``.

    No ``can.Message`` is kept: each one costs a few appends to typed arrays. The lockstep rig's
    batches (``on_frames``, ``sim.tickloop.deliver``) wait in a list and go into the arrays
    ``_FLUSH_FRAMES`` at a time, column by column.
    """

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
            payloads = [frame[2] for frame in frames]
            if set(map(len, payloads)) == {MAX_DLC}:
                self._timestamp.extend([frame[0] for frame in frames])
                self._can_id.extend([frame[1] for frame in frames])
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


def empty_frames() -> FrameArrays:
    """A FrameArrays of no frame."""
    return FrameArrays(
        np.zeros(0, np.float64), np.zeros(0, np.uint32), np.zeros(0, np.uint8),
        np.zeros((0, MAX_DLC), np.uint8), np.zeros(0, np.uint8),
    )



def concat_frames(parts: list[FrameArrays]) -> FrameArrays:
    """The frames of ``parts``, one after the other."""
    if len(parts) == 1:
        return parts[0]
    if not parts:
        return empty_frames()
    return FrameArrays(
        timestamp_s=np.concatenate([p.timestamp_s for p in parts]),
        can_id=np.concatenate([p.can_id for p in parts]),
        dlc=np.concatenate([p.dlc for p in parts]),
        data=np.concatenate([p.data for p in parts]),
        flags=np.concatenate([p.flags for p in parts]),
    )



def to_message(frames: FrameArrays, i: int) -> can.Message:
    """Frame ``i`` as a python-can message (its logged timestamp, flags and payload)."""
    flags = int(frames.flags[i])
    dlc = int(frames.dlc[i])
    remote = bool(flags & FLAG_REMOTE)
    return can.Message(
        timestamp=float(frames.timestamp_s[i]),
        arbitration_id=int(frames.can_id[i]),
        is_extended_id=bool(flags & FLAG_EXTENDED),
        is_remote_frame=remote,
        is_error_frame=bool(flags & FLAG_ERROR),
        is_fd=bool(flags & FLAG_FD),
        dlc=dlc,
        data=None if remote else bytes(frames.data[i, :dlc]),
    )
