"""Step 2 of the tick: the E2E check every received frame passes before a handler acts on it.

A frame of the wrong length is refused before the check (counted, E2E_ERROR); a frame the
Profile 2 receiver does not accept never changes state (E2E_ERROR, except a REPEATED frame,
which is only counted by its receiver).
"""

from __future__ import annotations

from odocan.firmware.e2e import E2EReceiver, E2EStatus
from odocan.firmware.errors import ErrorFlag, ErrorMask
from odocan.firmware.fixmath import wrap_u32

FRAME_BYTES = 8  # every odocan frame is a classic CAN frame of 8 bytes
_OK = E2EStatus.OK  # the enumerators as module constants: a 3.11 enum attribute read is ~0.14 us
_OKSOMELOST = E2EStatus.OKSOMELOST
_REPEATED = E2EStatus.REPEATED
_E2E_ERROR = ErrorFlag.E2E_ERROR


class Reception:
    """The gate between the mailbox and the handlers (C: one u32 counter)."""

    __slots__ = ("_errors", "frames_bad_length")

    def __init__(self, errors: ErrorMask) -> None:
        self._errors = errors
        self.frames_bad_length = 0  # u32: not 8 bytes (rejected before the E2E check)

    def usable(self, receiver: E2EReceiver, data: bytes) -> bool:
        """The Profile 2 check; True when the frame may be used (OK or OKSOMELOST)."""
        if len(data) != FRAME_BYTES:
            self.frames_bad_length = wrap_u32(self.frames_bad_length + 1)
            self._errors.set(ErrorFlag.E2E_ERROR)
            return False
        status = receiver.check(data)
        if status is _OK or status is _OKSOMELOST:
            return True
        if status is not _REPEATED:
            self._errors.set(_E2E_ERROR)
        return False
