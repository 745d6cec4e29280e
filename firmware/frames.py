"""The codec of the frames the ODOM_MCU receives and transmits, as generated C would be.

dbc/odocan.dbc is the contract. A frame is 8 bytes, Intel byte order, read as one little-endian
``uint64_t word``: a signal at DBC start bit ``s`` of length ``n`` is ``(word >> s) & ((1 << n) -
1)``. Every frame starts with the E2E Profile 2 header (firmware.e2e): CHECKSUM in bits 0-7,
COUNTER in bits 8-11; a multiplexer sits in byte 1's high nibble.

* ``unpack_<msg>(data) -> record``, for what the ECU receives: the raw fields. The CRC and
  counter are not checked here: run the message's ``E2EReceiver`` first, unpack what it accepts.
* ``pack_<msg>(counter, ..., errors) -> bytes``, for what it transmits: 8 bytes, E2E protected
  with ``counter`` (mod 16), raw integers only (0.1 mm, u16 binary angles...). A value outside
  its signal's DBC ``[min|max]`` saturates (fixmath.sat_range: SATURATION in ``errors``); fields
  that wrap by contract (counter low bits, angles, totals) are masked. Packers never raise.

The host's directions (what it sends the ECU and reads from it) are not the MCU's code:
``tests/host_frames.py`` holds them, on the same header helpers; the motor controller's and the
simulator's side (WHEEL_ENCODERS out, MOTOR_CMD in, SIM_TRUTH) is ``sim/frames.py``.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Final, NamedTuple

from odocan.firmware.config import Integrator
from odocan.firmware.e2e import COUNTER_MASK, DATA_ID_COUNT, p02_seal
from odocan.firmware.errors import ErrorMask, Reason
from odocan.firmware.fixmath import (
    I16_MAX,
    I16_MIN,
    I32_MAX,
    I32_MIN,
    U16_MAX,
    U32_MAX,
    sat_range,
    u8,
    u16,
    u32,
    u64,
    wrap_i32,
    wrap_u16,
    wrap_u32,
)

U4_MAX: Final = 0xF
U24_MAX: Final = 0xFF_FFFF
CAN_ID_MAX: Final = 0x7FF  # 11-bit identifiers
NAV_QUEUE_DEPTH_MAX: Final = 16  # NAV_STATUS QUEUE_DEPTH: the path's capacity (firmware.nav)


# --- message IDs (lower = higher priority; 0x280-0x2FF navigation) ---
WHEEL_ENCODERS_ID: Final = 0x100
MOTOR_CMD_ID: Final = 0x110
ODOM_POSE_X_ID: Final = 0x200
ODOM_POSE_Y_ID: Final = 0x201
ODOM_TWIST_ID: Final = 0x202
NAV_GOAL_ID: Final = 0x280
NAV_STATUS_ID: Final = 0x281
ODOM_SET_POSE_ID: Final = 0x300
ODOM_CONFIG_ID: Final = 0x301
ODOM_ACK_ID: Final = 0x302
ODOM_AUTH_ID: Final = 0x303
ODOM_FRESHNESS_ID: Final = 0x304
ODOM_STATUS_ID: Final = 0x380
SIM_TRUTH_ID: Final = 0x700


def _data_ids(slot: int) -> tuple[u8, ...]:
    """Profile 2 DataIDList of E2E slot ``slot`` (1..15): ``DataID[c] = (slot << 4) | c``."""
    return tuple((slot << 4) | counter for counter in range(DATA_ID_COUNT))


# --- E2E Profile 2 data-ID lists (the DBC's E2EDataIDs attribute) ---
WHEEL_ENCODERS_DATA_IDS: Final = _data_ids(1)
MOTOR_CMD_DATA_IDS: Final = _data_ids(2)
ODOM_POSE_X_DATA_IDS: Final = _data_ids(3)
ODOM_POSE_Y_DATA_IDS: Final = _data_ids(4)
ODOM_TWIST_DATA_IDS: Final = _data_ids(5)
ODOM_SET_POSE_DATA_IDS: Final = _data_ids(6)
ODOM_CONFIG_DATA_IDS: Final = _data_ids(7)
ODOM_ACK_DATA_IDS: Final = _data_ids(8)
ODOM_STATUS_DATA_IDS: Final = _data_ids(9)
NAV_GOAL_DATA_IDS: Final = _data_ids(10)
NAV_STATUS_DATA_IDS: Final = _data_ids(11)
ODOM_AUTH_DATA_IDS: Final = _data_ids(12)
ODOM_FRESHNESS_DATA_IDS: Final = _data_ids(13)


# --- enums on the wire (VAL_ tables; INTEGRATOR is firmware.config.Integrator) ---
class SetPoseField(IntEnum):
    """ODOM_SET_POSE multiplexer ``FIELD``."""

    X = 0
    Y = 1
    HEADING = 2
    APPLY = 15


class ConfigParam(IntEnum):
    """ODOM_CONFIG multiplexer ``PARAM``."""

    COUNTS_PER_REV = 0
    WHEEL_RADIUS_LEFT = 1
    WHEEL_RADIUS_RIGHT = 2
    WHEELBASE = 3
    COUNTER_BITS = 4
    INTEGRATOR = 5
    MAX_WHEEL_SPEED = 6  # u16 mm/s
    APPLY = 15


class AckResult(IntEnum):
    """ODOM_ACK ``RESULT``."""

    ACK = 0
    NACK = 1


class AckReason(IntEnum):
    """ODOM_ACK ``REASON``."""

    OK = 0
    OUT_OF_RANGE = 1  # a field value outside its valid range
    UNKNOWN_FIELD = 2  # a multiplexer value this firmware does not know
    INCOMPLETE = 3  # APPLY before every field was staged
    BUSY = 4  # cannot take the request now
    INCONSISTENT = 5  # each field valid, the set is not (APPLY)
    QUEUE_FULL = 6  # NAV_GOAL GO: the path already holds NAV_QUEUE_SLOTS goals
    AUTH_FAILED = 7  # SecOC: the ODOM_AUTH authenticator does not match (forged, wrong key)
    AUTH_FRESHNESS = 8  # SecOC: freshness not above the last accepted, or beyond the window
    AUTH_MISSING = 9  # SecOC: no ODOM_AUTH within 20 ms, or displaced by the next frame
    AUTH_UNAVAILABLE = 10  # SecOC: no usable key, NVM write failed or EPOCH exhausted
    REPEATED = 11  # ODOM_CONFIG: the last accepted COUNTER again, other content (two senders)


class StatusPage(IntEnum):
    """ODOM_STATUS multiplexer ``PAGE``: 0 summary, 1 totals, 2..5 E2E counts of one message
    each, 6 the running profile."""

    SUMMARY = 0
    FRAME_TOTALS = 1
    E2E_WHEEL_ENCODERS = 2
    E2E_ODOM_SET_POSE = 3
    E2E_ODOM_CONFIG = 4
    E2E_NAV_GOAL = 5
    PROFILE = 6  # the robot parameters the firmware runs with: MAX_WHEEL_SPEED, PROFILE_CRC


class NavGoalField(IntEnum):
    """NAV_GOAL multiplexer ``FIELD``."""

    X = 0
    Y = 1
    HEADING = 2
    STOP = 14
    GO = 15


class NavMode(IntEnum):
    """NAV_GOAL ``MODE``: the controller driving to a goal."""

    TURN_GO_TURN = 0
    GO_TO_GOAL = 1


class NavState(IntEnum):
    """NAV_STATUS ``STATE``."""

    IDLE = 0  # no goal since reset
    TURNING = 1  # turn-go-turn: rotating in place toward the goal
    DRIVING = 2  # driving to the goal position (either mode)
    FINAL_TURN = 3  # rotating in place to the goal's heading
    REACHED = 4  # the goal is reached (within tolerance); the motors are commanded to 0
    STOPPED = 5  # the host sent STOP: path cleared, motors commanded to 0
    ABORTED = 6  # the odometry stopped (encoders silent, fault): path cleared, motors to 0


# --- records returned by the unpackers (raw integers) ---
class WheelEncoders(NamedTuple):
    counter: int  # u4 E2E counter
    left_count: int  # u24: low 24 bits of the left hardware counter
    right_count: int  # u24
    ctrl_uptime_s: int = 0  # u4: 1 + the controller's whole seconds since power-up (0: unknown)


class OdomSetPose(NamedTuple):
    counter: int
    field: int  # SetPoseField
    value: int  # i32 for X/Y (0.1 mm), u16 bam16 for HEADING, 0 for APPLY, raw u32 otherwise


class OdomConfig(NamedTuple):
    counter: int
    param: int  # ConfigParam
    value: u32  # u32 parameters; u8 COUNTER_BITS / INTEGRATOR; u16 MAX_WHEEL_SPEED; raw u32 else


class NavGoal(NamedTuple):
    counter: int
    field: int  # NavGoalField
    value: int  # i32 for X/Y (0.1 mm), u16 bam16 for HEADING, 0 for STOP/GO, raw u32 otherwise
    mode: int  # u4 NavMode (GO only, else 0)
    append: int  # u1 NavAppend (GO only, else 0)
    no_final_heading: int  # u1 NavFinalHeading (GO only, else 0)
    goal_id: u8  # GO only, else 0


class OdomAuth(NamedTuple):
    counter: int  # u4 E2E counter of the ODOM_AUTH frame
    request: int  # u4 firmware.secoc.AuthRequest
    freshness: int  # u16: the low 16 bits of FV
    authenticator: int  # u32: MSB_32 of the CMAC tag


# --- the E2E header ---
seal_frame = p02_seal  # the frame of a word with its Profile 2 CRC in byte 0 (firmware.e2e)


def e2e_head(counter: int, nibble: int) -> u64:
    """Bits 8..15 of the word: COUNTER (bits 8-11) and byte 1's high nibble (bits 12-15)."""
    return ((nibble & U4_MAX) << 12) | ((counter & COUNTER_MASK) << 8)


