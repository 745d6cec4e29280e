"""Hand-written codec of every odocan frame, as generated C would be (dbc/odocan.dbc: the contract).

Each frame is 8 bytes, Intel byte order, read as one little-endian ``uint64_t word``: a signal at
DBC start bit ``s`` of length ``n`` is ``(word >> s) & ((1 << n) - 1)``. Every frame starts with the
E2E Profile 2 header (firmware.e2e): CHECKSUM in bits 0-7, COUNTER in bits 8-11.

* ``pack_<msg>(counter, ..., errors) -> bytes``: 8 bytes, E2E protected with ``counter`` (taken
  mod 16). Raw integers only (X in units of 0.1 mm, heading as a u16 binary angle, ...). A value
  outside its signal's DBC ``[min|max]`` is saturated (fixmath.sat_range: sets SATURATION in
  ``errors``); fields that are wrapping by contract (counter low bits, angles, totals) are masked.
  Packers never raise.
* ``unpack_<msg>(data) -> record``: the raw fields. The CRC and counter are not checked here: run
  the message's ``firmware.e2e.E2EReceiver`` first and unpack only what it accepts.

Multiplexed messages (NAV_GOAL, ODOM_SET_POSE, ODOM_CONFIG, ODOM_STATUS, SIM_TRUTH) carry their
multiplexer
in byte 1's high nibble.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Final, NamedTuple

from odocan.firmware.config import Integrator
from odocan.firmware.e2e import COUNTER_MASK, DATA_ID_COUNT, p02_crc
from odocan.firmware.errors import ErrorMask, Reason
from odocan.firmware.fixmath import (
    I16_MAX,
    I16_MIN,
    I32_MAX,
    I32_MIN,
    U16_MAX,
    U32_MAX,
    i16,
    i32,
    sat_range,
    u8,
    u16,
    u32,
    u64,
    wrap_i16,
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
SIM_TRUTH_DATA_IDS: Final = _data_ids(15)

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
    SIM_TRUTH_ID: SIM_TRUTH_DATA_IDS,
}


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


class StatusPage(IntEnum):
    """ODOM_STATUS multiplexer ``PAGE``: 0 summary, 1 totals, 2.. E2E counts of one message each."""

    SUMMARY = 0
    FRAME_TOTALS = 1
    E2E_WHEEL_ENCODERS = 2
    E2E_ODOM_SET_POSE = 3
    E2E_ODOM_CONFIG = 4
    E2E_NAV_GOAL = 5


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


class NavAppend(IntEnum):
    """NAV_GOAL ``APPEND``."""

    REPLACE = 0
    APPEND = 1


class NavFinalHeading(IntEnum):
    """NAV_GOAL ``NO_FINAL_HEADING``."""

    TURN_TO_HEADING = 0
    ANY_HEADING = 1


class NavState(IntEnum):
    """NAV_STATUS ``STATE``."""

    IDLE = 0  # no goal since reset
    TURNING = 1  # turn-go-turn: rotating in place toward the goal
    DRIVING = 2  # driving to the goal position (either mode)
    FINAL_TURN = 3  # rotating in place to the goal's heading
    REACHED = 4  # the goal is reached (within tolerance); the motors are commanded to 0
    STOPPED = 5  # the host sent STOP: path cleared, motors commanded to 0
    ABORTED = 6  # the odometry stopped (encoders silent, fault): path cleared, motors to 0


class SimTruthPart(IntEnum):
    """SIM_TRUTH multiplexer ``PART``."""

    X = 0
    Y = 1
    HEADING = 2


# --- records returned by the unpackers (raw integers) ---
class WheelEncoders(NamedTuple):
    counter: int  # u4 E2E counter
    left_count: int  # u24: low 24 bits of the left hardware counter
    right_count: int  # u24


class MotorCmd(NamedTuple):
    counter: int
    left_speed_mm_s: i16
    right_speed_mm_s: i16


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


class OdomSetPose(NamedTuple):
    counter: int
    field: int  # SetPoseField
    value: int  # i32 for X/Y (0.1 mm), u16 bam16 for HEADING, 0 for APPLY, raw u32 otherwise


class OdomConfig(NamedTuple):
    counter: int
    param: int  # ConfigParam
    value: u32  # u32 parameters; u8 for COUNTER_BITS / INTEGRATOR; raw u32 otherwise


class OdomAuth(NamedTuple):
    counter: int  # u4 E2E counter of the ODOM_AUTH frame
    request: int  # u4 firmware.secoc.AuthRequest
    freshness: int  # u16: the low 16 bits of FV
    authenticator: int  # u32: MSB_32 of the CMAC tag


class OdomFreshness(NamedTuple):
    counter: int
    cause: int  # firmware.secoc.FreshnessCause
    fv: int  # u48: the firmware's last accepted FV (EPOCH << 28 | COUNT)


class OdomAck(NamedTuple):
    counter: int
    request_counter: int
    request_id: int
    request_field: int
    result: int  # AckResult
    reason: int  # AckReason


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


class NavGoal(NamedTuple):
    counter: int
    field: int  # NavGoalField
    value: int  # i32 for X/Y (0.1 mm), u16 bam16 for HEADING, 0 for STOP/GO, raw u32 otherwise
    mode: int  # u4 NavMode (GO only, else 0)
    append: int  # u1 NavAppend (GO only, else 0)
    no_final_heading: int  # u1 NavFinalHeading (GO only, else 0)
    goal_id: u8  # GO only, else 0


class NavStatus(NamedTuple):
    counter: int
    state: int  # NavState
    goal_id: u8
    queue_depth: u8
    distance_mm: u16
    heading_error_bam16: i16  # 2*pi/65536 rad, [-pi, pi)


class SimTruth(NamedTuple):
    counter: int
    part: int  # SimTruthPart
    enc_counter: int
    value: int  # i32 for X/Y (0.1 mm), u16 bam16 for HEADING, raw u32 otherwise


# --- the E2E header ---
def _head(counter: int, nibble: int) -> u64:
    """Bits 8..15 of the word: COUNTER (bits 8-11) and byte 1's high nibble (bits 12-15)."""
    return ((nibble & U4_MAX) << 12) | ((counter & COUNTER_MASK) << 8)


