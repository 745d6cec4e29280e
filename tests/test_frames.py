"""The hand-written frame codec against cantools (layouts) and cantools.autosar (CRC): the
firmware's half (firmware/frames.py, what the ECU receives and transmits), the sim's half
(sim/frames.py, what the motor controller and the simulator send and receive) and the host's half
(tests/host_frames.py, what a host sends it and reads from it).

For every message and every multiplexer page, over every signal's whole raw range:
firmware-packed bytes are exactly cantools-encoded bytes with the CRC applied by cantools.autosar,
cantools decodes them to the values packed, and the firmware unpacks cantools' frames to the
values encoded.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cantools
import cantools.autosar
import pytest
from cantools.database.can import Message, Signal
from cantools.database.can.formats.arxml.end_to_end_properties import AutosarEnd2EndProperties
from cantools.database.can.formats.arxml.message_specifics import AutosarMessageSpecifics
from hypothesis import given
from hypothesis import strategies as st

from odocan.firmware import frames as f
from odocan.firmware import secoc
from odocan.firmware.e2e import E2EReceiver, E2EStatus
from odocan.firmware.errors import ErrorFlag, ErrorMask
from odocan.sim import frames as sf
from tests import host_frames as hf
from tests.dbc_typed import dbc_attribute, load_can_dbc

DBC_PATH = Path(__file__).resolve().parents[1] / "dbc" / "odocan.dbc"
DB = load_can_dbc(DBC_PATH)

Values = dict[str, int]


def with_e2e(message: Message) -> Message:
    """Attach the DBC's E2EDataIDs to ``message`` the way cantools' ARXML loader would, so that
    cantools.autosar picks the data ID from the counter itself."""
    e2e = AutosarEnd2EndProperties()
    e2e.category = "PROFILE_02"
    e2e.data_ids = [int(v) for v in dbc_attribute(message, "E2EDataIDs").split(",")]
    e2e.payload_length = 8
    specifics = AutosarMessageSpecifics()
    specifics.e2e = e2e
    message.autosar = specifics
    return message


for _message in DB.messages:
    with_e2e(_message)


@dataclass(frozen=True)
class Kind:
    """One frame layout: a message, or one page of a multiplexed message."""

    message: str
    mux: int | None
    pack: Callable[[int, Values, ErrorMask], bytes]
    unpack: Callable[[bytes], Values]

    @property
    def id(self) -> str:
        return self.message if self.mux is None else f"{self.message}[{self.mux}]"


def as_signals(record: Any, names: dict[str, str]) -> Values:
    """A firmware record as {signal name: raw value}; ``names`` maps record field -> signal."""
    return {names.get(k, k.upper()): v for k, v in record._asdict().items()}


def mux_kind(message: str, mux: int, value_signal: str | None, pack: Any, unpack: Any) -> Kind:
    """A page of a generic multiplexed codec ``pack(counter, mux, value, errors)``."""
    muxer = next(s.name for s in DB.get_message_by_name(message).signals if s.is_multiplexer)

    def do_pack(counter: int, v: Values, errors: ErrorMask) -> bytes:
        return pack(counter, mux, v[value_signal] if value_signal else 0, errors)  # type: ignore[no-any-return]

    def do_unpack(data: bytes) -> Values:
        out = dict(unpack(data)._asdict())
        got = {"COUNTER": out.pop("counter"), muxer: out.pop(muxer.lower())}
        value = out.pop("value")
        if value_signal:
            got[value_signal] = value
        else:
            assert value == 0
        return got | {k.upper(): v for k, v in out.items()}

    return Kind(message, mux, do_pack, do_unpack)


def sim_truth_kind(part: int, signal: str) -> Kind:
    def do_pack(c: int, v: Values, e: ErrorMask) -> bytes:
        return sf.pack_sim_truth(c, part, v["ENC_COUNTER"], v[signal], e)

    def do_unpack(data: bytes) -> Values:
        r = hf.unpack_sim_truth(data)
        return {"COUNTER": r.counter, "PART": r.part, "ENC_COUNTER": r.enc_counter, signal: r.value}

    return Kind("SIM_TRUTH", part, do_pack, do_unpack)


NAV_GO_SIGNALS = {"mode": "MODE", "append": "APPEND", "no_final_heading": "NO_FINAL_HEADING"}
NAV_GO_SIGNALS["goal_id"] = "GOAL_ID"


def nav_goal_kind(field: int, signal: str | None) -> Kind:
    """A NAV_GOAL page: X/Y/HEADING carry ``signal``, STOP nothing, GO its four fields."""

    def do_pack(c: int, v: Values, e: ErrorMask) -> bytes:
        if field == f.NavGoalField.GO:
            return hf.pack_nav_goal_go(c, **{k: v[s] for k, s in NAV_GO_SIGNALS.items()}, errors=e)
        return hf.pack_nav_goal(c, field, v[signal] if signal else 0, e)

    def do_unpack(data: bytes) -> Values:
        r = f.unpack_nav_goal(data)
        got = {"COUNTER": r.counter, "FIELD": r.field}
        go = {s: getattr(r, k) for k, s in NAV_GO_SIGNALS.items()}
        if field == f.NavGoalField.GO:
            assert r.value == 0
            return got | go
        assert set(go.values()) == {0}
        return got | ({signal: r.value} if signal else {})

    return Kind("NAV_GOAL", field, do_pack, do_unpack)


STATUS_E2E_NAMES = {"ok": "OK", "lost": "LOST", "repeated": "REPEATED", "crc_error": "CRC_ERROR"}
STATUS_E2E_NAMES["wrong_sequence"] = "WRONG_SEQ"


def status_e2e_kind(page: int, prefix: str) -> Kind:
    def do_pack(c: int, v: Values, _e: ErrorMask) -> bytes:
        args = {k: v[f"{prefix}_E2E_{s}"] for k, s in STATUS_E2E_NAMES.items()}
        return f.pack_odom_status_e2e(c, page, **args)

    def do_unpack(data: bytes) -> Values:
        r = hf.unpack_odom_status(data)
        assert isinstance(r, hf.OdomStatusE2E)
        names = {k: f"{prefix}_E2E_{s}" for k, s in STATUS_E2E_NAMES.items()}
        return as_signals(r, names)

    return Kind("ODOM_STATUS", page, do_pack, do_unpack)


KINDS = [
    Kind(
        "WHEEL_ENCODERS",
        None,
        lambda c, v, e: sf.pack_wheel_encoders(
            c, v["LEFT_COUNT"], v["RIGHT_COUNT"], v["CTRL_UPTIME"], e
        ),
        lambda d: as_signals(f.unpack_wheel_encoders(d), {"ctrl_uptime_s": "CTRL_UPTIME"}),
    ),
    Kind(
        "MOTOR_CMD",
        None,
        lambda c, v, e: f.pack_motor_cmd(c, v["LEFT_SPEED"], v["RIGHT_SPEED"], e),
        lambda d: as_signals(
            sf.unpack_motor_cmd(d),
            {"left_speed_mm_s": "LEFT_SPEED", "right_speed_mm_s": "RIGHT_SPEED"},
        ),
    ),
    Kind(
        "ODOM_POSE_X",
        None,
        lambda c, v, e: f.pack_odom_pose_x(c, v["ENC_COUNTER"], v["X"], v["HEADING"], e),
        lambda d: as_signals(
            hf.unpack_odom_pose_x(d), {"x_100um": "X", "heading_bam16": "HEADING"}
        ),
    ),
    Kind(
        "ODOM_POSE_Y",
        None,
        lambda c, v, e: f.pack_odom_pose_y(c, v["ENC_COUNTER"], v["Y"], v["TURNS"], e),
        lambda d: as_signals(hf.unpack_odom_pose_y(d), {"y_100um": "Y"}),
    ),
    Kind(
        "ODOM_TWIST",
        None,
        lambda c, v, e: f.pack_odom_twist(
            c, v["ENC_COUNTER"], v["LINEAR_VEL"], v["ANGULAR_VEL"], v["DISTANCE"], e
        ),
        lambda d: as_signals(
            hf.unpack_odom_twist(d),
            {
                "linear_vel_mm_s": "LINEAR_VEL",
                "angular_vel_mrad_s": "ANGULAR_VEL",
                "distance_mm": "DISTANCE",
            },
        ),
    ),
    *(
        mux_kind("ODOM_SET_POSE", int(field), signal, hf.pack_odom_set_pose, f.unpack_odom_set_pose)
        for field, signal in [
            (f.SetPoseField.X, "X"),
            (f.SetPoseField.Y, "Y"),
            (f.SetPoseField.HEADING, "HEADING"),
            (f.SetPoseField.APPLY, None),
        ]
    ),
    *(
        mux_kind(
            "ODOM_CONFIG",
            int(param),
            None if param == f.ConfigParam.APPLY else param.name,
            hf.pack_odom_config,
            f.unpack_odom_config,
        )
        for param in f.ConfigParam
    ),
    Kind(
        "ODOM_ACK",
        None,
        lambda c, v, e: f.pack_odom_ack(
            c,
            v["REQUEST_COUNTER"],
            v["REQUEST_ID"],
            v["REQUEST_FIELD"],
            v["RESULT"],
            v["REASON"],
            e,
        ),
        lambda d: as_signals(hf.unpack_odom_ack(d), {}),
    ),
    Kind(
        "ODOM_AUTH",
        None,
        lambda c, v, e: hf.pack_odom_auth(c, v["REQUEST"], v["FRESHNESS"], v["AUTHENTICATOR"], e),
        lambda d: as_signals(f.unpack_odom_auth(d), {}),
    ),
    Kind(
        "ODOM_FRESHNESS",
        None,
        lambda c, v, e: f.pack_odom_freshness(
            c, v["CAUSE"], (v["FV_EPOCH"] << 28) | v["FV_COUNT"], e
        ),
        lambda d: {
            "COUNTER": (r := hf.unpack_odom_freshness(d)).counter,
            "CAUSE": r.cause,
            "FV_COUNT": r.fv & ((1 << 28) - 1),
            "FV_EPOCH": r.fv >> 28,
        },
    ),
    Kind(
        "ODOM_STATUS",
        0,
        lambda c, v, e: f.pack_odom_status_summary(
            c, v["STATE"], v["INTEGRATOR"], v["ERROR_MASK"], v["UPTIME"], e, v["REASON"]
        ),
        lambda d: as_signals(hf.unpack_odom_status(d), {"uptime_s": "UPTIME"}) | {"PAGE": 0},
    ),
    Kind(
        "ODOM_STATUS",
        1,
        lambda c, v, _e: f.pack_odom_status_frame_totals(
            c, v["LOST_FRAMES"], v["REJECTED_FRAMES"], v["OVERFLOWED_FRAMES"]
        ),
        lambda d: (
            as_signals(
                hf.unpack_odom_status(d),
                {
                    "lost": "LOST_FRAMES",
                    "rejected": "REJECTED_FRAMES",
                    "overflowed": "OVERFLOWED_FRAMES",
                },
            )
            | {"PAGE": 1}
        ),
    ),
    status_e2e_kind(2, "ENC"),
    status_e2e_kind(3, "SET_POSE"),
    status_e2e_kind(4, "CONFIG"),
    status_e2e_kind(5, "NAV_GOAL"),
    Kind(
        "ODOM_STATUS",
        6,
        lambda c, v, _e: f.pack_odom_status_profile(c, v["MAX_WHEEL_SPEED"], v["PROFILE_CRC"]),
        lambda d: as_signals(hf.unpack_odom_status(d), {}),
    ),
    *(
        nav_goal_kind(int(field), field.name if field <= f.NavGoalField.HEADING else None)
        for field in f.NavGoalField
    ),
    Kind(
        "NAV_STATUS",
        None,
        lambda c, v, e: f.pack_nav_status(
            c,
            v["STATE"],
            v["GOAL_ID"],
            v["QUEUE_DEPTH"],
            v["DISTANCE"],
            v["HEADING_ERROR"],
            e,
        ),
        lambda d: as_signals(
            hf.unpack_nav_status(d),
            {"distance_mm": "DISTANCE", "heading_error_bam16": "HEADING_ERROR"},
        ),
    ),
    sim_truth_kind(0, "X"),
    sim_truth_kind(1, "Y"),
    sim_truth_kind(2, "HEADING"),
]


def payload_signals(kind: Kind) -> list[Signal]:
    """The signals of ``kind`` other than the E2E header and the multiplexer."""
    message = DB.get_message_by_name(kind.message)
    return [
        s
        for s in message.signals
        if s.name not in ("CHECKSUM", "COUNTER")
        and not s.is_multiplexer
        and (s.multiplexer_ids is None or kind.mux in s.multiplexer_ids)
    ]


def raw_range(signal: Signal) -> tuple[int, int]:
    """The DBC [min|max] of ``signal`` in raw units."""
    assert signal.minimum is not None
    assert signal.maximum is not None
    return round(signal.minimum / signal.scale), round(signal.maximum / signal.scale)


def values_strategy(kind: Kind) -> st.SearchStrategy[Values]:
    """Every payload signal over its whole raw range (edges included by hypothesis)."""
    return st.fixed_dictionaries(
        {s.name: st.integers(*raw_range(s)) for s in payload_signals(kind)}
    )


def cantools_frame(kind: Kind, counter: int, values: Values) -> bytes:
    """cantools' encoding of ``values`` with the CRC applied by cantools.autosar."""
    message = DB.get_message_by_name(kind.message)
    data = dict(values, CHECKSUM=0, COUNTER=counter)
    if kind.mux is not None:
        muxer = next(s.name for s in message.signals if s.is_multiplexer)
        data[muxer] = kind.mux
    encoded = message.encode(data, scaling=False, strict=True)
    protected = cantools.autosar.apply_profile2_crc(encoded, message)
    assert protected is not None
    return bytes(protected)


