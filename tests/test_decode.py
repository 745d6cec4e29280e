"""Bulk decoding and log reading against python-can and cantools.

* ``BulkDecoder`` equals cantools' ``decode_message(..., scaling=False)`` for every message and
  multiplexer page (hypothesis: raw values encoded by cantools), for a Motorola/signed layout, and
  for every frame of a real lockstep run.
* The candump parser equals ``can.LogReader`` on a file written by ``can.Logger``; it names the
  line of malformed input; ``.asc`` and ``.blf`` go through ``read_log`` too.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import cache
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from cantools.database.can import Database, Message
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.io.logs import FrameArrays, FrameCollector, LogFormatError, parse_candump, read_log
from odocan.host.protocol.decode import BulkDecoder
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests.dbc_typed import numbers

DB = database()
DECODER = BulkDecoder(DB)

MOTOROLA_DBC = """VERSION ""
BU_: A
BO_ 291 BIG: 8 A
 SG_ S12 : 7|12@0- (1,0) [-2048|2047] "-" A
 SG_ U20 : 11|20@0+ (1,0) [0|1048575] "-" A
 SG_ MIX : 32|9@1- (1,0) [-256|255] "-" A
 SG_ TOP : 55|16@0+ (1,0) [0|65535] "-" A
"""

# Layouts at the edges of the 64-bit word: full-width signals, signals ending at bit 63 (no mask
# after the shift), signed signals whose sign bit is bit 63, in both byte orders.
EDGE_DBC = """VERSION ""
BU_: A
BO_ 512 S64: 8 A
 SG_ S64 : 0|64@1- (1,0) [0|0] "-" A
BO_ 513 U64: 8 A
 SG_ U64 : 0|64@1+ (1,0) [0|0] "-" A
BO_ 514 TOPS: 8 A
 SG_ LOW : 0|40@1+ (1,0) [0|0] "-" A
 SG_ TOP : 40|24@1- (1,0) [0|0] "-" A
BO_ 515 MOTO64: 8 A
 SG_ M64 : 7|64@0- (1,0) [0|0] "-" A
BO_ 516 MOTOEND: 8 A
 SG_ HIGH : 7|1@0- (1,0) [0|0] "-" A
 SG_ REST : 6|55@0+ (1,0) [0|0] "-" A
 SG_ LAST : 63|8@0- (1,0) [0|0] "-" A
"""

# Extended multiplexing: SUB is itself a multiplexer, on page 0 of TOP only.
NESTED_DBC = """VERSION ""
BU_: A
BO_ 600 NEST: 8 A
 SG_ TOP M : 0|4@1+ (1,0) [0|15] "-" A
 SG_ SUB m0M : 4|4@1+ (1,0) [0|15] "-" A
 SG_ A m1 : 8|8@1+ (1,0) [0|255] "-" A
 SG_ B m2 : 8|8@1- (1,0) [0|0] "-" A
 SG_ C m1 : 16|16@1+ (1,0) [0|0] "-" A

SG_MUL_VAL_ 600 SUB TOP 0-0;
SG_MUL_VAL_ 600 A SUB 1-1;
SG_MUL_VAL_ 600 B SUB 2-2;
SG_MUL_VAL_ 600 C TOP 1-1;
"""


def pages(message: Message) -> list[int | None]:
    """Multiplexer values of a message's pages (None: not multiplexed)."""
    tree = message.signal_tree
    for node in tree:
        if isinstance(node, dict):
            return [*sorted(next(iter(node.values())).keys())]
    return [None]


KINDS = [(m.name, page) for m in DB.messages for page in pages(m)]


def raw_value(signal: cantools.database.can.Signal) -> st.SearchStrategy[int]:
    """Any raw value of the signal's width."""
    if signal.is_signed:
        return st.integers(-(1 << (signal.length - 1)), (1 << (signal.length - 1)) - 1)
    return st.integers(0, (1 << signal.length) - 1)


