"""The motor controller's and the simulator's side of the bus's integer codec.

What MOTOR_CTRL and SIM send and receive, not what the ODOM_MCU runs: MOTOR_CTRL packs
WHEEL_ENCODERS and reads MOTOR_CMD, SIM packs SIM_TRUTH (``sim.motor_controller``). Built on the
firmware's header helpers (``firmware.frames``: ``e2e_head``, ``seal_frame``, ``frame_word``), with
the same conventions: a packer saturates a value outside its signal's DBC range (SATURATION in
``errors``) or masks a field that wraps by contract, and never raises; an unpacker returns the raw
fields, the E2E check being the receiver's job. ``tests/test_frames.py`` proves them against
cantools over every raw range.
"""

from __future__ import annotations

import math
from enum import IntEnum
from typing import NamedTuple

from odocan.firmware.errors import ErrorMask
from odocan.firmware.fixmath import i16, sat_range, wrap_i16, wrap_u16, wrap_u32
from odocan.firmware.frames import (
    U4_MAX,
    U24_MAX,
    e2e_head,
    frame_word,
    i32_field,
    seal_frame,
)
from odocan.sim.e2efacts import SIM_TRUTH, WHEEL_ENCODERS, echo_mask, message_e2e

ENC_COUNTER_START_BIT = 16  # SIM_TRUTH's ENC_COUNTER: byte 2's low bits


class MotorCmd(NamedTuple):
    counter: int  # byte 1's low nibble: the E2E COUNTER (its DBC bits of it)
    left_speed_mm_s: i16
    right_speed_mm_s: i16


class SimTruthPart(IntEnum):
    """SIM_TRUTH multiplexer ``PART``."""

    X = 0
    Y = 1
    HEADING = 2


CTRL_UPTIME_MAX_S = 15  # CTRL_UPTIME saturates here (u4)


def ctrl_uptime_code(age_s: float) -> int:
    """CTRL_UPTIME of a controller ``age_s`` seconds after its power-up (>= 0): 1 + its whole
    seconds, saturated at 15 (the DBC's comment)."""
    return min(CTRL_UPTIME_MAX_S, 1 + math.floor(age_s))


# --- WHEEL_ENCODERS (MOTOR_CTRL -> ODOM_MCU, HOST; 10 ms) ---
def pack_wheel_encoders(
    counter: int,
    left_count: int,
    right_count: int,
    ctrl_uptime_s: int = 0,
    errors: ErrorMask | None = None,
    data_ids: tuple[int, ...] | None = None,
) -> bytes:
    """WHEEL_ENCODERS: the low 24 bits of each hardware counter (any width: wrapping, never
    saturated) and CTRL_UPTIME, the controller's age code (u4: ``ctrl_uptime_code``; 0, the
    default: not reported, as an old controller sends), saturated to 0..15 (SATURATION in
    ``errors`` when given); sealed with ``data_ids`` (default: the DBC's E2EDataIDs)."""
    if not 0 <= ctrl_uptime_s <= CTRL_UPTIME_MAX_S:
        ctrl_uptime_s = sat_range(ctrl_uptime_s, 0, CTRL_UPTIME_MAX_S, errors or ErrorMask())
    word = (
        e2e_head(counter, ctrl_uptime_s)
        | ((left_count & U24_MAX) << 16)
        | ((right_count & U24_MAX) << 40)
    )
    return seal_frame(word, data_ids or message_e2e(WHEEL_ENCODERS).data_ids)


# --- MOTOR_CMD (ODOM_MCU or HOST -> MOTOR_CTRL; 20 ms while commanding) ---
def unpack_motor_cmd(data: bytes | bytearray) -> MotorCmd:
    """MOTOR_CMD: rim speed setpoints in mm/s."""
    w = frame_word(data)
    return MotorCmd((w >> 8) & U4_MAX, wrap_i16(w >> 16), wrap_i16(w >> 32))


# --- SIM_TRUTH (SIM -> HOST; 100 ms, one part per frame; multiplexed by PART) ---
def enc_counter_mask() -> int:
    """SIM_TRUTH ENC_COUNTER's largest value (2 ** its DBC bits - 1)."""
    return echo_mask(SIM_TRUTH, "ENC_COUNTER", ENC_COUNTER_START_BIT)


def pack_sim_truth(
    counter: int, part: int, enc_counter: int, value: int, errors: ErrorMask,
    e2e: tuple[int, tuple[int, ...]] | None = None,
) -> bytes:
    """SIM_TRUTH: one part. X/Y saturate to i32 (0.1 mm), HEADING wraps to u16; an unknown
    ``part`` sends ``value`` as raw u32; ``e2e``: ENC_COUNTER's largest value and the data IDs
    (default: the DBC's, ``enc_counter_mask`` and E2EDataIDs)."""
    part &= U4_MAX
    if part in (SimTruthPart.X, SimTruthPart.Y):
        raw = i32_field(value, errors)
    elif part == SimTruthPart.HEADING:
        raw = wrap_u16(value)
    else:
        raw = wrap_u32(value)
    echo_max, data_ids = e2e or (enc_counter_mask(), message_e2e(SIM_TRUTH).data_ids)
    word = e2e_head(counter, part) | ((enc_counter & echo_max) << ENC_COUNTER_START_BIT) | (
        raw << 24)
    return seal_frame(word, data_ids)
