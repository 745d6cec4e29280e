"""E2E Profile 2: the firmware's CRC8H2F against cantools.autosar; the receiver state machine."""

from __future__ import annotations

import cantools.autosar
import pytest
from hypothesis import given
from hypothesis import strategies as st

from odocan.firmware.e2e import (
    CRC8H2F_CHECK,
    CRC8H2F_TABLE,
    MAX_DELTA_COUNTER_LIMIT,
    E2EReceiver,
    E2EStatus,
    crc8h2f,
    p02_crc,
)
from tests.host_frames import p02_next_counter, p02_protect

DATA_IDS = tuple(range(0x10, 0x20))
OTHER_DATA_IDS = tuple(range(0x20, 0x30))

# AUTOSAR SWS CRC Library, 7.2.1.2 (8-bit 0x2F polynomial CRC calculation): check values.
AUTOSAR_CRC8H2F_VECTORS = [
    ("00000000", 0x12),
    ("F20183", 0xC2),
    ("0FAA0055", 0xC6),
    ("00FF5511", 0x77),
    ("332255AABBCCDDEEFF", 0x11),
    ("926B55", 0x33),
    ("FFFFFFFF", 0x6C),
]


def frame(counter: int, payload: bytes = b"\x11\x22\x33\x44\x55\x66", ids=DATA_IDS) -> bytes:
    """A valid Profile 2 frame of ``counter`` (payload in bytes 2..7)."""
    buf = bytearray(b"\x00\xa0" + payload)
    p02_protect(buf, counter, ids)
    return bytes(buf)


# --- CRC ---


def test_check_value_is_0xdf() -> None:
    """CRC8H2F("123456789") = 0xDF (the AUTOSAR check value), and cantools agrees through its
    own Profile 2 function: payload bytes 1..7 = "12345678", data ID = ord("9")."""
    assert crc8h2f(b"123456789") == CRC8H2F_CHECK == 0xDF
    assert cantools.autosar.compute_profile2_crc(b"\x0012345678", ord("9")) == 0xDF


@pytest.mark.parametrize(("hex_data", "expected"), AUTOSAR_CRC8H2F_VECTORS)
def test_autosar_vectors(hex_data: str, expected: int) -> None:
    assert crc8h2f(bytes.fromhex(hex_data)) == expected


def gf2_mod(dividend: int, divisor: int) -> int:
    """Remainder of carry-less (GF(2)) polynomial division."""
    while dividend.bit_length() >= divisor.bit_length():
        dividend ^= divisor << (dividend.bit_length() - divisor.bit_length())
    return dividend


def test_table_is_x8_times_byte_mod_the_0x12f_polynomial() -> None:
    """Entry b is (b * x^8) mod (x^8 + x^5 + x^3 + x^2 + x + 1), by polynomial division."""
    assert tuple(gf2_mod(b << 8, 0x12F) for b in range(256)) == CRC8H2F_TABLE


@given(
    payload=st.binary(min_size=8, max_size=8),
    counter=st.integers(0, 15),
    ids=st.lists(st.integers(0, 255), min_size=16, max_size=16).map(tuple),
)
def test_protect_matches_cantools(payload: bytes, counter: int, ids: tuple[int, ...]) -> None:
    """p02_protect writes the counter nibble (keeping the high nibble) and cantools' CRC."""
    buf = bytearray(payload)
    p02_protect(buf, counter, ids)
    assert buf[1] == (payload[1] & 0xF0) | counter
    assert buf[2:] == payload[2:]
    assert buf[0] == cantools.autosar.compute_profile2_crc(bytes(buf), ids[counter])
    assert cantools.autosar.check_profile2_crc(bytes(buf), ids[counter]) is True
    assert p02_crc(buf, ids[counter]) == buf[0]


@given(payload=st.binary(min_size=8, max_size=8), data_id=st.integers(0, 255))
def test_crc_matches_cantools_on_any_frame(payload: bytes, data_id: int) -> None:
    assert p02_crc(payload, data_id) == cantools.autosar.compute_profile2_crc(payload, data_id)