def frame_word(data: bytes | bytearray) -> u64:
    """The frame as a little-endian ``uint64_t``."""
    return int.from_bytes(data, "little")


def i32_field(value: int, errors: ErrorMask) -> u32:
    """An i32 signal as its 32 raw bits: saturated to the i32 range, then two's complement."""
    if I32_MIN <= value <= I32_MAX:  # in range: the (uint32_t) cast alone
        return value & U32_MAX
    return wrap_u32(sat_range(value, I32_MIN, I32_MAX, errors))


def _i16_field(value: int, errors: ErrorMask) -> u16:
    """An i16 signal as its 16 raw bits: saturated to the i16 range, then two's complement."""
    if I16_MIN <= value <= I16_MAX:  # in range: the (uint16_t) cast alone
        return value & U16_MAX
    return wrap_u16(sat_range(value, I16_MIN, I16_MAX, errors))


# === what the ECU receives ===
# --- WHEEL_ENCODERS (MOTOR_CTRL -> ODOM_MCU, HOST; 10 ms) ---
def unpack_wheel_encoders(data: bytes | bytearray) -> WheelEncoders:
    """WHEEL_ENCODERS: u24 counts (extend them with the delta of the low 24 bits) and the
    controller's CTRL_UPTIME (u4 s, saturated at 15; 0: not reported)."""
    return WheelEncoders(*unpack_wheel_encoders_fields(data))