def encoded(
    db: Database, name: str, page: int | None, draw: Callable[[st.SearchStrategy[int]], int]
) -> bytes:
    """A frame of one page, encoded by cantools from drawn raw values."""
    message = db.get_message_by_name(name)
    values: dict[str, int] = {}
    for signal in message.signals:
        if signal.multiplexer_ids is None or page in signal.multiplexer_ids:
            values[signal.name] = draw(raw_value(signal))
        if signal.is_multiplexer:
            values[signal.name] = int(page) if page is not None else 0
    return bytes(db.encode_message(name, values, scaling=False, strict=False))


def as_frames(can_id: int, payloads: list[bytes], extended: bool = False) -> FrameArrays:
    """FrameArrays of data frames of one identifier."""
    collector = FrameCollector()
    for i, data in enumerate(payloads):
        collector.on_message_received(
            can.Message(timestamp=i * 0.01, arbitration_id=can_id, data=data,
                        is_extended_id=extended)
        )
    return collector.arrays()


def assert_same(db: Database, decoder: BulkDecoder, name: str, payloads: list[bytes]) -> None:
    """Bulk decode == cantools decode for every payload (the signals cantools returns)."""
    message = db.get_message_by_name(name)
    frames = as_frames(message.frame_id, payloads, message.is_extended_frame)
    bulk = decoder.decode(frames, name)
    assert list(bulk["index"]) == list(range(len(payloads)))
    for i, data in enumerate(payloads):
        expected = numbers(db, name, data, scaling=False)
        got = {key: int(bulk[key][i]) for key in expected}
        assert got == expected, (name, data.hex())


@pytest.mark.parametrize(("name", "page"), KINDS)
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_bulk_decoder_equals_cantools_on_every_page(
    name: str, page: int | None, data: st.DataObject
) -> None:
    payloads = [encoded(DB, name, page, data.draw) for _ in range(5)]
    assert_same(DB, DECODER, name, payloads)
    if page is not None:
        frames = as_frames(DB.get_message_by_name(name).frame_id, payloads)
        page_values = DECODER.decode_page(frames, name, page)
        expected = numbers(DB, name, payloads[0], scaling=False)
        assert set(page_values) - {"timestamp_s", "index"} == set(expected)


@settings(max_examples=200, deadline=None)
@given(payload=st.binary(min_size=8, max_size=8))
def test_bulk_decoder_big_endian_and_signed_layouts(payload: bytes) -> None:
    db = cantools.database.load_string(MOTOROLA_DBC, database_format="dbc")
    assert isinstance(db, Database)
    assert_same(db, BulkDecoder(db), "BIG", [payload])


@settings(max_examples=200, deadline=None)
@given(payload=st.binary(min_size=8, max_size=8))
def test_bulk_decoder_at_the_edges_of_the_word(payload: bytes) -> None:
    db = cantools.database.load_string(EDGE_DBC, database_format="dbc")
    assert isinstance(db, Database)
    decoder = BulkDecoder(db)
    for name in ("S64", "U64", "TOPS", "MOTO64", "MOTOEND"):
        assert_same(db, decoder, name, [payload, bytes(8), b"\xff" * 8])


@settings(max_examples=100, deadline=None)
@given(top=st.integers(0, 1), sub=st.integers(1, 2), rest=st.binary(min_size=7, max_size=7))
def test_a_page_of_a_nested_multiplexer_is_what_cantools_decodes(
    top: int, sub: int, rest: bytes
) -> None:
    """decode_page on frames of one (TOP, SUB) (the pages the DBC defines): exactly the
    signals and values cantools decodes."""
    db = cantools.database.load_string(NESTED_DBC, database_format="dbc")
    assert isinstance(db, Database)
    payload = bytes([top | sub << 4]) + rest
    frames = as_frames(600, [payload, payload])
    page = BulkDecoder(db).decode_page(frames, "NEST", top)
    expected = numbers(db, "NEST", payload, scaling=False)
    assert {key: int(value[1]) for key, value in page.items() if key not in
            ("timestamp_s", "index")} == expected


