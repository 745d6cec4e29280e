"""Errors are state, not exceptions: a u32 error mask of sticky bits, reported in ODOM_STATUS."""

from __future__ import annotations

from enum import IntEnum, IntFlag


class ErrorFlag(IntFlag):
    """Bits of the firmware's u32 error mask (the ``ERROR_MASK`` signal of ODOM_STATUS)."""

    NONE = 0
    SATURATION = 1 << 0  # an arithmetic result was clamped to its width
    CONFIG_INVALID = 1 << 1  # a configuration was refused (nack sent, nothing changed)
    ENCODER_TIMEOUT = 1 << 2  # no fresh WHEEL_ENCODERS for the watchdog period
    MAILBOX_OVERFLOW = 1 << 3  # the receive mailbox was full: a frame was dropped
    E2E_ERROR = 1 << 4  # a frame failed its CRC or sequence check
    BUS_OFF = 1 << 6  # the CAN controller reported bus-off
    TIME_LOST = 1 << 7  # the tick ran WATCHDOG_TICKS periods or more late (a stalled MCU)
    IMPLAUSIBLE_STEP = 1 << 8  # an encoder step beyond the maximum wheel speed: not integrated
    COUNTER_RESET = 1 << 9  # the encoder counters restarted: re-primed, the jump not integrated
    # (also a step too long to read: its bound reached half the counters' range, encoders.py)
    POSE_UNCERTAIN = 1 << 10  # merged steps' worst-case error passed the tolerance (uncertainty.py)


class State(IntEnum):
    """Firmware state (the ``STATE`` signal of ODOM_STATUS)."""

    INIT = 0  # waiting for the first encoder frame
    OK = 1
    DEGRADED = 2  # the pose may be off: see ``Reason`` (encoders silent: integration paused)
    FAULT = 3


class Reason(IntEnum):
    """Why the state is not OK (the ``REASON`` signal of ODOM_STATUS): the last cause of
    DEGRADED (or FAULT); NONE while OK."""

    NONE = 0
    ENCODER_TIMEOUT = 1  # no accepted WHEEL_ENCODERS for the watchdog period
    TIME_LOST = 2  # the firmware itself did not run for the watchdog period (stall)
    MAILBOX_OVERFLOW = 3  # received frames were dropped: the mailbox was full
    IMPLAUSIBLE_STEP = 4  # an encoder step beyond the maximum wheel speed was refused
    COUNTER_RESET = 5  # the encoder counters restarted (motor controller reboot), or a step
    # was ambiguous (a silence long enough for them to wrap): re-primed, nothing integrated
    CONFIG_INVALID = 6  # the boot configuration was refused (FAULT)
    POSE_UNCERTAIN = 7  # the worst-case error of the steps merged across lost periods (a stall,
    # lost frames) passed the tolerance: latched until a set-pose, as COUNTER_RESET


class ErrorMask:
    """A u32 mask of sticky ``ErrorFlag`` bits; ``clear()`` is the only way to reset them."""

    __slots__ = ("bits",)

    def __init__(self) -> None:
        self.bits: int = 0

    def set(self, flag: ErrorFlag) -> None:
        """Set ``flag`` (OR into the mask). Runs in any context: no allocation."""
        self.bits |= int(flag)

    def has(self, flag: ErrorFlag) -> bool:
        """True when ``flag`` is set."""
        return bool(self.bits & int(flag))

    def clear(self) -> None:
        """Reset every bit."""
        self.bits = 0