def unpack_wheel_encoders_fields(data: bytes | bytearray) -> tuple[int, int, int, int]:
    """``unpack_wheel_encoders`` as a plain tuple (counter, left_count, right_count,
    ctrl_uptime_s): the firmware's read of every frame (building the record costs ~0.3 us more
    in CPython; C: the same struct). ``frame_word`` in line: every encoder frame."""
    w = int.from_bytes(data, "little")
    return (w >> 8) & U4_MAX, (w >> 16) & U24_MAX, (w >> 40) & U24_MAX, (w >> 12) & U4_MAX


# --- ODOM_SET_POSE, ODOM_CONFIG, NAV_GOAL (HOST -> ODOM_MCU; events; multiplexed) ---
def unpack_odom_set_pose(data: bytes | bytearray) -> OdomSetPose:
    """ODOM_SET_POSE: (counter, field, value) with value read per field (see OdomSetPose)."""
    w = frame_word(data)
    field = (w >> 12) & U4_MAX
    raw = (w >> 16) & U32_MAX
    if field in (SetPoseField.X, SetPoseField.Y):
        value = wrap_i32(raw)
    elif field == SetPoseField.HEADING:
        value = raw & U16_MAX
    elif field == SetPoseField.APPLY:
        value = 0
    else:
        value = raw
    return OdomSetPose((w >> 8) & U4_MAX, field, value)