def test_the_decoder_s_kept_selection_is_read_only_and_belongs_to_one_frames() -> None:
    """What ``select`` keeps for the next call cannot be changed in place (numpy refuses), and
    other frames (the next chunk of a stream) get their own selection and values, not the kept
    ones; decoded values are the caller's own."""
    frames = rig_run()
    decoder = BulkDecoder(DB)
    first = decoder.select(frames, "WHEEL_ENCODERS")
    with pytest.raises(ValueError, match="read-only"):
        first[0] = 0
    decoded = decoder.decode(frames, "WHEEL_ENCODERS")
    decoded["LEFT_COUNT"][:] = 0
    again = decoder.decode(frames, "WHEEL_ENCODERS")
    assert np.any(again["LEFT_COUNT"] != 0)
    later = frames.select(np.arange(len(frames) // 2, len(frames)))
    part = decoder.decode(later, "WHEEL_ENCODERS")
    fresh = BulkDecoder(DB).decode(later, "WHEEL_ENCODERS")
    assert part.keys() == fresh.keys()
    for key, value in fresh.items():
        np.testing.assert_array_equal(part[key], value)
    assert 0 < len(part["index"]) < len(first)


@cache
def rig_run(seconds: float = 3.0) -> FrameArrays:
    """Every frame of a short lockstep run."""
    collector = FrameCollector()
    with LockstepRig(RigConfig(load("pmir"), "exact", "random", 7), [collector]) as rig:
        rig.run(seconds)
    return collector.arrays()


def test_bulk_decoder_equals_cantools_on_a_lockstep_run() -> None:
    frames = rig_run()
    checked = 0
    for message in DB.messages:
        bulk = DECODER.decode(frames, message.name)
        for i, position in enumerate(bulk["index"].tolist()):
            data = bytes(frames.data[position])
            expected = numbers(DB, message.frame_id, data, scaling=False)
            assert {key: int(bulk[key][i]) for key in expected} == expected
            checked += 1
    assert checked == len(frames)


# --- read_log -----------------------------------------------------------------------------------


def special_messages() -> list[can.Message]:
    """Frames the rig never sends: extended, remote, error, short, CAN FD, empty."""
    return [
        can.Message(timestamp=100.5, arbitration_id=0x1ABCDEF0, is_extended_id=True, data=b"\x01"),
        can.Message(timestamp=100.6, arbitration_id=0x123, is_extended_id=False,
                    is_remote_frame=True, dlc=4),
        can.Message(timestamp=100.7, is_error_frame=True),
        can.Message(timestamp=100.8, arbitration_id=0x7FF, is_extended_id=False, data=b""),
        can.Message(timestamp=100.9, arbitration_id=0x42, is_extended_id=False, is_fd=True,
                    data=b"\xaa\xbb\xcc"),
        can.Message(timestamp=1700000000.123456, arbitration_id=0x100, is_extended_id=False,
                    data=bytes(range(8)), is_rx=False),
    ]


def write_log(path: Path, frames: FrameArrays, extra: Sequence[can.Message] = ()) -> None:
    """Write frames (and extra messages) with python-can's own Logger."""
    with can.Logger(str(path)) as logger:
        for i in range(len(frames)):
            logger.on_message_received(
                can.Message(
                    timestamp=float(frames.timestamp_s[i]), arbitration_id=int(frames.can_id[i]),
                    is_extended_id=False, data=bytes(frames.data[i][: frames.dlc[i]]),
                    channel="vcan0",
                )
            )
        for msg in extra:
            logger.on_message_received(msg)


def via_log_reader(path: Path) -> FrameArrays:
    """python-can's reading of a log."""
    collector = FrameCollector()
    for msg in can.LogReader(str(path)):
        collector.on_message_received(msg)
    return collector.arrays()


def assert_frames_equal(a: FrameArrays, b: FrameArrays, timestamp_tol: float = 0.0) -> None:
    assert len(a) == len(b)
    np.testing.assert_array_equal(a.can_id, b.can_id)
    np.testing.assert_array_equal(a.dlc, b.dlc)
    np.testing.assert_array_equal(a.data, b.data)
    np.testing.assert_array_equal(a.flags, b.flags)
    if timestamp_tol == 0.0:
        np.testing.assert_array_equal(a.timestamp_s, b.timestamp_s)
    else:
        np.testing.assert_allclose(a.timestamp_s, b.timestamp_s, rtol=0, atol=timestamp_tol)


def test_candump_parser_equals_python_can(tmp_path: Path) -> None:
    path = tmp_path / "run.log"
    write_log(path, rig_run(), special_messages())
    ours = read_log(path)
    assert_frames_equal(ours, via_log_reader(path))
    assert len(ours) == len(rig_run()) + len(special_messages())


def test_candump_parser_takes_odd_but_valid_lines(tmp_path: Path) -> None:
    text = (
        "(1.000000) vcan0 100#0011223344556677 R\r\n"
        "\n"
        "  (1.5)   can1   1FF#AB   \n"
        "(2.25) 0 12345#\n"
        "(3.000000) vcan0 20000080#\n"
        "(4.000000) vcan0 123##1AABB T\n"
        "(5) vcan0 7FF#R8"  # no final newline
    )
    path = tmp_path / "odd.log"
    path.write_text(text)
    assert_frames_equal(read_log(path), via_log_reader(path))


def test_candump_parser_equal_length_lines_of_two_layouts(tmp_path: Path) -> None:
    """Lines of one length, one after the other (parsed in place as strided rows), in two
    layouts interleaved (the second layout's rows are copied out for the next template)."""
    lines = []
    for k in range(300):
        if k % 7 == 3:  # same length as the others, the fields elsewhere (the stamp in order:
            # one far off both neighbours is set aside, ``stampglitch``)
            lines.append(f"({k:04d}.000) vcan0 1{k % 100:02X}#00112233445566{k % 256:02X} R")
        else:
            lines.append(f"({k:04d}.123456) can1 2{k % 100:02X}#{k % 256:02X}112233445566 T")
    assert len({len(line) for line in lines}) == 1
    path = tmp_path / "two_layouts.log"
    path.write_text("\n".join(lines) + "\n")
    assert_frames_equal(read_log(path), via_log_reader(path))


@pytest.mark.parametrize(
    ("line", "what"),
    [
        ("(1.0) vcan0 100#00112G", "bad hex"),
        ("(1.0) vcan0 100#00112", "odd number of hex digits"),
        ("vcan0 100#0011", "field(s)"),
        ("1.0 vcan0 100#0011", "missing timestamp"),
        ("(1.0) vcan0 100#001122334455667788", "9 data bytes"),
        ("(1.0) vcan0 1000000000#00", "bad CAN ID"),
        ("(1.x) vcan0 100#00", "bad timestamp"),
        ("(1.0) vcan0 100-0011", "no '#'"),
    ],
)
def test_candump_parser_names_the_bad_line(tmp_path: Path, line: str, what: str) -> None:
    good = "(0.500000) vcan0 100#0011223344556677 R\n"
    path = tmp_path / "bad.log"
    path.write_text(good * 3 + line + "\n" + good)
    with pytest.raises(LogFormatError) as info:
        read_log(path)
    message = str(info.value)
    assert message.startswith(f"{path}:4: ")
    assert what in message
    assert "\n" not in message


def test_a_bad_line_deep_in_a_big_file_is_found() -> None:
    good = b"(0.500000) vcan0 100#0011223344556677 R\n"
    content = good * 5000 + b"(0.600000) vcan0 100#00112233445566ZZ R\n" + good * 10
    with pytest.raises(LogFormatError, match=r"^big.log:5001: bad hex"):
        parse_candump(content, "big.log")


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_asc_and_blf_round_trip(tmp_path: Path, suffix: str) -> None:
    frames = rig_run()
    path = tmp_path / f"run{suffix}"
    write_log(path, frames)
    back = read_log(path)
    assert_frames_equal(back, frames, timestamp_tol=2e-6)


def test_missing_and_empty_logs_are_one_line_errors(tmp_path: Path) -> None:
    with pytest.raises(LogFormatError, match="no such log file"):
        read_log(tmp_path / "nope.log")
    empty = tmp_path / "empty.log"
    empty.write_text("\n\n")
    with pytest.raises(LogFormatError, match="empty log"):
        read_log(empty)
    junk = tmp_path / "junk.blf"
    junk.write_bytes(b"not a blf file at all")
    with pytest.raises(LogFormatError, match=r"junk\.blf"):
        read_log(junk)