def expected_signals(kind: Kind, counter: int, values: Values) -> Values:
    """What a decoder of this kind's frame should report (without CHECKSUM)."""
    message = DB.get_message_by_name(kind.message)
    out = dict(values, COUNTER=counter)
    if kind.mux is not None:
        out[next(s.name for s in message.signals if s.is_multiplexer)] = kind.mux
    return out


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.id)
@given(data=st.data(), counter=st.integers(0, 15))
def test_firmware_frames_are_cantools_frames(kind: Kind, data: st.DataObject, counter: int) -> None:
    values = data.draw(values_strategy(kind))
    errors = ErrorMask()
    packed = kind.pack(counter, values, errors)
    assert errors.bits == 0  # in range: nothing saturated
    message = DB.get_message_by_name(kind.message)
    assert packed == cantools_frame(kind, counter, values)
    assert cantools.autosar.check_profile2_crc(packed, message) is True
    decoded = message.decode(packed, decode_choices=False, scaling=False)
    assert isinstance(decoded, dict)  # not a container message
    decoded.pop("CHECKSUM")
    assert decoded == expected_signals(kind, counter, values)


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: k.id)
@given(data=st.data(), counter=st.integers(0, 15))
def test_firmware_unpacks_cantools_frames(kind: Kind, data: st.DataObject, counter: int) -> None:
    values = data.draw(values_strategy(kind))
    frame = cantools_frame(kind, counter, values)
    receiver = E2EReceiver(hf.DATA_IDS_BY_FRAME_ID[DB.get_message_by_name(kind.message).frame_id])
    assert receiver.check(frame) is E2EStatus.OK
    assert kind.unpack(frame) == expected_signals(kind, counter, values)