CONFIG_U8_LIMITS: Final[dict[int, tuple[int, int]]] = {
    ConfigParam.COUNTER_BITS: (16, 32),
    ConfigParam.INTEGRATOR: (Integrator.EULER, Integrator.EXACT),
}


def unpack_odom_config(data: bytes | bytearray) -> OdomConfig:
    """ODOM_CONFIG: (counter, param, value) with value read per parameter (see OdomConfig)."""
    w = frame_word(data)
    param = (w >> 12) & U4_MAX
    value = (w >> 16) & U32_MAX
    if param in CONFIG_U8_LIMITS:
        value &= 0xFF
    elif param == ConfigParam.MAX_WHEEL_SPEED:
        value &= U16_MAX
    elif param == ConfigParam.APPLY:
        value = 0
    return OdomConfig((w >> 8) & U4_MAX, param, value)


def unpack_nav_goal(data: bytes | bytearray) -> NavGoal:
    """NAV_GOAL: the record with ``value`` read per field and GO's fields (raw: MODE is not
    range-checked here; the receiver answers OUT_OF_RANGE)."""
    w = frame_word(data)
    field = (w >> 12) & U4_MAX
    raw = (w >> 16) & U32_MAX
    counter = (w >> 8) & U4_MAX
    if field == NavGoalField.GO:
        goal_id = (raw >> 8) & 0xFF
        return NavGoal(counter, field, 0, raw & U4_MAX, (raw >> 4) & 1, (raw >> 5) & 1, goal_id)
    if field in (NavGoalField.X, NavGoalField.Y):
        value = wrap_i32(raw)
    elif field == NavGoalField.HEADING:
        value = raw & U16_MAX
    elif field == NavGoalField.STOP:
        value = 0
    else:
        value = raw
    return NavGoal(counter, field, value, 0, 0, 0, 0)


# --- ODOM_AUTH (HOST -> ODOM_MCU; event, after each secured command frame) ---
def unpack_odom_auth(data: bytes | bytearray) -> OdomAuth:
    """ODOM_AUTH's raw fields (run its E2E check first)."""
    w = frame_word(data)
    return OdomAuth((w >> 8) & U4_MAX, (w >> 12) & U4_MAX, (w >> 16) & U16_MAX, (w >> 32) & U32_MAX)


# === what the ECU transmits ===
# --- MOTOR_CMD (ODOM_MCU or HOST -> MOTOR_CTRL; 20 ms while commanding) ---
def pack_motor_cmd(
    counter: int, left_speed_mm_s: int, right_speed_mm_s: int, errors: ErrorMask
) -> bytes:
    """MOTOR_CMD: rim speed setpoints in mm/s, saturated to i16."""
    word = (
        e2e_head(counter, 0)
        | (_i16_field(left_speed_mm_s, errors) << 16)
        | (_i16_field(right_speed_mm_s, errors) << 32)
    )
    return seal_frame(word, MOTOR_CMD_DATA_IDS)


