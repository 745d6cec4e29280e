"""The bridge's compiled per-frame decoder against cantools itself, on every message of the DBC."""

from __future__ import annotations

import math
from typing import Any

import cantools
import pytest
from cantools.database.errors import DecodeError
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.mqtt.livedecode import LiveDecoder, values_decoder
from odocan.sim.contract import database

DB = database()
MESSAGES = [m.name for m in DB.messages]


def _cantools(name: str, data: bytes) -> tuple[str, Any]:
    try:
        return "ok", DB.get_message_by_name(name).decode(data, decode_choices=False)
    except DecodeError:
        return "DecodeError", None


def _live(name: str, data: bytes) -> tuple[str, Any]:
    try:
        return "ok", LiveDecoder(DB.get_message_by_name(name)).decode(data)
    except DecodeError:
        return "DecodeError", None


def _same(a: tuple[str, Any], b: tuple[str, Any]) -> None:
    assert a[0] == b[0]
    if a[1] is None:
        return
    assert list(a[1]) == list(b[1])  # the same signals, in the same order
    for key, value in a[1].items():
        assert type(value) is type(b[1][key]), key
        assert value == b[1][key] or (math.isnan(value) and math.isnan(b[1][key])), key


@pytest.mark.parametrize("name", MESSAGES)
@settings(max_examples=300, deadline=None)
@given(data=st.binary(min_size=0, max_size=12))
def test_every_message_decodes_as_cantools_does(name: str, data: bytes) -> None:
    _same(_live(name, data), _cantools(name, data))


@pytest.mark.parametrize("name", MESSAGES)
@given(st.integers(min_value=0, max_value=15), st.binary(min_size=8, max_size=8))
def test_every_multiplexer_page_decodes_as_cantools_does(name: str, page: int, data: bytes) -> None:
    """Random payloads rarely hit a defined page: put each page value in the multiplexer."""
    message = DB.get_message_by_name(name)
    muxes = [s for s in message.signals if s.is_multiplexer]
    word = int.from_bytes(data, "little")
    for mux in muxes:
        mask = ((1 << mux.length) - 1) << mux.start
        word = (word & ~mask) | ((page << mux.start) & mask)
    payload = word.to_bytes(8, "little")
    _same(_live(name, payload), _cantools(name, payload))


def test_a_big_endian_or_float_message_is_decoded_by_cantools() -> None:
    db = cantools.database.load_string(
        'VERSION ""\nBS_:\nBU_: A\n'
        "BO_ 1 M: 8 A\n SG_ F : 0|32@1- (1,0) [0|0] \"\" A\n SG_ B : 39|8@0+ (2,1) [0|0] \"\" A\n"
        "SIG_VALTYPE_ 1 F : 1;\n",
        database_format="dbc",
    )
    assert isinstance(db, cantools.database.can.Database)
    message = db.get_message_by_name("M")
    data = bytes([0, 0, 0x80, 0x3F, 7, 0, 0, 0])
    assert LiveDecoder(message).decode(data) == message.decode(data, decode_choices=False)
    assert LiveDecoder(message).decode(data)["F"] == 1.0


@pytest.mark.parametrize("name", MESSAGES)
@settings(max_examples=200, deadline=None)
@given(data=st.binary(min_size=0, max_size=12), order=st.randoms(use_true_random=False))
def test_the_values_decoder_gives_cantools_values_in_the_order_asked(
    name: str, data: bytes, order: Any
) -> None:
    """Every signal of the message outside its multiplexed pages, in a drawn order, and one it
    lacks (its default): the tuple is cantools' values, of the same types; an undecodable
    payload is its DecodeError."""
    message = DB.get_message_by_name(name)
    names = [s.name for s in message.signals if not s.multiplexer_ids]
    order.shuffle(names)
    names.insert(order.randrange(len(names) + 1), "NOT_A_SIGNAL")
    expected = _cantools(name, data)
    try:
        got: tuple[str, Any] = ("ok", values_decoder(message, tuple(names),
                                                     {"NOT_A_SIGNAL": 7})(data))
    except DecodeError:
        got = ("DecodeError", None)
    assert got[0] == expected[0]
    if expected[1] is None:
        return
    want = tuple(7 if n == "NOT_A_SIGNAL" else expected[1][n] for n in names)
    assert len(got[1]) == len(want)
    for value, wanted in zip(got[1], want, strict=True):
        assert type(value) is type(wanted)
        assert value == wanted or (math.isnan(value) and math.isnan(wanted))