def _seal(word: u64, data_ids: tuple[u8, ...]) -> bytes:
    """The frame of ``word`` (CHECKSUM bits still 0) with its Profile 2 CRC in byte 0."""
    crc = p02_crc(word.to_bytes(8, "little"), data_ids[(word >> 8) & COUNTER_MASK])
    return (word | crc).to_bytes(8, "little")


def _word(data: bytes | bytearray) -> u64:
    """The frame as a little-endian ``uint64_t``."""
    return int.from_bytes(data, "little")


def _u32_field(value: int, errors: ErrorMask) -> u32:
    """A u32 signal: saturated to [0, U32_MAX]."""
    return sat_range(value, 0, U32_MAX, errors)


def _i32_field(value: int, errors: ErrorMask) -> u32:
    """An i32 signal as its 32 raw bits: saturated to the i32 range, then two's complement."""
    return wrap_u32(sat_range(value, I32_MIN, I32_MAX, errors))


def _i16_field(value: int, errors: ErrorMask) -> u16:
    """An i16 signal as its 16 raw bits: saturated to the i16 range, then two's complement."""
    return wrap_u16(sat_range(value, I16_MIN, I16_MAX, errors))


# --- WHEEL_ENCODERS (MOTOR_CTRL -> ODOM_MCU, HOST; 10 ms) ---
def pack_wheel_encoders(counter: int, left_count: int, right_count: int) -> bytes:
    """WHEEL_ENCODERS: the low 24 bits of each hardware counter (any width: wrapping, never
    saturated)."""
    word = _head(counter, 0) | ((left_count & U24_MAX) << 16) | ((right_count & U24_MAX) << 40)
    return _seal(word, WHEEL_ENCODERS_DATA_IDS)


def unpack_wheel_encoders(data: bytes | bytearray) -> WheelEncoders:
    """WHEEL_ENCODERS: u24 counts; extend them with the delta of the low 24 bits."""
    w = _word(data)
    return WheelEncoders((w >> 8) & U4_MAX, (w >> 16) & U24_MAX, (w >> 40) & U24_MAX)


