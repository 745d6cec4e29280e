"""CAN frames as numpy arrays (``FrameArrays``), collected live from python-can
(``FrameCollector``, in ``host.io.collector``: importable from here too) or read from a log
(``host.io.logs``), and back to python-can messages."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.sim.exceptions import OdocanError

if TYPE_CHECKING:
    import can

    from odocan.host.io.collector import FrameCollector as FrameCollector

FLAG_EXTENDED = 0x01  # 29-bit identifier
FLAG_REMOTE = 0x02  # remote transmission request
FLAG_ERROR = 0x04  # error frame (can_id 0, no data)
FLAG_FD = 0x08  # CAN FD frame (of at most 8 bytes)
MAX_DLC = 8  # classic CAN payload; longer frames are refused
# Beyond this a timestamp is no clock's (some 31 700 years of seconds; a candump's is Unix time, a
# bench's from 0): one such line once leaked numpy's invalid cast of its period count and a
# 300-digit "ms back" into the warnings, so it is a bad line, refused as '(nan)' is. Every reader
# (``host.io.logs``: candump's own, python-can's for the other formats) refuses it.
MAX_TIMESTAMP_S = 1e12

U8Array = npt.NDArray[np.uint8]


def __getattr__(name: str) -> object:
    """``FrameCollector`` (``host.io.collector``), imported when first asked for: it is a
    python-can ``Listener``, and reading a candump log needs no python-can (start-up)."""
    if name == "FrameCollector":
        from odocan.host.io.collector import FrameCollector

        return FrameCollector
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class LogFormatError(OdocanError):
    """A log file that cannot be read: ``LOG:LINE: what is wrong`` (one line)."""


def timestamp_fault(seconds: float) -> str | None:
    """What is wrong with a frame's time (s) as a log's reader reads it, in words (None: a
    clock's time): not a finite number (every duration and rate after it would be nan), or
    beyond ``MAX_TIMESTAMP_S`` either side. One rule for every log format."""
    import math

    if not math.isfinite(seconds):
        return "not a finite number"
    if abs(seconds) > MAX_TIMESTAMP_S:
        return f"beyond {MAX_TIMESTAMP_S:g} s: no clock's time"
    return None


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
    import can

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