def test_every_message_and_page_is_covered() -> None:
    covered = {(k.message, k.mux) for k in KINDS}
    for message in DB.messages:
        muxers = [s for s in message.signals if s.is_multiplexer]
        if not muxers:
            assert (message.name, None) in covered
        else:
            pages = muxers[0].choices
            assert pages is not None, message.name
            for value in pages:
                assert (message.name, int(value)) in covered, (message.name, value)


# --- saturation and wrapping ---

SATURATING = [
    (k, s.name)
    for k in KINDS
    for s in payload_signals(k)
    if s.name not in ("ENC_COUNTER", "REQUEST_COUNTER", "REQUEST_FIELD", "TURNS", "ERROR_MASK")
    and not (k.message == "ODOM_STATUS" and k.mux != 0)
    and s.name not in ("LEFT_COUNT", "RIGHT_COUNT", "DISTANCE", "HEADING", "HEADING_ERROR")
    # SecOC: truncations of wider values (FV's low bits, the CMAC's first 32), by design
    and s.name not in ("FRESHNESS", "AUTHENTICATOR", "FV_COUNT", "FV_EPOCH")
] + [(k, "DISTANCE") for k in KINDS if k.message == "NAV_STATUS"]  # NAV_STATUS's saturates


def mid_values(kind: Kind) -> Values:
    """A valid value for every payload signal of ``kind`` (its range's lower end)."""
    return {s.name: raw_range(s)[0] for s in payload_signals(kind)}