# --- MOTOR_CMD (ODOM_MCU or HOST -> MOTOR_CTRL; 20 ms while commanding) ---
def pack_motor_cmd(
    counter: int, left_speed_mm_s: int, right_speed_mm_s: int, errors: ErrorMask
) -> bytes:
    """MOTOR_CMD: rim speed setpoints in mm/s, saturated to i16."""
    word = (
        _head(counter, 0)
        | (_i16_field(left_speed_mm_s, errors) << 16)
        | (_i16_field(right_speed_mm_s, errors) << 32)
    )
    return _seal(word, MOTOR_CMD_DATA_IDS)


def unpack_motor_cmd(data: bytes | bytearray) -> MotorCmd:
    """MOTOR_CMD: rim speed setpoints in mm/s."""
    w = _word(data)
    return MotorCmd((w >> 8) & U4_MAX, wrap_i16(w >> 16), wrap_i16(w >> 32))


# --- ODOM_POSE_X / ODOM_POSE_Y / ODOM_TWIST (ODOM_MCU -> HOST; 20 ms) ---
def pack_odom_pose_x(
    counter: int, enc_counter: int, x_100um: int, heading_bam16: int, errors: ErrorMask
) -> bytes:
    """ODOM_POSE_X: x (0.1 mm, saturated to i32) and heading (u16 binary angle, wraps)."""
    word = (
        _head(counter, enc_counter)
        | (_i32_field(x_100um, errors) << 16)
        | (wrap_u16(heading_bam16) << 48)
    )
    return _seal(word, ODOM_POSE_X_DATA_IDS)


def unpack_odom_pose_x(data: bytes | bytearray) -> OdomPoseX:
    """ODOM_POSE_X: x in 0.1 mm, heading as a u16 binary angle."""
    w = _word(data)
    return OdomPoseX((w >> 8) & U4_MAX, (w >> 12) & U4_MAX, wrap_i32(w >> 16), w >> 48)


def pack_odom_pose_y(
    counter: int, enc_counter: int, y_100um: int, turns: int, errors: ErrorMask
) -> bytes:
    """ODOM_POSE_Y: y (0.1 mm, saturated to i32) and whole heading turns (i16, wraps)."""
    word = (
        _head(counter, enc_counter) | (_i32_field(y_100um, errors) << 16) | (wrap_u16(turns) << 48)
    )
    return _seal(word, ODOM_POSE_Y_DATA_IDS)


def unpack_odom_pose_y(data: bytes | bytearray) -> OdomPoseY:
    """ODOM_POSE_Y: y in 0.1 mm, whole turns."""
    w = _word(data)
    return OdomPoseY((w >> 8) & U4_MAX, (w >> 12) & U4_MAX, wrap_i32(w >> 16), wrap_i16(w >> 48))


def pack_odom_twist(
    counter: int,
    enc_counter: int,
    linear_vel_mm_s: int,
    angular_vel_mrad_s: int,
    distance_mm: int,
    errors: ErrorMask,
) -> bytes:
    """ODOM_TWIST: velocities saturated to i16; distance (mm, any width) keeps its low 16 bits."""
    word = (
        _head(counter, enc_counter)
        | (_i16_field(linear_vel_mm_s, errors) << 16)
        | (_i16_field(angular_vel_mrad_s, errors) << 32)
        | (wrap_u16(distance_mm) << 48)
    )
    return _seal(word, ODOM_TWIST_DATA_IDS)


def unpack_odom_twist(data: bytes | bytearray) -> OdomTwist:
    """ODOM_TWIST: mm/s, mrad/s, and the low 16 bits of the distance in mm."""
    w = _word(data)
    return OdomTwist(
        (w >> 8) & U4_MAX,
        (w >> 12) & U4_MAX,
        wrap_i16(w >> 16),
        wrap_i16(w >> 32),
        (w >> 48) & U16_MAX,
    )