# --- ODOM_POSE_X / ODOM_POSE_Y / ODOM_TWIST (ODOM_MCU -> HOST; 20 ms) ---
# Sent every 20 ms: the header and the fields in range are packed in line (e2e_head, wrap_u16,
# i32_field's and _i16_field's casts: C's static inline functions); out of range, the helpers.
def pack_odom_pose_x(
    counter: int, enc_counter: int, x_100um: int, heading_bam16: int, errors: ErrorMask
) -> bytes:
    """ODOM_POSE_X: x (0.1 mm, saturated to i32) and heading (u16 binary angle, wraps)."""
    x_raw = x_100um & U32_MAX if I32_MIN <= x_100um <= I32_MAX else i32_field(x_100um, errors)
    head = ((enc_counter & U4_MAX) << 12) | ((counter & COUNTER_MASK) << 8)
    word = head | (x_raw << 16) | ((heading_bam16 & U16_MAX) << 48)
    return seal_frame(word, ODOM_POSE_X_DATA_IDS)


def pack_odom_pose_y(
    counter: int, enc_counter: int, y_100um: int, turns: int, errors: ErrorMask
) -> bytes:
    """ODOM_POSE_Y: y (0.1 mm, saturated to i32) and whole heading turns (i16, wraps)."""
    y_raw = y_100um & U32_MAX if I32_MIN <= y_100um <= I32_MAX else i32_field(y_100um, errors)
    head = ((enc_counter & U4_MAX) << 12) | ((counter & COUNTER_MASK) << 8)
    word = head | (y_raw << 16) | ((turns & U16_MAX) << 48)
    return seal_frame(word, ODOM_POSE_Y_DATA_IDS)


def pack_odom_twist(
    counter: int,
    enc_counter: int,
    linear_vel_mm_s: int,
    angular_vel_mrad_s: int,
    distance_mm: int,
    errors: ErrorMask,
) -> bytes:
    """ODOM_TWIST: velocities saturated to i16; distance (mm, any width) keeps its low 16 bits."""
    v, w = linear_vel_mm_s, angular_vel_mrad_s
    v_raw = v & U16_MAX if I16_MIN <= v <= I16_MAX else _i16_field(v, errors)
    w_raw = w & U16_MAX if I16_MIN <= w <= I16_MAX else _i16_field(w, errors)
    head = ((enc_counter & U4_MAX) << 12) | ((counter & COUNTER_MASK) << 8)
    word = head | (v_raw << 16) | (w_raw << 32) | ((distance_mm & U16_MAX) << 48)
    return seal_frame(word, ODOM_TWIST_DATA_IDS)


# --- NAV_STATUS (ODOM_MCU -> HOST; 100 ms and on every change of STATE or GOAL_ID) ---
def pack_nav_status(
    counter: int,
    state: int,
    goal_id: int,
    queue_depth: int,
    distance_mm: int,
    heading_error_bam16: int,
    errors: ErrorMask,
) -> bytes:
    """NAV_STATUS: STATE, GOAL_ID, QUEUE_DEPTH, DISTANCE saturate to their DBC ranges; the heading
    error is an angle and wraps to i16."""
    word = (
        e2e_head(counter, sat_range(state, NavState.IDLE, NavState.ABORTED, errors))
        | (sat_range(goal_id, 0, 0xFF, errors) << 16)
        | (sat_range(queue_depth, 0, NAV_QUEUE_DEPTH_MAX, errors) << 24)
        | (sat_range(distance_mm, 0, U16_MAX, errors) << 32)
        | (wrap_u16(heading_error_bam16) << 48)
    )
    return seal_frame(word, NAV_STATUS_DATA_IDS)


# --- ODOM_ACK (ODOM_MCU -> HOST; event) ---
def pack_odom_ack(
    counter: int,
    request_counter: int,
    request_id: int,
    request_field: int,
    result: int,
    reason: int,
    errors: ErrorMask,
) -> bytes:
    """ODOM_ACK: answer the request frame (``request_id``, its COUNTER and multiplexer value)."""
    word = (
        e2e_head(counter, request_counter)
        | (sat_range(request_id, 0, CAN_ID_MAX, errors) << 16)
        | ((request_field & U4_MAX) << 32)
        | (sat_range(result, AckResult.ACK, AckResult.NACK, errors) << 36)
        | (sat_range(reason, AckReason.OK, AckReason.REPEATED, errors) << 40)
    )
    return seal_frame(word, ODOM_ACK_DATA_IDS)


