"""The host's half of the bus's integer codec: what the ODOM_MCU's peers send it and read from it.

``firmware/frames.py`` holds only what the firmware itself receives and transmits, as the MCU
would. A host sends ODOM_SET_POSE, ODOM_CONFIG, NAV_GOAL (GO included) and ODOM_AUTH, and reads
ODOM_POSE_X/Y, ODOM_TWIST, NAV_STATUS, ODOM_ACK, ODOM_FRESHNESS, ODOM_STATUS and SIM_TRUTH. The
tests that play that host (the rigs, the C port's probes, the width sanitizer's drives) and
bench/ build and read those frames here, bit for bit, on the firmware's own header helpers
(``e2e_head``, ``seal_frame``, ``frame_word``); ``tests/test_frames.py`` proves both halves
against cantools over every raw range. The product's host reads the bus with cantools
(``odocan.host.protocol``), never with this.

It also holds the E2E sender (``p02_protect``, ``p02_next_counter``: ``E2E_P02Protect`` on
``firmware.e2e.p02_crc``), which the ECU never runs and the tests' hosts do; ``tests/test_e2e.py``
proves it against cantools.autosar.

Same conventions as the firmware's half: ``pack_*`` saturate a value outside its signal's DBC
range (SATURATION in ``errors``) and never raise; ``unpack_*`` return the raw fields, the E2E
check being the receiver's job.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Final, NamedTuple

from odocan.firmware.config import MAX_WHEEL_SPEED_MAX_MM_S, MAX_WHEEL_SPEED_MIN_MM_S
from odocan.firmware.e2e import COUNTER_MASK, p02_crc
from odocan.firmware.errors import ErrorMask
from odocan.firmware.fixmath import (
    U16_MAX,
    U32_MAX,
    i16,
    i32,
    sat_range,
    u8,
    u16,
    u32,
    wrap_i16,
    wrap_i32,
    wrap_u16,
    wrap_u32,
)
from odocan.firmware.frames import (
    CONFIG_U8_LIMITS,
    FV_MASK,
    MOTOR_CMD_DATA_IDS,
    MOTOR_CMD_ID,
    NAV_GOAL_DATA_IDS,
    NAV_GOAL_ID,
    NAV_STATUS_DATA_IDS,
    NAV_STATUS_ID,
    ODOM_ACK_DATA_IDS,
    ODOM_ACK_ID,
    ODOM_AUTH_DATA_IDS,
    ODOM_AUTH_ID,
    ODOM_CONFIG_DATA_IDS,
    ODOM_CONFIG_ID,
    ODOM_FRESHNESS_DATA_IDS,
    ODOM_FRESHNESS_ID,
    ODOM_POSE_X_DATA_IDS,
    ODOM_POSE_X_ID,
    ODOM_POSE_Y_DATA_IDS,
    ODOM_POSE_Y_ID,
    ODOM_SET_POSE_DATA_IDS,
    ODOM_SET_POSE_ID,
    ODOM_STATUS_DATA_IDS,
    ODOM_STATUS_ID,
    ODOM_TWIST_DATA_IDS,
    ODOM_TWIST_ID,
    SIM_TRUTH_ID,
    U4_MAX,
    WHEEL_ENCODERS_DATA_IDS,
    WHEEL_ENCODERS_ID,
    ConfigParam,
    NavGoalField,
    NavMode,
    SetPoseField,
    StatusPage,
    e2e_head,
    frame_word,
    i32_field,
    seal_frame,
)
from odocan.sim.e2efacts import SIM_TRUTH, message_e2e
from odocan.sim.frames import SimTruthPart


# --- the E2E sender (the ECU seals its own frames with firmware.frames.seal_frame) ---
def p02_protect(frame: bytearray, counter: int, data_ids: tuple[u8, ...]) -> None:
    """``E2E_P02Protect`` on an 8-byte frame: write COUNTER (byte 1 low nibble), then CHECKSUM.

    ``counter`` is taken modulo 16 (the sender's u4 counter); byte 1's high nibble is kept.
    ``data_ids`` is the message's 16-entry list; the entry chosen is ``data_ids[counter]``.
    """
    counter &= COUNTER_MASK
    frame[1] = (frame[1] & 0xF0) | counter
    frame[0] = p02_crc(frame, data_ids[counter])


def p02_next_counter(counter: int) -> int:
    """The sender's next counter: ``(counter + 1) mod 16`` (Profile 2 counts 0..15)."""
    return (counter + 1) & COUNTER_MASK


# --- enums on the wire the firmware reads as raw bits (NAV_GOAL GO's flags) ---
class NavAppend(IntEnum):
    """NAV_GOAL ``APPEND``."""

    REPLACE = 0
    APPEND = 1


class NavFinalHeading(IntEnum):
    """NAV_GOAL ``NO_FINAL_HEADING``."""

    TURN_TO_HEADING = 0
    ANY_HEADING = 1


# --- records returned by the unpackers (raw integers) ---
class OdomPoseX(NamedTuple):
    counter: int
    enc_counter: int  # u4: COUNTER of the WHEEL_ENCODERS frame included
    x_100um: i32  # 0.1 mm
    heading_bam16: u16  # 2*pi/65536 rad


class OdomPoseY(NamedTuple):
    counter: int
    enc_counter: int
    y_100um: i32
    turns: i16  # whole turns of the unwrapped heading, wrapping


class OdomTwist(NamedTuple):
    counter: int
    enc_counter: int
    linear_vel_mm_s: i16
    angular_vel_mrad_s: i16
    distance_mm: u16  # low 16 bits of the path length in mm


class NavStatus(NamedTuple):
    counter: int
    state: int  # NavState
    goal_id: u8
    queue_depth: u8
    distance_mm: u16
    heading_error_bam16: i16  # 2*pi/65536 rad, [-pi, pi)


class OdomAck(NamedTuple):
    counter: int
    request_counter: int
    request_id: int
    request_field: int
    result: int  # AckResult
    reason: int  # AckReason


class OdomFreshness(NamedTuple):
    counter: int
    cause: int  # firmware.secoc.FreshnessCause
    fv: int  # u48: the firmware's last accepted FV (EPOCH << 28 | COUNT)


class OdomStatusSummary(NamedTuple):
    counter: int
    state: int  # firmware.errors.State
    integrator: int  # Integrator
    error_mask: u16  # low 16 bits of the u32 error mask
    uptime_s: int  # u24
    reason: int = 0  # u4 firmware.errors.Reason: why the state is not OK


class OdomStatusFrameTotals(NamedTuple):
    counter: int
    lost: u16  # wrapping
    rejected: u16
    overflowed: u16


class OdomStatusE2E(NamedTuple):
    counter: int
    page: int  # StatusPage.E2E_*: which received message
    ok: u16  # wrapping
    lost: u8
    repeated: u8
    crc_error: u8
    wrong_sequence: u8


class OdomStatusProfile(NamedTuple):
    counter: int
    page: int  # StatusPage.PROFILE
    max_wheel_speed: u16  # mm/s
    profile_crc: u32


class SimTruth(NamedTuple):
    counter: int
    part: int  # SimTruthPart
    enc_counter: int
    value: int  # i32 for X/Y (0.1 mm), u16 bam16 for HEADING, raw u32 otherwise


# --- the DBC's E2EDataIDs attribute, by frame ---
DATA_IDS_BY_FRAME_ID: Final[dict[int, tuple[u8, ...]]] = {
    WHEEL_ENCODERS_ID: WHEEL_ENCODERS_DATA_IDS,
    MOTOR_CMD_ID: MOTOR_CMD_DATA_IDS,
    ODOM_POSE_X_ID: ODOM_POSE_X_DATA_IDS,
    ODOM_POSE_Y_ID: ODOM_POSE_Y_DATA_IDS,
    ODOM_TWIST_ID: ODOM_TWIST_DATA_IDS,
    ODOM_SET_POSE_ID: ODOM_SET_POSE_DATA_IDS,
    ODOM_CONFIG_ID: ODOM_CONFIG_DATA_IDS,
    ODOM_ACK_ID: ODOM_ACK_DATA_IDS,
    ODOM_AUTH_ID: ODOM_AUTH_DATA_IDS,
    ODOM_FRESHNESS_ID: ODOM_FRESHNESS_DATA_IDS,
    ODOM_STATUS_ID: ODOM_STATUS_DATA_IDS,
    NAV_GOAL_ID: NAV_GOAL_DATA_IDS,
    NAV_STATUS_ID: NAV_STATUS_DATA_IDS,
    SIM_TRUTH_ID: message_e2e(SIM_TRUTH).data_ids,  # the sim's, not the firmware's
}


# --- the frames a host sends the ECU ---
def _u32_field(value: int, errors: ErrorMask) -> u32:
    """A u32 signal: saturated to [0, U32_MAX]."""
    return sat_range(value, 0, U32_MAX, errors)


def pack_odom_set_pose(counter: int, field: int, value: int, errors: ErrorMask) -> bytes:
    """ODOM_SET_POSE: one staged write. X/Y saturate to i32, HEADING wraps to u16, APPLY carries
    nothing (``value`` ignored); an unknown ``field`` sends ``value`` as raw u32 (tests)."""
    field &= U4_MAX
    if field in (SetPoseField.X, SetPoseField.Y):
        raw = i32_field(value, errors)
    elif field == SetPoseField.HEADING:
        raw = wrap_u16(value)
    elif field == SetPoseField.APPLY:
        raw = 0
    else:
        raw = wrap_u32(value)
    return seal_frame(e2e_head(counter, field) | (raw << 16), ODOM_SET_POSE_DATA_IDS)


def pack_odom_config(counter: int, param: int, value: int, errors: ErrorMask) -> bytes:
    """ODOM_CONFIG: one staged parameter. u32 parameters saturate to u32, COUNTER_BITS to
    [16, 32], INTEGRATOR to [0, 2], MAX_WHEEL_SPEED to its DBC range [1, 65535] mm/s; APPLY
    carries nothing (``value`` ignored); an unknown ``param`` sends ``value`` as raw u32
    (tests). A value the DBC's range excludes (MAX_WHEEL_SPEED 0) goes through
    ``pack_odom_config_raw``."""
    param &= U4_MAX
    limits = CONFIG_U8_LIMITS.get(param)
    if limits is not None:
        raw = sat_range(value, limits[0], limits[1], errors)
    elif param == ConfigParam.MAX_WHEEL_SPEED:
        raw = sat_range(value, MAX_WHEEL_SPEED_MIN_MM_S, MAX_WHEEL_SPEED_MAX_MM_S, errors)
    elif param == ConfigParam.APPLY:
        raw = 0
    elif param <= ConfigParam.WHEELBASE:
        raw = _u32_field(value, errors)
    else:
        raw = wrap_u32(value)
    return seal_frame(e2e_head(counter, param) | (raw << 16), ODOM_CONFIG_DATA_IDS)


def pack_odom_config_raw(counter: int, param: int, raw: int) -> bytes:
    """ODOM_CONFIG with ``raw`` (u32, wrapped) as the payload, unsaturated: a value outside the
    DBC's range, sent so that the receiver's refusal (NACK OUT_OF_RANGE) is exercised."""
    payload = wrap_u32(raw)
    return seal_frame(e2e_head(counter, param & U4_MAX) | (payload << 16), ODOM_CONFIG_DATA_IDS)


def pack_nav_goal(counter: int, field: int, value: int, errors: ErrorMask) -> bytes:
    """NAV_GOAL X, Y, HEADING or STOP: X/Y saturate to i32 (0.1 mm), HEADING wraps to u16, STOP
    carries nothing; GO goes through ``pack_nav_goal_go``; any other ``field`` (GO included)
    sends ``value`` as raw u32 (tests)."""
    field &= U4_MAX
    if field in (NavGoalField.X, NavGoalField.Y):
        raw = i32_field(value, errors)
    elif field == NavGoalField.HEADING:
        raw = wrap_u16(value)
    elif field == NavGoalField.STOP:
        raw = 0
    else:
        raw = wrap_u32(value)
    return seal_frame(e2e_head(counter, field) | (raw << 16), NAV_GOAL_DATA_IDS)


def pack_nav_goal_go(
    counter: int, mode: int, append: int, no_final_heading: int, goal_id: int, errors: ErrorMask
) -> bytes:
    """NAV_GOAL GO: commit the staged goal. MODE saturates to [0, 1], the flags to one bit,
    GOAL_ID to u8."""
    word = (
        e2e_head(counter, NavGoalField.GO)
        | (sat_range(mode, NavMode.TURN_GO_TURN, NavMode.GO_TO_GOAL, errors) << 16)
        | (sat_range(append, 0, 1, errors) << 20)
        | (sat_range(no_final_heading, 0, 1, errors) << 21)
        | (sat_range(goal_id, 0, 0xFF, errors) << 24)
    )
    return seal_frame(word, NAV_GOAL_DATA_IDS)


def pack_odom_auth(
    counter: int, request: int, freshness: int, mac: int, errors: ErrorMask | None = None
) -> bytes:
    """ODOM_AUTH: REQUEST (byte 1 high nibble), FRESHNESS (bytes 2-3), AUTHENTICATOR (4-7); an
    out-of-range REQUEST saturates (SATURATION in ``errors``, when given)."""
    errors = ErrorMask() if errors is None else errors
    word = (
        e2e_head(counter, sat_range(request, 0, 2, errors))
        | ((freshness & U16_MAX) << 16)
        | ((mac & U32_MAX) << 32)
    )
    return seal_frame(word, ODOM_AUTH_DATA_IDS)


# --- the frames a host reads from the ECU (and the simulator's SIM_TRUTH) ---
def unpack_odom_pose_x(data: bytes | bytearray) -> OdomPoseX:
    """ODOM_POSE_X: x in 0.1 mm, heading as a u16 binary angle."""
    w = frame_word(data)
    return OdomPoseX((w >> 8) & U4_MAX, (w >> 12) & U4_MAX, wrap_i32(w >> 16), w >> 48)


def unpack_odom_pose_y(data: bytes | bytearray) -> OdomPoseY:
    """ODOM_POSE_Y: y in 0.1 mm, whole turns."""
    w = frame_word(data)
    return OdomPoseY((w >> 8) & U4_MAX, (w >> 12) & U4_MAX, wrap_i32(w >> 16), wrap_i16(w >> 48))


def unpack_odom_twist(data: bytes | bytearray) -> OdomTwist:
    """ODOM_TWIST: mm/s, mrad/s, and the low 16 bits of the distance in mm."""
    w = frame_word(data)
    return OdomTwist(
        (w >> 8) & U4_MAX,
        (w >> 12) & U4_MAX,
        wrap_i16(w >> 16),
        wrap_i16(w >> 32),
        (w >> 48) & U16_MAX,
    )


def unpack_nav_status(data: bytes | bytearray) -> NavStatus:
    """NAV_STATUS: state, goal, queue depth, distance in mm, heading error in BAM16."""
    w = frame_word(data)
    return NavStatus(
        (w >> 8) & U4_MAX,
        (w >> 12) & U4_MAX,
        (w >> 16) & 0xFF,
        (w >> 24) & 0xFF,
        (w >> 32) & U16_MAX,
        wrap_i16(w >> 48),
    )


def unpack_odom_ack(data: bytes | bytearray) -> OdomAck:
    """ODOM_ACK: which request, ACK/NACK and the reason."""
    w = frame_word(data)
    return OdomAck(
        (w >> 8) & U4_MAX,
        (w >> 12) & U4_MAX,
        (w >> 16) & U16_MAX,
        (w >> 32) & U4_MAX,
        (w >> 36) & 1,
        (w >> 40) & 0xFF,
    )


def unpack_odom_freshness(data: bytes | bytearray) -> OdomFreshness:
    """ODOM_FRESHNESS's raw fields."""
    w = frame_word(data)
    return OdomFreshness((w >> 8) & U4_MAX, (w >> 12) & U4_MAX, (w >> 16) & FV_MASK)


def unpack_odom_status(
    data: bytes | bytearray,
) -> OdomStatusSummary | OdomStatusFrameTotals | OdomStatusE2E | OdomStatusProfile:
    """ODOM_STATUS: the record of the page carried (pages 2..5 share the E2E layout)."""
    w = frame_word(data)
    counter = (w >> 8) & U4_MAX
    page = (w >> 12) & U4_MAX
    if page == StatusPage.SUMMARY:
        return OdomStatusSummary(
            counter,
            (w >> 16) & 0x3,
            (w >> 18) & 0x3,
            (w >> 24) & U16_MAX,
            w >> 40,
            (w >> 20) & U4_MAX,
        )
    if page == StatusPage.FRAME_TOTALS:
        return OdomStatusFrameTotals(counter, (w >> 16) & U16_MAX, (w >> 32) & U16_MAX, w >> 48)
    if page == StatusPage.PROFILE:
        return OdomStatusProfile(counter, page, (w >> 16) & U16_MAX, w >> 32)
    return OdomStatusE2E(
        counter,
        page,
        (w >> 16) & U16_MAX,
        (w >> 32) & 0xFF,
        (w >> 40) & 0xFF,
        (w >> 48) & 0xFF,
        w >> 56,
    )


def unpack_sim_truth(data: bytes | bytearray) -> SimTruth:
    """SIM_TRUTH: (counter, part, enc_counter, value) with value read per part (see SimTruth)."""
    w = frame_word(data)
    part = (w >> 12) & U4_MAX
    raw = (w >> 24) & U32_MAX
    if part in (SimTruthPart.X, SimTruthPart.Y):
        value = wrap_i32(raw)
    elif part == SimTruthPart.HEADING:
        value = raw & U16_MAX
    else:
        value = raw
    return SimTruth((w >> 8) & U4_MAX, part, (w >> 16) & U4_MAX, value)