@pytest.mark.parametrize(("kind", "signal"), SATURATING, ids=lambda x: getattr(x, "id", x))
@given(excess=st.integers(1, 1 << 40), above=st.booleans())
def test_out_of_range_saturates_to_the_dbc_limit(
    kind: Kind, signal: str, excess: int, above: bool
) -> None:
    """Beyond [min|max] the packer clamps to the DBC limit and sets SATURATION; never raises."""
    spec = DB.get_message_by_name(kind.message).get_signal_by_name(signal)
    low, high = raw_range(spec)
    values = mid_values(kind)
    values[signal] = high + excess if above else low - excess
    errors = ErrorMask()
    packed = kind.pack(3, values, errors)
    assert errors.has(ErrorFlag.SATURATION)
    assert kind.unpack(packed)[signal] == (high if above else low)


WRAPPING = [
    ("WHEEL_ENCODERS", None, "LEFT_COUNT", 24),
    ("WHEEL_ENCODERS", None, "RIGHT_COUNT", 24),
    ("ODOM_POSE_X", None, "HEADING", 16),
    ("ODOM_POSE_Y", None, "TURNS", 16),
    ("ODOM_TWIST", None, "DISTANCE", 16),
    ("ODOM_SET_POSE", 2, "HEADING", 16),
    ("ODOM_STATUS", 0, "ERROR_MASK", 16),
    ("ODOM_STATUS", 1, "LOST_FRAMES", 16),
    ("ODOM_STATUS", 2, "ENC_E2E_OK", 16),
    ("ODOM_STATUS", 3, "SET_POSE_E2E_LOST", 8),
    ("SIM_TRUTH", 2, "HEADING", 16),
    ("NAV_GOAL", 2, "HEADING", 16),
    ("NAV_STATUS", None, "HEADING_ERROR", 16),
    ("ODOM_STATUS", 5, "NAV_GOAL_E2E_WRONG_SEQ", 8),
    ("ODOM_STATUS", 6, "MAX_WHEEL_SPEED", 16),
    ("ODOM_STATUS", 6, "PROFILE_CRC", 32),
]


