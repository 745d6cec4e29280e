"""The bus contract: dbc/odocan.dbc loads cleanly in two independent parsers and keeps its rules."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import canmatrix.formats
import cantools
import pytest
from cantools.database.can import Message
from cantools.subparsers.dump.formatting import layout_string

from odocan.firmware import frames
from odocan.firmware.config import Integrator
from odocan.firmware.errors import State
from odocan.sim import frames as sf
from tests import host_frames as hf
from tests.dbc_typed import choices, dbc_attribute, load_can_dbc

ROOT = Path(__file__).resolve().parents[1]
DBC_PATH = ROOT / "dbc" / "odocan.dbc"
README_PATH = ROOT / "dbc" / "README.md"
NODES = {"MOTOR_CTRL", "ODOM_MCU", "HOST", "SIM"}
UPPER_SNAKE = re.compile(r"^[A-Z][A-Z0-9]*(_[A-Z0-9]+)*$")
RAW_FORMAT = re.compile(r"\b[ui]\d{1,2}\b")  # u4, u16, i32 ... in a signal comment
CYCLIC_SEND_TYPES = {"Cyclic", "CyclicIfActive"}
NAV_BLOCK = range(0x280, 0x300)  # navigation: only NAV_* messages live here
NAV_SLOTS = {"NAV_GOAL": 10, "NAV_STATUS": 11}  # the E2E slots kept for them from the start


@pytest.fixture(scope="module")
def db() -> cantools.database.can.Database:
    return load_can_dbc(DBC_PATH)


def send_type(message: Message) -> str:
    """The GenMsgSendType enum name of ``message``."""
    assert message.dbc is not None
    attribute = message.dbc.attributes["GenMsgSendType"]
    assert isinstance(attribute.value, int), attribute.value  # an ENUM attribute: the index
    return str(attribute.definition.choices[attribute.value])


def data_ids(message: Message) -> tuple[int, ...]:
    """The message's Profile 2 data-ID list from the ``E2EDataIDs`` attribute."""
    return tuple(int(v) for v in dbc_attribute(message, "E2EDataIDs").split(","))


def page_messages(message: Message) -> list[tuple[str, Message]]:
    """One message per multiplexer value, holding the signals of that page (for layouts)."""
    muxers = [s for s in message.signals if s.is_multiplexer]
    if not muxers:
        return [(message.name, message)]
    mux = muxers[0]
    assert mux.choices is not None, mux.name
    pages = []
    for value in sorted({v for s in message.signals for v in (s.multiplexer_ids or [])}):
        signals = [s for s in message.signals if s.multiplexer_ids in (None, [value])]
        title = f"{message.name}, {mux.name} = {value} ({mux.choices[value]})"
        pages.append((title, Message(message.frame_id, message.name, 8, signals, strict=True)))
    return pages


# --- loading ---


def test_loads_in_cantools_strict(db: cantools.database.can.Database) -> None:
    assert {m.name for m in db.messages} == {
        "WHEEL_ENCODERS",
        "MOTOR_CMD",
        "ODOM_POSE_X",
        "ODOM_POSE_Y",
        "ODOM_TWIST",
        "ODOM_SET_POSE",
        "ODOM_CONFIG",
        "ODOM_ACK",
        "ODOM_AUTH",
        "ODOM_FRESHNESS",
        "ODOM_STATUS",
        "SIM_TRUTH",
        "NAV_GOAL",
        "NAV_STATUS",
    }
    assert {n.name for n in db.nodes} == NODES


def load_canmatrix(
    path: Path, caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]
) -> tuple[canmatrix.CanMatrix | None, list[logging.LogRecord], str]:
    """Load with canmatrix, returning its matrix, every log record, and what it printed."""
    caplog.clear()
    capsys.readouterr()
    with caplog.at_level(logging.DEBUG):
        matrix = canmatrix.formats.loadp_flat(str(path))
    return matrix, list(caplog.records), capsys.readouterr().out