@given(payload=st.binary(min_size=8, max_size=8), bit=st.integers(8, 63))
def test_every_single_bit_flip_is_detected(payload: bytes, bit: int) -> None:
    """A CRC8 detects every single-bit error in the protected bytes 1..7."""
    buf = bytearray(payload)
    p02_protect(buf, payload[1], DATA_IDS)
    buf[bit // 8] ^= 1 << (bit % 8)
    assert p02_crc(buf, DATA_IDS[buf[1] & 0xF]) != buf[0]


def test_next_counter_wraps_15_to_0() -> None:
    assert [p02_next_counter(c) for c in (0, 14, 15)] == [1, 15, 0]


# --- receiver ---


def statuses(rx: E2EReceiver, counters: list[int | None]) -> list[E2EStatus]:
    """Check a frame per counter (``None``: a period without a frame)."""
    return [rx.check(None if c is None else frame(c)) for c in counters]


def test_first_frame_after_init_is_accepted_whatever_its_counter() -> None:
    for start in (0, 7, 15):
        rx = E2EReceiver(DATA_IDS)
        assert rx.check(frame(start)) is E2EStatus.OK
        assert rx.last_valid_counter == start


def test_in_sequence_with_wrap_14_15_0() -> None:
    rx = E2EReceiver(DATA_IDS)
    counters: list[int | None] = [13, 14, 15, 0, 1]
    assert statuses(rx, counters) == [E2EStatus.OK] * 5
    assert rx.count_ok == 5
    assert rx.lost_frames == 0


def test_repeated_frame_is_reported_and_not_taken() -> None:
    rx = E2EReceiver(DATA_IDS)
    assert statuses(rx, [4, 5, 5, 6]) == [
        E2EStatus.OK,
        E2EStatus.OK,
        E2EStatus.REPEATED,
        E2EStatus.OK,
    ]
    assert rx.count_repeated == 1
    assert rx.count_ok == 3


def test_lost_frames_within_the_window_are_oksomelost() -> None:
    """MaxDeltaCounterInit 1: the next call accepts +1 and +2 (AUTOSAR's own example)."""
    rx = E2EReceiver(DATA_IDS, max_delta_counter_init=1)
    assert statuses(rx, [14, 0]) == [E2EStatus.OK, E2EStatus.OKSOMELOST]  # 15 lost, over the wrap
    assert rx.lost_data == 1
    assert rx.lost_frames == 1
    assert rx.count_oksomelost == 1
    assert statuses(rx, [1]) == [E2EStatus.OK]
    assert rx.lost_data == 0


def test_window_widens_by_one_per_check_call_without_a_valid_frame() -> None:
    """Two silent periods (check(None)) then +4: the window has grown to 4."""
    rx = E2EReceiver(DATA_IDS, max_delta_counter_init=1)
    assert statuses(rx, [0, None, None, 4]) == [
        E2EStatus.OK,
        E2EStatus.NONEWDATA,
        E2EStatus.NONEWDATA,
        E2EStatus.OKSOMELOST,
    ]
    assert rx.lost_frames == 3
    assert rx.count_nonewdata == 2


def test_jump_beyond_the_window_is_wrong_sequence() -> None:
    rx = E2EReceiver(DATA_IDS, max_delta_counter_init=1)
    assert statuses(rx, [0, 1, 4]) == [E2EStatus.OK, E2EStatus.OK, E2EStatus.WRONGSEQUENCE]
    assert rx.last_valid_counter == 1  # the reference is kept
    assert rx.check(frame(2)) is E2EStatus.OK  # a late in-sequence frame is still fine
    assert rx.count_wrongsequence == 1


def test_wrong_sequence_recovers_when_the_counter_comes_round() -> None:
    """No SyncCounter (R4.0): the reference stays, the sender is taken back at reference + 1."""
    rx = E2EReceiver(DATA_IDS, max_delta_counter_init=1)
    got = statuses(rx, [0, *range(5, 16), 0, 1])
    assert got == [E2EStatus.OK] + [E2EStatus.WRONGSEQUENCE] * 11 + [
        E2EStatus.REPEATED,
        E2EStatus.OK,
    ]


def test_larger_init_window_accepts_larger_jumps() -> None:
    rx = E2EReceiver(DATA_IDS, max_delta_counter_init=5)
    assert statuses(rx, [0, 6, 13]) == [
        E2EStatus.OK,
        E2EStatus.OKSOMELOST,
        E2EStatus.WRONGSEQUENCE,
    ]


def test_crc_error_wrong_data_id_and_bad_length_are_errors() -> None:
    rx = E2EReceiver(DATA_IDS)
    assert rx.check(frame(0)) is E2EStatus.OK
    corrupted = bytearray(frame(1))
    corrupted[5] ^= 0x04
    assert rx.check(bytes(corrupted)) is E2EStatus.ERROR
    assert rx.check(frame(1, ids=OTHER_DATA_IDS)) is E2EStatus.ERROR  # masquerade
    assert rx.check(frame(1)[:7]) is E2EStatus.ERROR
    assert rx.count_error == 3
    assert rx.last_valid_counter == 0
    assert rx.check(frame(1)) is E2EStatus.OK


def test_reset_waits_for_first_data_again() -> None:
    rx = E2EReceiver(DATA_IDS)
    statuses(rx, [0, 1])
    rx.reset()
    assert rx.check(frame(9)) is E2EStatus.OK
    assert rx.count_ok == 3  # counts survive a reset


def test_accepted_sums_ok_and_oksomelost() -> None:
    rx = E2EReceiver(DATA_IDS, max_delta_counter_init=3)
    statuses(rx, [0, 1, 3, 3, 4])
    assert rx.accepted() == 4


@given(
    events=st.lists(
        st.one_of(
            st.tuples(st.just("step"), st.integers(0, 15)),
            st.tuples(st.just("corrupt"), st.integers(8, 63)),
            st.tuples(st.just("silence"), st.just(0)),
        ),
        max_size=60,
    ),
    init=st.integers(1, 14),
)
def test_receiver_follows_the_autosar_rules(events: list[tuple[str, int]], init: int) -> None:
    """Against a model written from the SWS text: window = init + calls since the last accepted
    frame (max 15); delta 1 OK, 0 REPEATED, 2..window OKSOMELOST, beyond WRONGSEQUENCE."""
    rx = E2EReceiver(DATA_IDS, max_delta_counter_init=init)
    sent, last, window, first = 0, 0, 0, True
    for kind, arg in events:
        window = min(window + 1, 15)
        if kind == "silence":
            assert rx.check(None) is E2EStatus.NONEWDATA
            continue
        sent = (sent + arg) & 0xF
        data = bytearray(frame(sent))
        if kind == "corrupt":
            data[arg // 8] ^= 1 << (arg % 8)
            assert rx.check(bytes(data)) is E2EStatus.ERROR
            continue
        delta = (sent - last) & 0xF
        got = rx.check(bytes(data))
        if first or delta == 1:
            assert got is E2EStatus.OK
        elif delta == 0:
            assert got is E2EStatus.REPEATED
        elif delta <= window:
            assert got is E2EStatus.OKSOMELOST
            assert rx.lost_data == delta - 1
        else:
            assert got is E2EStatus.WRONGSEQUENCE
        if got in (E2EStatus.OK, E2EStatus.OKSOMELOST):
            first, last, window = False, sent, init


def test_new_periods_is_that_many_new_period_calls() -> None:
    """The ECU widens its encoder window once a tick by ``new_periods(n)`` (one saturating add);
    it must leave the receiver exactly as ``n`` calls of ``new_period`` would, from every window
    a receiver can hold (0..15) and for any count of periods, none included."""
    for window in range(MAX_DELTA_COUNTER_LIMIT + 1):
        for periods in range(2 * MAX_DELTA_COUNTER_LIMIT + 3):
            once = E2EReceiver(DATA_IDS, max_delta_counter_init=0, window_per_period=True)
            looped = E2EReceiver(DATA_IDS, max_delta_counter_init=0, window_per_period=True)
            once.max_delta_counter = looped.max_delta_counter = window
            once.new_periods(periods)
            for _ in range(periods):
                looped.new_period()
            assert once.max_delta_counter == looped.max_delta_counter == min(
                window + periods, MAX_DELTA_COUNTER_LIMIT
            ), (window, periods)