@pytest.mark.parametrize(("message", "mux", "signal", "bits"), WRAPPING)
@given(value=st.integers(0, (1 << 64) - 1))
def test_wrapping_fields_keep_their_low_bits(
    message: str, mux: int | None, signal: str, bits: int, value: int
) -> None:
    """Counters, angles and totals wrap by contract: the low bits, no saturation flag."""
    kind = next(k for k in KINDS if (k.message, k.mux) == (message, mux))
    values = mid_values(kind)
    values[signal] = value
    errors = ErrorMask()
    got = kind.unpack(kind.pack(0, values, errors))[signal]
    spec = DB.get_message_by_name(message).get_signal_by_name(signal)
    low_bits = value & ((1 << bits) - 1)
    expected = low_bits - (1 << bits) if spec.is_signed and low_bits >> (bits - 1) else low_bits
    assert got == expected
    assert errors.bits == 0


def test_fv_mask_is_the_dbc_fv_signals_and_the_secoc_fv_width() -> None:
    """One FV_MASK (firmware.frames): FV_COUNT and FV_EPOCH side by side in the DBC, and
    SecOC's FV = EPOCH << COUNT_BITS | COUNT."""
    message = DB.get_message_by_name("ODOM_FRESHNESS")
    count, epoch = (message.get_signal_by_name(name) for name in ("FV_COUNT", "FV_EPOCH"))
    assert (count.length, epoch.length) == (secoc.COUNT_BITS, secoc.EPOCH_BITS)
    assert count.start + count.length == epoch.start
    assert (1 << (count.length + epoch.length)) - 1 == f.FV_MASK
    assert not hasattr(secoc, "FV_MASK")


def test_counter_is_taken_mod_16() -> None:
    assert sf.pack_wheel_encoders(17, 5, 6) == sf.pack_wheel_encoders(1, 5, 6)
    assert f.unpack_wheel_encoders(sf.pack_wheel_encoders(15, 5, 6)).counter == 15


def test_unknown_pages_are_sent_raw_and_read_back() -> None:
    """The firmware NACKs an unknown FIELD/PARAM: the codec must carry one to it."""
    errors = ErrorMask()
    config = f.unpack_odom_config(hf.pack_odom_config(2, 9, 123_456, errors))
    assert (config.param, config.value) == (9, 123_456)
    pose = f.unpack_odom_set_pose(hf.pack_odom_set_pose(2, 7, 0xDEADBEEF, errors))
    assert (pose.field, pose.value) == (7, 0xDEADBEEF)
    assert errors.bits == 0
    goal = f.unpack_nav_goal(hf.pack_nav_goal(2, 9, 0xDEADBEEF, errors))
    assert (goal.field, goal.value) == (9, 0xDEADBEEF)
    assert errors.bits == 0


def test_nav_goal_go_reads_an_unknown_mode_raw() -> None:
    """MODE outside the DBC range reaches the firmware (which NACKs it OUT_OF_RANGE)."""
    frame = hf.pack_nav_goal(0, f.NavGoalField.GO, 0x2A07, ErrorMask())  # raw bits, not GO's packer
    goal = f.unpack_nav_goal(frame)
    assert (goal.field, goal.mode, goal.append, goal.no_final_heading, goal.goal_id) == (
        f.NavGoalField.GO,
        7,
        0,
        0,
        0x2A,
    )