# --- ODOM_SET_POSE (HOST -> ODOM_MCU; event; multiplexed by FIELD) ---
def pack_odom_set_pose(counter: int, field: int, value: int, errors: ErrorMask) -> bytes:
    """ODOM_SET_POSE: one staged write. X/Y saturate to i32, HEADING wraps to u16, APPLY carries
    nothing (``value`` ignored); an unknown ``field`` sends ``value`` as raw u32 (tests)."""
    field &= U4_MAX
    if field in (SetPoseField.X, SetPoseField.Y):
        raw = _i32_field(value, errors)
    elif field == SetPoseField.HEADING:
        raw = wrap_u16(value)
    elif field == SetPoseField.APPLY:
        raw = 0
    else:
        raw = wrap_u32(value)
    return _seal(_head(counter, field) | (raw << 16), ODOM_SET_POSE_DATA_IDS)


def unpack_odom_set_pose(data: bytes | bytearray) -> OdomSetPose:
    """ODOM_SET_POSE: (counter, field, value) with value read per field (see OdomSetPose)."""
    w = _word(data)
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


# --- ODOM_CONFIG (HOST -> ODOM_MCU; event; multiplexed by PARAM) ---
_CONFIG_U8_LIMITS: Final[dict[int, tuple[int, int]]] = {
    ConfigParam.COUNTER_BITS: (16, 32),
    ConfigParam.INTEGRATOR: (Integrator.EULER, Integrator.EXACT),
}


def pack_odom_config(counter: int, param: int, value: int, errors: ErrorMask) -> bytes:
    """ODOM_CONFIG: one staged parameter. u32 parameters saturate to u32, COUNTER_BITS to
    [16, 32], INTEGRATOR to [0, 2]; APPLY carries nothing (``value`` ignored); an unknown
    ``param`` sends ``value`` as raw u32 (tests)."""
    param &= U4_MAX
    limits = _CONFIG_U8_LIMITS.get(param)
    if limits is not None:
        raw = sat_range(value, limits[0], limits[1], errors)
    elif param == ConfigParam.APPLY:
        raw = 0
    elif param <= ConfigParam.WHEELBASE:
        raw = _u32_field(value, errors)
    else:
        raw = wrap_u32(value)
    return _seal(_head(counter, param) | (raw << 16), ODOM_CONFIG_DATA_IDS)


def unpack_odom_config(data: bytes | bytearray) -> OdomConfig:
    """ODOM_CONFIG: (counter, param, value) with value read per parameter (see OdomConfig)."""
    w = _word(data)
    param = (w >> 12) & U4_MAX
    value = (w >> 16) & U32_MAX
    if param in _CONFIG_U8_LIMITS:
        value &= 0xFF
    elif param == ConfigParam.APPLY:
        value = 0
    return OdomConfig((w >> 8) & U4_MAX, param, value)


# --- NAV_GOAL (HOST -> ODOM_MCU; event; multiplexed by FIELD) ---
def pack_nav_goal(counter: int, field: int, value: int, errors: ErrorMask) -> bytes:
    """NAV_GOAL X, Y, HEADING or STOP: X/Y saturate to i32 (0.1 mm), HEADING wraps to u16, STOP
    carries nothing; GO goes through ``pack_nav_goal_go``; any other ``field`` (GO included)
    sends ``value`` as raw u32 (tests)."""
    field &= U4_MAX
    if field in (NavGoalField.X, NavGoalField.Y):
        raw = _i32_field(value, errors)
    elif field == NavGoalField.HEADING:
        raw = wrap_u16(value)
    elif field == NavGoalField.STOP:
        raw = 0
    else:
        raw = wrap_u32(value)
    return _seal(_head(counter, field) | (raw << 16), NAV_GOAL_DATA_IDS)


def pack_nav_goal_go(
    counter: int, mode: int, append: int, no_final_heading: int, goal_id: int, errors: ErrorMask
) -> bytes:
    """NAV_GOAL GO: commit the staged goal. MODE saturates to [0, 1], the flags to one bit,
    GOAL_ID to u8."""
    word = (
        _head(counter, NavGoalField.GO)
        | (sat_range(mode, NavMode.TURN_GO_TURN, NavMode.GO_TO_GOAL, errors) << 16)
        | (sat_range(append, 0, 1, errors) << 20)
        | (sat_range(no_final_heading, 0, 1, errors) << 21)
        | (sat_range(goal_id, 0, 0xFF, errors) << 24)
    )
    return _seal(word, NAV_GOAL_DATA_IDS)