# --- ODOM_FRESHNESS (ODOM_MCU -> HOST; 1000 ms and on events) ---
# The u48 FV (FV_COUNT and FV_EPOCH side by side): firmware.secoc's EPOCH << COUNT_BITS | COUNT.
# Its one home is here: secoc imports this codec, so the codec cannot import secoc.
FV_MASK: Final = (1 << 48) - 1


def pack_odom_freshness(counter: int, cause: int, fv: int, errors: ErrorMask) -> bytes:
    """ODOM_FRESHNESS: CAUSE (byte 1 high nibble), FV (u48: COUNT bits 16-43, EPOCH 44-63)."""
    word = e2e_head(counter, sat_range(cause, 0, 4, errors)) | ((fv & FV_MASK) << 16)
    return seal_frame(word, ODOM_FRESHNESS_DATA_IDS)


# --- ODOM_STATUS (ODOM_MCU -> HOST; 100 ms, one page per cycle; multiplexed by PAGE) ---
def pack_odom_status_summary(
    counter: int,
    state: int,
    integrator: int,
    error_mask: int,
    uptime_s: int,
    errors: ErrorMask,
    reason: int = 0,
) -> bytes:
    """ODOM_STATUS page 0: state, integrator, reason (saturated to the DBC range), the low 16
    bits of the error mask, uptime (s, saturated to u24)."""
    word = (
        e2e_head(counter, StatusPage.SUMMARY)
        | (sat_range(state, 0, 3, errors) << 16)
        | (sat_range(integrator, Integrator.EULER, Integrator.EXACT, errors) << 18)
        | (sat_range(reason, Reason.NONE, Reason.POSE_UNCERTAIN, errors) << 20)
        | (wrap_u16(error_mask) << 24)
        | (sat_range(uptime_s, 0, U24_MAX, errors) << 40)
    )
    return seal_frame(word, ODOM_STATUS_DATA_IDS)


def pack_odom_status_frame_totals(counter: int, lost: int, rejected: int, overflowed: int) -> bytes:
    """ODOM_STATUS page 1: frame totals, each keeping its low 16 bits (wrapping counters)."""
    word = (
        e2e_head(counter, StatusPage.FRAME_TOTALS)
        | (wrap_u16(lost) << 16)
        | (wrap_u16(rejected) << 32)
        | (wrap_u16(overflowed) << 48)
    )
    return seal_frame(word, ODOM_STATUS_DATA_IDS)


def pack_odom_status_e2e(
    counter: int, page: int, ok: int, lost: int, repeated: int, crc_error: int, wrong_sequence: int
) -> bytes:
    """ODOM_STATUS pages 2..: one received message's E2E counts; ``ok`` keeps 16 bits, the others
    8 bits (wrapping counters, e.g. from E2EReceiver: accepted(), lost_frames, count_*)."""
    word = (
        e2e_head(counter, page)
        | (wrap_u16(ok) << 16)
        | ((lost & 0xFF) << 32)
        | ((repeated & 0xFF) << 40)
        | ((crc_error & 0xFF) << 48)
        | ((wrong_sequence & 0xFF) << 56)
    )
    return seal_frame(word, ODOM_STATUS_DATA_IDS)


def pack_odom_status_profile(counter: int, max_wheel_speed_mm_s: int, profile_crc: int) -> bytes:
    """ODOM_STATUS page 6: the plausibility bound in use (u16 mm/s, as configured: an invalid
    configuration's value is shown as it is) and the CRC-32 of the parameter set the firmware
    runs with (``config.profile_crc32``)."""
    word = (
        e2e_head(counter, StatusPage.PROFILE)
        | (wrap_u16(max_wheel_speed_mm_s) << 16)
        | (wrap_u32(profile_crc) << 32)
    )
    return seal_frame(word, ODOM_STATUS_DATA_IDS)
