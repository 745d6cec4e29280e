"""One ``candump -L`` line as python-can reads it (``can.io.canutils``), with an error naming the
line and what is wrong: the path of ``host.io.candump`` for whatever its vectorised parser does
not take (non-canonical lines, error frames, remote and FD frames, the first bad line)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.io.frames import MAX_DLC, LogFormatError, timestamp_fault

CAN_ERR_FLAG = 0x20000000  # candump: error frame marker in the ID (can/error.h)
_CAN_ERR_BUSERROR = 0x00000080
ID_MASK_29 = 0x1FFFFFFF

if TYPE_CHECKING:
    import can


def parse_candump_line(raw: bytes, where: str = "<line>") -> can.Message | None:
    """One ``candump -L`` line as python-can reads it (None for a blank line).

    Raises ``LogFormatError`` naming ``where`` (``LOG:LINE``) and what is wrong.
    """
    import can  # here, not at start-up: a canonical log never comes this way

    try:
        text = raw.decode("ascii").strip()
    except UnicodeDecodeError:
        raise LogFormatError(f"{where}: not ASCII text") from None
    if not text:
        return None
    fields = text.split()
    is_rx = True
    if len(fields) == 4 and fields[3].lower() in ("r", "t"):
        is_rx = fields.pop().lower() == "r"
    if len(fields) != 3:
        raise LogFormatError(
            f"{where}: expected '(TIMESTAMP) CHANNEL ID#DATA', got {len(fields)} field(s)"
        )
    timestamp = _parse_timestamp(fields[0], where)
    can_id_text, sep, data_text = fields[2].partition("#")
    if not sep:
        raise LogFormatError(f"{where}: no '#' between CAN ID and data in {fields[2]!r}")
    can_id = _parse_can_id(can_id_text, where)
    if can_id & CAN_ERR_FLAG and can_id & _CAN_ERR_BUSERROR:
        return can.Message(timestamp=timestamp, is_error_frame=True)
    is_fd = data_text.startswith("#")
    if is_fd:
        data_text = data_text[2:]
    if data_text[:1].lower() == "r":
        dlc = _parse_remote_dlc(data_text[1:], where)
        return can.Message(
            timestamp=timestamp, arbitration_id=can_id & ID_MASK_29,
            is_extended_id=len(can_id_text) > 3, is_remote_frame=True, dlc=dlc, is_rx=is_rx,
        )
    return can.Message(
        timestamp=timestamp, arbitration_id=can_id & ID_MASK_29,
        is_extended_id=len(can_id_text) > 3, data=_parse_data(data_text, where), is_fd=is_fd,
        is_rx=is_rx,
    )


def _parse_timestamp(text: str, where: str) -> float:
    """``(SECONDS)`` -> float seconds (``timestamp_fault``: a clock's)."""
    if not (text.startswith("(") and text.endswith(")")):
        raise LogFormatError(f"{where}: missing timestamp: expected '(SECONDS)', got {text!r}")
    try:
        seconds = float(text[1:-1])
    except ValueError:
        raise LogFormatError(f"{where}: bad timestamp {text!r}") from None
    if (fault := timestamp_fault(seconds)) is not None:  # '(nan)', '(1e300)'
        raise LogFormatError(f"{where}: bad timestamp {text!r} ({fault})")
    return seconds


def _parse_can_id(text: str, where: str) -> int:
    """1..8 hex digits."""
    if not 1 <= len(text) <= 8 or any(ch not in "0123456789abcdefABCDEF" for ch in text):
        raise LogFormatError(f"{where}: bad CAN ID {text!r} (1 to 8 hex digits)")
    return int(text, 16)


def _parse_remote_dlc(text: str, where: str) -> int:
    """The optional DLC digit(s) after ``R``."""
    if not text:
        return 0
    if not text.isdigit() or int(text) > MAX_DLC:
        raise LogFormatError(f"{where}: bad remote frame length {text!r} (0..8)")
    return int(text)


def _parse_data(text: str, where: str) -> bytes:
    """Hex data, two digits a byte, at most 8 bytes."""
    if len(text) % 2:
        raise LogFormatError(f"{where}: odd number of hex digits in data {text!r}")
    if len(text) > 2 * MAX_DLC:
        raise LogFormatError(
            f"{where}: {len(text) // 2} data bytes (more than 8: CAN FD frames of more than "
            "8 bytes are not supported)"
        )
    try:
        return bytes.fromhex(text)
    except ValueError:
        raise LogFormatError(f"{where}: bad hex in data {text!r}") from None
