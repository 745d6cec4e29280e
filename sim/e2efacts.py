"""The E2E facts of the frames the sim sends and takes, read of the DBC it is given (rule 3).

The sim's nodes send WHEEL_ENCODERS (MOTOR_CTRL), SIM_TRUTH (SIM) and MOTOR_CMD (the scenario
driver) and check MOTOR_CMD (MOTOR_CTRL). Each message's COUNTER lap (2 ** its bits), the
COUNTER a signal echoes (SIM_TRUTH's ENC_COUNTER: WHEEL_ENCODERS') and the data IDs
(``E2EDataIDs``) are read here of the DBC at ``sim.contract.DBC_PATH`` (``ODOCAN_DBC``), message
by message, never restated: a DBC whose WHEEL_ENCODERS COUNTER counts 3 bits makes the motor
controller's COUNTER wrap 7 -> 0 while SIM_TRUTH's keeps its own lap.

What the sim's packers cannot follow is refused in one line naming the message and the fact
(``ConfigurationError``, exit 2 on the CLI): a COUNTER that is not byte 1's low bits (Intel,
unsigned, from bit 8), one wider than E2E Profile 2's 4 bits (its DataIDList has 16 entries, and
byte 1's high nibble is the message's own), or fewer data IDs than COUNTER values.
"""

from __future__ import annotations

from functools import cache
from typing import Any, NamedTuple

from odocan.sim import contract
from odocan.sim.exceptions import ConfigurationError

COUNTER_START_BIT = 8  # Profile 2's COUNTER: byte 1's low bits (byte 0 is the CHECKSUM)
PROFILE2_COUNTER_BITS = 4  # E2E Profile 2: 16 data IDs, one per COUNTER value
WHEEL_ENCODERS, MOTOR_CMD, SIM_TRUTH = "WHEEL_ENCODERS", "MOTOR_CMD", "SIM_TRUTH"


class MessageE2E(NamedTuple):
    """One message's E2E facts as its sender steps them."""

    counter_mask: int  # the COUNTER's largest value (2 ** bits - 1): it wraps to 0 after it
    data_ids: tuple[int, ...]  # E2EDataIDs: the data ID of each COUNTER value


def _message(name: str) -> Any:
    try:
        return contract.source().get_message_by_name(name)
    except KeyError:
        raise ConfigurationError(f"the DBC ({contract.DBC_PATH}) has no message {name}") from None


def _bits(message: Any, signal: str, start: int) -> int:
    """The length in bits of ``message``'s ``signal``, the sim's layout checked: Intel,
    unsigned, from bit ``start``, at most Profile 2's 4 bits."""
    try:
        spec = message.get_signal_by_name(signal)
    except KeyError:
        raise ConfigurationError(f"{message.name} has no signal {signal} in the DBC") from None
    length = int(spec.length)
    if spec.byte_order != "little_endian" or spec.is_signed or spec.start != start:
        raise ConfigurationError(f"{message.name} {signal}: the sim packs it Intel, unsigned,"
                                 f" from bit {start}")
    if length > PROFILE2_COUNTER_BITS:
        raise ConfigurationError(
            f"{message.name} {signal} of {length} bits: E2E Profile 2 counts"
            f" {PROFILE2_COUNTER_BITS} bits at most (16 data IDs), the sim cannot send it")
    return length


@cache
def message_e2e(name: str) -> MessageE2E:
    """Message ``name``'s COUNTER lap and data IDs in the DBC at ``contract.DBC_PATH`` (read
    once a process: the DBC is fixed when the sim starts)."""
    message = _message(name)
    bits = _bits(message, "COUNTER", COUNTER_START_BIT)
    attribute = message.dbc.attributes.get("E2EDataIDs") if message.dbc else None
    text = "" if attribute is None else str(attribute.value)
    try:
        data_ids = tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise ConfigurationError(f"{name} E2EDataIDs {text!r}: not a list of numbers") from None
    if len(data_ids) < 1 << bits:
        raise ConfigurationError(
            f"{name} E2EDataIDs: {len(data_ids)} data IDs for {1 << bits} COUNTER values")
    return MessageE2E((1 << bits) - 1, data_ids)


@cache
def echo_mask(name: str, signal: str, start: int) -> int:
    """The largest value of message ``name``'s ``signal`` (from bit ``start``) that echoes
    another message's COUNTER (SIM_TRUTH's ENC_COUNTER: 2 ** its bits - 1)."""
    return (1 << _bits(_message(name), signal, start)) - 1


# The messages the firmware (ODOM_MCU) sends or checks: its build's COUNTER and data IDs
FIRMWARE_MESSAGES = ("WHEEL_ENCODERS", "MOTOR_CMD", "ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST",
                     "ODOM_SET_POSE", "ODOM_CONFIG", "ODOM_ACK", "ODOM_STATUS", "NAV_GOAL",
                     "NAV_STATUS", "ODOM_AUTH", "ODOM_FRESHNESS")


def require_firmware_follows() -> None:
    """Refuse, in one line naming the message and the fact, a DBC whose COUNTER width or data
    IDs differ from what odocan's firmware was built with (``firmware.e2e.COUNTER_MASK``,
    ``firmware.frames.*_DATA_IDS``, and the C port's header generated from the same DBC): a
    rig whose sim and judges follow the DBC while its firmware speaks another would blame the
    firmware for the DBC. The sim alone (``odocan sim``) follows any DBC it can send."""
    from odocan.firmware import frames
    from odocan.firmware.e2e import COUNTER_MASK

    for name in FIRMWARE_MESSAGES:
        facts = message_e2e(name)
        if facts.counter_mask != COUNTER_MASK:
            raise ConfigurationError(
                f"{name} COUNTER of {facts.counter_mask.bit_length()} bits in the DBC"
                f" ({contract.DBC_PATH}): odocan's firmware counts"
                f" {COUNTER_MASK.bit_length()}; it cannot speak this DBC")
        if facts.data_ids[: COUNTER_MASK + 1] != getattr(frames, f"{name}_DATA_IDS"):
            raise ConfigurationError(
                f"{name} E2EDataIDs in the DBC ({contract.DBC_PATH}) are not the ones"
                " odocan's firmware was built with; it cannot speak this DBC")