def unpack_nav_goal(data: bytes | bytearray) -> NavGoal:
    """NAV_GOAL: the record with ``value`` read per field and GO's fields (raw: MODE is not
    range-checked here; the receiver answers OUT_OF_RANGE)."""
    w = _word(data)
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
        _head(counter, sat_range(state, NavState.IDLE, NavState.ABORTED, errors))
        | (sat_range(goal_id, 0, 0xFF, errors) << 16)
        | (sat_range(queue_depth, 0, NAV_QUEUE_DEPTH_MAX, errors) << 24)
        | (sat_range(distance_mm, 0, U16_MAX, errors) << 32)
        | (wrap_u16(heading_error_bam16) << 48)
    )
    return _seal(word, NAV_STATUS_DATA_IDS)


def unpack_nav_status(data: bytes | bytearray) -> NavStatus:
    """NAV_STATUS: state, goal, queue depth, distance in mm, heading error in BAM16."""
    w = _word(data)
    return NavStatus(
        (w >> 8) & U4_MAX,
        (w >> 12) & U4_MAX,
        (w >> 16) & 0xFF,
        (w >> 24) & 0xFF,
        (w >> 32) & U16_MAX,
        wrap_i16(w >> 48),
    )


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
        _head(counter, request_counter)
        | (sat_range(request_id, 0, CAN_ID_MAX, errors) << 16)
        | ((request_field & U4_MAX) << 32)
        | (sat_range(result, AckResult.ACK, AckResult.NACK, errors) << 36)
        | (sat_range(reason, AckReason.OK, AckReason.AUTH_UNAVAILABLE, errors) << 40)
    )
    return _seal(word, ODOM_ACK_DATA_IDS)


def unpack_odom_ack(data: bytes | bytearray) -> OdomAck:
    """ODOM_ACK: which request, ACK/NACK and the reason."""
    w = _word(data)
    return OdomAck(
        (w >> 8) & U4_MAX,
        (w >> 12) & U4_MAX,
        (w >> 16) & U16_MAX,
        (w >> 32) & U4_MAX,
        (w >> 36) & 1,
        (w >> 40) & 0xFF,
    )


# --- ODOM_AUTH (HOST -> ODOM_MCU; event, after each secured command frame) ---
FV_MASK: Final = (1 << 48) - 1  # the u48 freshness value


def pack_odom_auth(
    counter: int, request: int, freshness: int, mac: int, errors: ErrorMask
) -> bytes:
    """ODOM_AUTH: REQUEST (byte 1 high nibble), FRESHNESS (bytes 2-3), AUTHENTICATOR (4-7)."""
    word = (
        _head(counter, sat_range(request, 0, 2, errors))
        | ((freshness & U16_MAX) << 16)
        | ((mac & U32_MAX) << 32)
    )
    return _seal(word, ODOM_AUTH_DATA_IDS)


def unpack_odom_auth(data: bytes | bytearray) -> OdomAuth:
    """ODOM_AUTH's raw fields (run its E2E check first)."""
    w = _word(data)
    return OdomAuth((w >> 8) & U4_MAX, (w >> 12) & U4_MAX, (w >> 16) & U16_MAX, (w >> 32) & U32_MAX)


# --- ODOM_FRESHNESS (ODOM_MCU -> HOST; 1000 ms and on events) ---
def pack_odom_freshness(counter: int, cause: int, fv: int, errors: ErrorMask) -> bytes:
    """ODOM_FRESHNESS: CAUSE (byte 1 high nibble), FV (u48: COUNT bits 16-43, EPOCH 44-63)."""
    word = _head(counter, sat_range(cause, 0, 4, errors)) | ((fv & FV_MASK) << 16)
    return _seal(word, ODOM_FRESHNESS_DATA_IDS)