def test_loads_in_canmatrix_without_any_warning(
    caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]
) -> None:
    matrix, records, printed = load_canmatrix(DBC_PATH, caplog, capsys)
    assert matrix is not None
    assert [r.getMessage() for r in records] == []
    assert printed == ""
    assert len(matrix.frames) == 14


@pytest.mark.parametrize(
    "bad_line",
    ["BO_TX_BU_ 999 : HOST;", "VAL_TABLE_ T;"],
    ids=["printed-error", "debug-log"],
)
def test_canmatrix_capture_sees_a_broken_file(
    bad_line: str,
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Negative control: the capture above does see what canmatrix says about a bad line."""
    broken = tmp_path / "broken.dbc"
    broken.write_text(DBC_PATH.read_text() + "\n" + bad_line + "\n")
    _, records, printed = load_canmatrix(broken, caplog, capsys)
    assert records or printed


def test_canmatrix_reads_what_cantools_reads(
    db: cantools.database.can.Database,
    caplog: pytest.LogCaptureFixture,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Two independent parsers agree on every frame, signal, comment, cycle time and mux."""
    matrix, _, _ = load_canmatrix(DBC_PATH, caplog, capsys)
    assert matrix is not None
    for message in db.messages:
        frame = matrix.frame_by_id(canmatrix.ArbitrationId(message.frame_id))
        assert frame is not None
        assert frame.name == message.name
        assert frame.size == 8
        assert not frame.arbitration_id.extended
        assert sorted(frame.transmitters) == sorted(message.senders)
        assert int(frame.cycle_time) == (message.cycle_time or 0)
        got = {
            s.name: (
                s.start_bit,
                s.size,
                s.is_signed,
                s.unit,
                s.comment,
                s.mux_val,
                s.is_multiplexer,
            )
            for s in frame.signals
        }
        want = {
            s.name: (
                s.start,
                s.length,
                s.is_signed,
                s.unit,
                s.comment,
                s.multiplexer_ids[0] if s.multiplexer_ids else None,
                s.is_multiplexer,
            )
            for s in message.signals
        }
        assert got == want


# --- conventions ---


def test_names_nodes_and_frame_format(db: cantools.database.can.Database) -> None:
    for message in db.messages:
        assert UPPER_SNAKE.match(message.name)
        assert message.length == 8
        assert not message.is_extended_frame
        assert not message.is_fd
        assert message.frame_id <= 0x7FF
        assert (message.frame_id in NAV_BLOCK) == message.name.startswith("NAV_")
        assert set(message.senders) <= NODES
        assert message.senders
        assert message.comment
        for signal in message.signals:
            assert UPPER_SNAKE.match(signal.name)
            assert signal.byte_order == "little_endian"
            assert set(signal.receivers) <= NODES
            assert signal.receivers
    assert sorted(db.get_message_by_name("MOTOR_CMD").senders) == ["HOST", "ODOM_MCU"]


def test_every_signal_has_a_unit_and_a_comment_with_its_raw_format(
    db: cantools.database.can.Database,
) -> None:
    for message in db.messages:
        for signal in message.signals:
            assert signal.unit, f"{message.name}.{signal.name} has no unit"
            missing = f"{message.name}.{signal.name}: comment without a raw format"
            assert signal.comment, missing
            assert RAW_FORMAT.search(signal.comment), missing


def test_cyclic_messages_have_a_cycle_time_and_events_none(
    db: cantools.database.can.Database,
) -> None:
    for message in db.messages:
        if send_type(message) in CYCLIC_SEND_TYPES:
            assert message.cycle_time, message.name
            assert message.cycle_time > 0, message.name
        else:
            assert send_type(message) == "Event", message.name
            assert not message.cycle_time, message.name
    cycles = {m.name: m.cycle_time for m in db.messages}
    assert cycles["WHEEL_ENCODERS"] == 10
    assert cycles["ODOM_STATUS"] == 100
    assert cycles["MOTOR_CMD"] == cycles["ODOM_POSE_X"] == 20
    assert cycles["SIM_TRUTH"] == 100  # 10 Hz truth, as a motion-capture reference gives
    assert cycles["NAV_STATUS"] == 100
    assert send_type(db.get_message_by_name("NAV_GOAL")) == "Event"


def test_every_message_has_checksum_and_counter_at_the_profile2_bits(
    db: cantools.database.can.Database,
) -> None:
    for message in db.messages:
        checksum = message.get_signal_by_name("CHECKSUM")
        counter = message.get_signal_by_name("COUNTER")
        assert (checksum.start, checksum.length, checksum.is_signed) == (0, 8, False)
        assert (counter.start, counter.length, counter.is_signed) == (8, 4, False)
        assert checksum.multiplexer_ids is None
        assert counter.multiplexer_ids is None


def test_byte1_high_nibble_is_the_mux_or_the_echoed_counter(
    db: cantools.database.can.Database,
) -> None:
    """Multiplexers sit in byte 1's high nibble; pose and twist echo ENC_COUNTER there."""
    mux_names = {"ODOM_SET_POSE": "FIELD", "ODOM_CONFIG": "PARAM", "ODOM_STATUS": "PAGE"}
    mux_names["SIM_TRUTH"] = "PART"
    mux_names["NAV_GOAL"] = "FIELD"
    for message in db.messages:
        muxers = [s for s in message.signals if s.is_multiplexer]
        if message.name in mux_names:
            assert [(s.name, s.start, s.length) for s in muxers] == [
                (mux_names[message.name], 12, 4)
            ]
        else:
            assert muxers == []
    for name in ("ODOM_POSE_X", "ODOM_POSE_Y", "ODOM_TWIST"):
        enc = db.get_message_by_name(name).get_signal_by_name("ENC_COUNTER")
        assert (enc.start, enc.length) == (12, 4)
    enc = db.get_message_by_name("SIM_TRUTH").get_signal_by_name("ENC_COUNTER")
    assert enc.multiplexer_ids is None  # in every part


def test_encoders_and_commands_have_the_highest_priority(
    db: cantools.database.can.Database,
) -> None:
    ids = sorted((m.frame_id, m.name) for m in db.messages)
    assert [name for _, name in ids[:2]] == ["WHEEL_ENCODERS", "MOTOR_CMD"]


def test_enums_have_value_tables(db: cantools.database.can.Database) -> None:
    assert choices(db, "ODOM_STATUS", "STATE") == {
        0: "INIT",
        1: "OK",
        2: "DEGRADED",
        3: "FAULT",
    }
    expected_integrator = {0: "EULER", 1: "RK2", 2: "EXACT"}
    for name in ("ODOM_STATUS", "ODOM_CONFIG"):
        assert choices(db, name, "INTEGRATOR") == expected_integrator
    assert set(choices(db, "ODOM_ACK", "REASON").values()) >= {
        "OK",
        "OUT_OF_RANGE",
        "UNKNOWN_FIELD",
        "INCOMPLETE",
        "BUSY",
        "QUEUE_FULL",
    }
    assert choices(db, "ODOM_ACK", "REQUEST_ID") == {
        frames.NAV_GOAL_ID: "NAV_GOAL",
        frames.ODOM_SET_POSE_ID: "ODOM_SET_POSE",
        frames.ODOM_CONFIG_ID: "ODOM_CONFIG",
    }


def test_firmware_enums_match_the_value_tables(db: cantools.database.can.Database) -> None:
    pairs = [
        ("ODOM_SET_POSE", "FIELD", frames.SetPoseField),
        ("ODOM_CONFIG", "PARAM", frames.ConfigParam),
        ("ODOM_CONFIG", "INTEGRATOR", Integrator),
        ("ODOM_ACK", "RESULT", frames.AckResult),
        ("ODOM_ACK", "REASON", frames.AckReason),
        ("ODOM_STATUS", "PAGE", frames.StatusPage),
        ("ODOM_STATUS", "STATE", State),
        ("SIM_TRUTH", "PART", sf.SimTruthPart),
        ("NAV_GOAL", "FIELD", frames.NavGoalField),
        ("NAV_GOAL", "MODE", frames.NavMode),
        ("NAV_GOAL", "APPEND", hf.NavAppend),
        ("NAV_GOAL", "NO_FINAL_HEADING", hf.NavFinalHeading),
        ("NAV_STATUS", "STATE", frames.NavState),
    ]
    for message_name, signal_name, enum in pairs:
        assert choices(db, message_name, signal_name) == {
            int(member): member.name for member in enum
        }, f"{message_name}.{signal_name}"


# --- E2E data IDs ---


def test_data_id_lists_follow_the_slot_scheme_and_are_unique(
    db: cantools.database.can.Database,
) -> None:
    seen: set[int] = set()
    for message in db.messages:
        ids = data_ids(message)
        slot = ids[0] >> 4
        assert ids == tuple((slot << 4) | c for c in range(16)), message.name
        assert 1 <= slot <= 15
        assert (slot in NAV_SLOTS.values()) == message.name.startswith("NAV_")
        assert NAV_SLOTS.get(message.name, slot) == slot
        assert message.comment is not None, message.name
        assert f"E2E slot {slot} " in message.comment
        assert not seen & set(ids)
        seen |= set(ids)


def test_firmware_ids_and_data_ids_are_the_dbc_ones(db: cantools.database.can.Database) -> None:
    for message in db.messages:
        assert getattr(frames, f"{message.name}_ID") == message.frame_id
        if message.name != "SIM_TRUTH":  # the sim's, not the firmware's: sim.e2efacts reads it
            assert getattr(frames, f"{message.name}_DATA_IDS") == data_ids(message)
        assert hf.DATA_IDS_BY_FRAME_ID[message.frame_id] == data_ids(message)
    assert len(hf.DATA_IDS_BY_FRAME_ID) == len(db.messages)


# --- ranges ---


def test_every_raw_range_fits_its_bits(db: cantools.database.can.Database) -> None:
    """[min|max] divided by the scale lands on integers inside the signal's width."""
    for message in db.messages:
        for signal in message.signals:
            assert signal.offset == 0
            assert signal.minimum is not None
            assert signal.maximum is not None
            low = signal.minimum / signal.scale
            high = signal.maximum / signal.scale
            assert abs(low - round(low)) < 1e-3
            assert abs(high - round(high)) < 0.5
            lo_bits = -(1 << (signal.length - 1)) if signal.is_signed else 0
            hi_bits = (1 << (signal.length - (1 if signal.is_signed else 0))) - 1
            assert lo_bits <= round(low) <= round(high) <= hi_bits, f"{message.name}.{signal.name}"


def test_pose_resolutions(db: cantools.database.can.Database) -> None:
    x = db.get_message_by_name("ODOM_POSE_X").get_signal_by_name("X")
    heading = db.get_message_by_name("ODOM_POSE_X").get_signal_by_name("HEADING")
    assert x.scale == 0.0001
    assert x.length == 32
    assert x.maximum is not None
    assert x.maximum > 1000
    assert heading.scale <= 1e-4
    assert heading.length == 16
    assert not heading.is_signed
    assert abs(heading.scale * 65536 - 2 * 3.141592653589793) < 1e-12


# --- documentation ---


def test_readme_draws_every_frame_layout(db: cantools.database.can.Database) -> None:
    """dbc/README.md holds cantools' own layout drawing of every message (and of every page of a
    multiplexed one), as generated now from the DBC: the drawings cannot go stale."""
    readme = README_PATH.read_text()
    for message in db.messages:
        for title, page in page_messages(message):
            assert f"### {title}\n" in readme, title
            assert layout_string(page) in readme, f"layout of {title} is stale"


def readme_layouts(db: cantools.database.can.Database) -> str:
    """The layout section of dbc/README.md (run this module to print it)."""
    parts = []
    for message in sorted(db.messages, key=lambda m: m.frame_id):
        for title, page in page_messages(message):
            parts.append(f"### {title}\n\n```\n{layout_string(page)}\n```\n")
    return "\n".join(parts)


if __name__ == "__main__":
    print(readme_layouts(load_can_dbc(DBC_PATH)))