def unpack_odom_freshness(data: bytes | bytearray) -> OdomFreshness:
    """ODOM_FRESHNESS's raw fields."""
    w = _word(data)
    return OdomFreshness((w >> 8) & U4_MAX, (w >> 12) & U4_MAX, (w >> 16) & FV_MASK)


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
        _head(counter, StatusPage.SUMMARY)
        | (sat_range(state, 0, 3, errors) << 16)
        | (sat_range(integrator, Integrator.EULER, Integrator.EXACT, errors) << 18)
        | (sat_range(reason, Reason.NONE, Reason.CONFIG_INVALID, errors) << 20)
        | (wrap_u16(error_mask) << 24)
        | (sat_range(uptime_s, 0, U24_MAX, errors) << 40)
    )
    return _seal(word, ODOM_STATUS_DATA_IDS)


def pack_odom_status_frame_totals(counter: int, lost: int, rejected: int, overflowed: int) -> bytes:
    """ODOM_STATUS page 1: frame totals, each keeping its low 16 bits (wrapping counters)."""
    word = (
        _head(counter, StatusPage.FRAME_TOTALS)
        | (wrap_u16(lost) << 16)
        | (wrap_u16(rejected) << 32)
        | (wrap_u16(overflowed) << 48)
    )
    return _seal(word, ODOM_STATUS_DATA_IDS)


def pack_odom_status_e2e(
    counter: int, page: int, ok: int, lost: int, repeated: int, crc_error: int, wrong_sequence: int
) -> bytes:
    """ODOM_STATUS pages 2..: one received message's E2E counts; ``ok`` keeps 16 bits, the others
    8 bits (wrapping counters, e.g. from E2EReceiver: accepted(), lost_frames, count_*)."""
    word = (
        _head(counter, page)
        | (wrap_u16(ok) << 16)
        | ((lost & 0xFF) << 32)
        | ((repeated & 0xFF) << 40)
        | ((crc_error & 0xFF) << 48)
        | ((wrong_sequence & 0xFF) << 56)
    )
    return _seal(word, ODOM_STATUS_DATA_IDS)


def unpack_odom_status(
    data: bytes | bytearray,
) -> OdomStatusSummary | OdomStatusFrameTotals | OdomStatusE2E:
    """ODOM_STATUS: the record of the page carried (pages >= 2 all share the E2E layout)."""
    w = _word(data)
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
    return OdomStatusE2E(
        counter,
        page,
        (w >> 16) & U16_MAX,
        (w >> 32) & 0xFF,
        (w >> 40) & 0xFF,
        (w >> 48) & 0xFF,
        w >> 56,
    )


# --- SIM_TRUTH (SIM -> HOST; the three parts every 20 ms; multiplexed by PART) ---
def pack_sim_truth(
    counter: int, part: int, enc_counter: int, value: int, errors: ErrorMask
) -> bytes:
    """SIM_TRUTH: one part. X/Y saturate to i32 (0.1 mm), HEADING wraps to u16; an unknown
    ``part`` sends ``value`` as raw u32."""
    part &= U4_MAX
    if part in (SimTruthPart.X, SimTruthPart.Y):
        raw = _i32_field(value, errors)
    elif part == SimTruthPart.HEADING:
        raw = wrap_u16(value)
    else:
        raw = wrap_u32(value)
    word = _head(counter, part) | ((enc_counter & U4_MAX) << 16) | (raw << 24)
    return _seal(word, SIM_TRUTH_DATA_IDS)


def unpack_sim_truth(data: bytes | bytearray) -> SimTruth:
    """SIM_TRUTH: (counter, part, enc_counter, value) with value read per part (see SimTruth)."""
    w = _word(data)
    part = (w >> 12) & U4_MAX
    raw = (w >> 24) & U32_MAX
    if part in (SimTruthPart.X, SimTruthPart.Y):
        value = wrap_i32(raw)
    elif part == SimTruthPart.HEADING:
        value = raw & U16_MAX
    else:
        value = raw
    return SimTruth((w >> 8) & U4_MAX, part, (w >> 16) & U4_MAX, value)
