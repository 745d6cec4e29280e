"""The ``odocan`` transport (``sim.transport``): a wire's semantics, python-can ``virtual``'s
behaviour message for message, the plugin found by name, python-can's own tools on it."""

from __future__ import annotations

import itertools
import sys
import threading
import time
import tomllib
from collections.abc import Iterator
from importlib import import_module
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

import can
import can.player
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.sim import canbits, transport
from odocan.sim.transport import OdocanBus

ROOT = Path(__file__).resolve().parent.parent
_channels = iter(range(1 << 30))


@pytest.fixture
def channel() -> str:
    """A channel name no other test uses."""
    return f"test-transport-{next(_channels)}"


def _msg(can_id: int = 0x123, data: bytes = b"\x01\x02\x03", ts: float = 1.5) -> can.Message:
    return can.Message(timestamp=ts, arbitration_id=can_id, is_extended_id=False, data=data)


def _drain(bus: can.BusABC) -> list[can.Message]:
    out = []
    while (msg := bus.recv(0)) is not None:
        out.append(msg)
    return out


@pytest.fixture
def three(channel: str) -> Iterator[tuple[OdocanBus, OdocanBus, OdocanBus]]:
    """Three handles on one wire: a plain sender, a plain receiver, one that hears itself."""
    buses = (
        OdocanBus(channel, preserve_timestamps=True),
        OdocanBus(channel, preserve_timestamps=True),
        OdocanBus(channel, preserve_timestamps=True, receive_own_messages=True),
    )
    yield buses
    for bus in buses:
        bus.shutdown()


# --- a wire's semantics ----------------------------------------------------------------------


def test_every_other_handle_receives_and_only_the_asking_sender_hears_itself(
    three: tuple[OdocanBus, OdocanBus, OdocanBus], channel: str
) -> None:
    a, b, c = three
    a.send(_msg(0x10))
    c.send(_msg(0x20))
    assert [m.arbitration_id for m in _drain(a)] == [0x20]
    assert [(m.arbitration_id, m.is_rx) for m in _drain(b)] == [(0x10, True), (0x20, True)]
    assert [(m.arbitration_id, m.is_rx) for m in _drain(c)] == [(0x10, True), (0x20, False)]
    a.send(_msg(0x30))
    assert all(m.channel == channel for m in _drain(b))


def _fields(msg: can.Message) -> tuple[object, ...]:
    return (msg.timestamp, msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame,
            msg.is_error_frame, msg.channel, msg.dlc, bytes(msg.data), msg.is_fd, msg.is_rx,
            msg.bitrate_switch, msg.error_state_indicator)


@pytest.mark.parametrize("bitrate", [None, 500_000])
def test_send_data_delivers_what_send_of_the_same_frame_delivers(
    bitrate: int | None, channel: str
) -> None:
    """``send_data(id, data, t)`` (the rig's nodes) against ``send(data_frame(t, id, data))``:
    every field of every receiver's message, the sender's echo and a receiver's filter."""
    heard: dict[str, list[tuple[object, ...]]] = {}
    for way in ("send", "send_data"):
        name = channel  # one wire at a time: every handle closes before the next way
        kw: dict[str, Any] = {"preserve_timestamps": True, "bitrate": bitrate}
        kw["clock"] = lambda: 10.0  # bit-timed: every frame has ended by then
        sender = OdocanBus(name, receive_own_messages=True, **kw)
        plain = OdocanBus(name, **kw)
        picky = OdocanBus(name, can_filters=[{"can_id": 0x20, "can_mask": 0x7FF}], **kw)
        frames = ((0x10, b"\x01\x02", 1.5), (0x20, b"", 2.0), (0x7FF, b"x" * 8, 3.0))
        for can_id, data, t_s in frames:
            if way == "send":
                sender.send(transport.data_frame(t_s, can_id, data))
            else:
                sender.send_data(can_id, data, t_s)
        heard[way] = [_fields(m) for bus in (sender, plain, picky) for m in _drain(bus)]
        for bus in (sender, plain, picky):
            bus.shutdown()
    assert len(heard["send"]) == 3 + 3 + 1
    assert heard["send_data"] == heard["send"]


def test_no_receiver_shares_a_mutable_message(
    three: tuple[OdocanBus, OdocanBus, OdocanBus],
) -> None:
    a, b, c = three
    sent = _msg(data=b"\xaa" * 8)
    a.send(sent)
    got_b, got_c = b.recv(0), c.recv(0)
    assert got_b is not None
    assert got_c is not None
    assert got_b is not got_c
    assert got_b is not sent
    assert got_b.data is not got_c.data
    assert got_b.data is not sent.data
    got_b.data[0] = 0
    got_b.arbitration_id = 0x7FF
    assert got_c.data == bytearray(b"\xaa" * 8)
    assert got_c.arbitration_id == 0x123
    assert sent.data == bytearray(b"\xaa" * 8)
    sent.data[1] = 0  # the sender reusing its buffer changes nothing already on the wire
    assert got_c.data == bytearray(b"\xaa" * 8)


def test_timestamps_as_python_can_virtual(channel: str) -> None:
    with OdocanBus(channel, preserve_timestamps=True) as tx, OdocanBus(channel) as rx:
        tx.send(_msg(ts=12.25))
        assert rx.recv(0).timestamp == 12.25  # type: ignore[union-attr]
    with OdocanBus(channel) as tx, OdocanBus(channel) as rx:
        before = time.time()
        tx.send(_msg(ts=12.25))
        after = time.time()
        stamp = rx.recv(0).timestamp  # type: ignore[union-attr]
        assert before <= stamp <= after


def test_channels_are_separate_wires_and_order_is_kept(channel: str) -> None:
    with (
        OdocanBus(channel) as tx,
        OdocanBus(channel) as rx,
        OdocanBus(channel + "-other") as elsewhere,
    ):
        for i in range(100):
            tx.send(_msg(i))
        assert [m.arbitration_id for m in _drain(rx)] == list(range(100))
        assert elsewhere.recv(0) is None


def test_a_bounded_queue_drops_the_oldest_and_counts_it(channel: str) -> None:
    with OdocanBus(channel) as tx, OdocanBus(channel, rx_queue_size=3) as rx:
        for i in range(5):
            tx.send(_msg(i))
        assert [m.arbitration_id for m in _drain(rx)] == [2, 3, 4]
        assert rx.rx_overruns == 2
    with pytest.raises(ValueError, match="rx_queue_size"):
        OdocanBus(channel, rx_queue_size=-1)


def test_software_filters_apply(channel: str) -> None:
    filters: can.typechecking.CanFilters = [{"can_id": 0x100, "can_mask": 0x700}]
    with OdocanBus(channel) as tx, OdocanBus(channel, can_filters=filters) as rx:
        for can_id in (0x0FF, 0x100, 0x1AB, 0x200):
            tx.send(_msg(can_id))
        assert [m.arbitration_id for m in _drain(rx)] == [0x100, 0x1AB]
        tx.send(_msg(0x300))
        assert rx.recv(0.01) is None


def test_recv_waits_for_a_frame_from_another_thread(channel: str) -> None:
    with OdocanBus(channel) as tx, OdocanBus(channel) as rx:
        assert rx.recv(0.02) is None
        timer = threading.Timer(0.05, tx.send, (_msg(0x42),))
        timer.start()
        got = rx.recv(5.0)
        timer.join()
        assert got is not None
        assert got.arbitration_id == 0x42


def test_shutdown_wakes_a_blocked_receiver_and_closes_the_handle(channel: str) -> None:
    tx = OdocanBus(channel)
    rx = OdocanBus(channel)
    result: list[can.Message | None] = [_msg()]
    waiter = threading.Thread(target=lambda: result.__setitem__(0, rx.recv(None)))
    waiter.start()
    time.sleep(0.05)
    rx.shutdown()
    waiter.join(5.0)
    assert not waiter.is_alive()
    assert result == [None]
    tx.send(_msg())  # a closed handle is off the wire: nobody left to receive, no error
    with pytest.raises(can.CanOperationError):
        rx.send(_msg())
    with pytest.raises(can.CanOperationError):
        rx.recv(0)
    tx.shutdown()
    assert channel not in {c["channel"] for c in OdocanBus._detect_available_configs()}


def test_a_notifier_hands_every_frame_to_its_listeners(channel: str) -> None:
    with OdocanBus(channel) as tx, OdocanBus(channel) as rx:
        reader = can.BufferedReader()
        notifier = can.Notifier(rx, [reader], timeout=0.01)
        try:
            for i in range(50):
                tx.send(_msg(i))
            got = [reader.get_message(5.0) for _ in range(50)]
        finally:
            notifier.stop()
        assert [m.arbitration_id for m in got if m is not None] == list(range(50))


# --- the same messages as python-can virtual -------------------------------------------------

_FRAME = st.tuples(
    st.integers(0, 2),  # which handle sends
    st.integers(0, 0x7FF),
    st.binary(max_size=8),
    st.floats(0, 1e6, allow_nan=False),
    st.booleans(),  # extended id
)


Frame = tuple[int, int, bytes, float, bool]


def _replay(interface: str, channel: str, frames: list[Frame]) -> list[list[tuple[object, ...]]]:
    """Every handle's received messages after ``frames`` were sent, polling in between."""
    buses = [
        can.Bus(
            interface="virtual", channel=channel, preserve_timestamps=True, receive_own_messages=own
        )
        if interface == "virtual"
        else OdocanBus(channel, preserve_timestamps=True, receive_own_messages=own)
        for own in (False, True, False)
    ]
    heard: list[list[can.Message]] = [[], [], []]
    try:
        for i, (sender, can_id, data, ts, ext) in enumerate(frames):
            msg = can.Message(timestamp=ts, arbitration_id=can_id, data=data, is_extended_id=ext)
            buses[sender].send(msg)
            if i % 3 == 0:
                for bus, out in zip(buses, heard, strict=True):
                    out.extend(_drain(bus))
        for bus, out in zip(buses, heard, strict=True):
            out.extend(_drain(bus))
    finally:
        for bus in buses:
            bus.shutdown()
    return [
        [
            (
                m.timestamp,
                m.arbitration_id,
                m.is_extended_id,
                bytes(m.data),
                m.dlc,
                m.is_rx,
                m.channel,
                m.is_remote_frame,
                m.is_error_frame,
                m.is_fd,
            )
            for m in out
        ]
        for out in heard
    ]


@settings(max_examples=60, deadline=None)
@given(st.lists(_FRAME, max_size=40))
def test_every_handle_hears_what_it_would_hear_on_python_can_virtual(
    frames: list[Frame],
) -> None:
    name = f"test-transport-virtual-{next(_channels)}"
    assert _replay("odocan", name, frames) == _replay("virtual", name, frames)


# --- the plugin, by name ---------------------------------------------------------------------


def _declared_entry_point() -> str:
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    value: str = pyproject["project"]["entry-points"]["can.interface"][transport.INTERFACE]
    return value


def test_pyproject_declares_the_plugin_under_python_cans_entry_point_group() -> None:
    module_name, _, class_name = _declared_entry_point().partition(":")
    assert getattr(import_module(module_name), class_name) is OdocanBus


def test_an_installed_plugin_is_what_python_can_finds() -> None:
    installed = {ep.name: ep.value for ep in entry_points(group="can.interface")}
    if transport.INTERFACE not in installed:
        pytest.skip("odocan installed before the plugin: reinstall (pip install -e .) to list it")
    assert installed[transport.INTERFACE] == _declared_entry_point()
    module_name, _, class_name = _declared_entry_point().partition(":")
    assert can.interfaces.BACKENDS[transport.INTERFACE] == (module_name, class_name)


def test_can_bus_opens_it_by_name(channel: str) -> None:
    transport.register()
    transport.register()  # idempotent
    assert transport.INTERFACE in can.VALID_INTERFACES
    with (
        can.Bus(interface="odocan", channel=channel, preserve_timestamps=True) as tx,
        can.Bus(interface="odocan", channel=channel) as rx,
    ):
        assert isinstance(tx, OdocanBus)
        tx.send(_msg(0x55))
        got = rx.recv(0)
        assert got is not None
        assert got.arbitration_id == 0x55
        found = can.detect_available_configs(interfaces=["odocan"])
        assert {"interface": "odocan", "channel": channel} in found


def test_python_cans_player_plays_a_log_onto_it(
    tmp_path: Path, channel: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    transport.register()
    sent = [_msg(0x100 + i, bytes([i] * (i % 9)), ts=i * 0.001) for i in range(20)]
    path = tmp_path / "drive.log"
    with can.Logger(path) as logger:
        for msg in sent:
            logger(msg)
    argv = ["can.player", "-i", "odocan", "-c", channel, "--ignore-timestamps", "-g", "0"]
    monkeypatch.setattr(sys, "argv", [*argv, str(path)])
    with OdocanBus(channel) as rx:
        can.player.main()
        heard = _drain(rx)
    assert [(m.arbitration_id, bytes(m.data)) for m in heard] == [
        (m.arbitration_id, bytes(m.data)) for m in sent
    ]


# --- frames as bits (sim.canbits) ------------------------------------------------------------

_DATA_FRAME = st.builds(
    lambda ext, can_id, data, rtr: can.Message(
        arbitration_id=can_id & (0x1FFFFFFF if ext else 0x7FF),
        is_extended_id=ext,
        data=b"" if rtr else data,
        is_remote_frame=rtr,
        dlc=len(data),
    ),
    st.booleans(),
    st.integers(0, 0x1FFFFFFF),
    st.binary(max_size=8),
    st.booleans(),
)


def _crc15_by_division(bits: str) -> int:
    """CRC-15/CAN as the remainder of M(x) x^15 divided by the generator 0xC599 (GF(2))."""
    value = int(bits, 2) << 15 if bits else 0
    for top in range(len(bits) + 14, 14, -1):
        if value >> top & 1:
            value ^= 0xC599 << (top - 15)
    return value


def _stuffed_by_bit(bits: str) -> int:
    """Stuff bits inserted, one bit at a time as a transmitter does."""
    last, run, stuffed = "", 0, 0
    for bit in bits:
        run = run + 1 if bit == last else 1
        last = bit
        if run == 5:
            stuffed += 1
            last, run = ("1" if bit == "0" else "0"), 1
    return stuffed


@settings(max_examples=300, deadline=None)
@given(_DATA_FRAME)
def test_crc15_is_the_polynomial_remainder(msg: can.Message) -> None:
    bits = canbits.unstuffed_bits(msg)
    body, crc = bits[:-15], int(bits[-15:], 2)
    assert crc == _crc15_by_division(body)


@settings(max_examples=2000, deadline=None)
@given(st.text(alphabet="01", max_size=160) | st.from_regex(r"\A(0{3,9}|1{3,9}){0,12}\Z"))
def test_stuff_count_matches_a_bit_by_bit_transmitter(bits: str) -> None:
    assert canbits.stuff_count(bits) == _stuffed_by_bit(bits)


@settings(max_examples=300, deadline=None)
@given(_DATA_FRAME)
def test_frame_lengths_lie_within_the_published_bounds(msg: can.Message) -> None:
    """Davis et al. 2007, eq. 4 (less the 3-bit interframe space): g + 8n + 10 bits unstuffed,
    at most floor((g + 8n - 1)/4) stuff bits, g = 34 (standard) or 54 (extended)."""
    n = 0 if msg.is_remote_frame else len(msg.data)
    g = 54 if msg.is_extended_id else 34
    bits = canbits.frame_bits(msg)
    assert g + 8 * n + 10 <= bits <= g + 8 * n + 10 + (g + 8 * n - 1) // 4


def test_a_frame_worked_by_hand() -> None:
    """ID 0x000, no data: SOF, ID, RTR, IDE, r0 and DLC are 19 dominant bits and the CRC of
    zeros is zero: 34 zeros carry a stuff bit after every 5 (6 of them), plus the 10-bit tail."""
    msg = can.Message(arbitration_id=0, is_extended_id=False, data=b"")
    assert canbits.unstuffed_bits(msg) == "0" * 34
    assert canbits.frame_bits(msg) == 34 + 6 + 10
    error = can.Message(is_error_frame=True)
    assert canbits.frame_bits(error) == 14
    with pytest.raises(ValueError, match="FD"):
        canbits.frame_bits(can.Message(arbitration_id=1, is_fd=True, data=bytes(12)))


def test_arbitration_order_is_bitwise() -> None:
    key = canbits.arbitration_key
    std = can.Message(arbitration_id=0x100, is_extended_id=False)
    std_rtr = can.Message(arbitration_id=0x100, is_extended_id=False, is_remote_frame=True)
    ext_same_base = can.Message(arbitration_id=0x100 << 18, is_extended_id=True)
    ext_lower_base = can.Message(arbitration_id=(0x0FF << 18) | 0x3FFFF, is_extended_id=True)
    error = can.Message(is_error_frame=True)
    frames = [std_rtr, ext_same_base, std, ext_lower_base, error]
    ordered = sorted(frames, key=key)
    assert ordered == [error, ext_lower_base, std, std_rtr, ext_same_base]


# --- the bit-timed wire ----------------------------------------------------------------------


class FakeClock:
    """Simulated time for bit-timed handles."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def _timed(channel: str, clock: FakeClock, bitrate: int = 500_000) -> list[OdocanBus]:
    return [
        OdocanBus(channel, bitrate=bitrate, clock=clock, preserve_timestamps=True) for _ in range(3)
    ]


def test_bit_timed_frames_arrive_at_their_end_of_frame_lowest_id_first(channel: str) -> None:
    clock = FakeClock()
    a, b, c = _timed(channel, clock)
    try:
        high, low = _msg(0x300, b"\xff" * 8, ts=0.0), _msg(0x100, b"\x00" * 3, ts=0.0)
        a.send(high)
        a.send(low)  # same controller, sent later: the lower identifier still wins
        bits_low, bits_high = canbits.frame_bits(low), canbits.frame_bits(high)
        end_low = bits_low / 500_000
        end_high = (bits_low + canbits.INTERFRAME_BITS + bits_high) / 500_000
        clock.now_s = end_low * 0.999
        assert b.recv(0) is None
        clock.now_s = end_low
        got = b.recv(0)
        assert got is not None
        assert (got.arbitration_id, got.timestamp) == (0x100, end_low)
        assert b.recv(0) is None
        clock.now_s = 1.0
        assert [(m.arbitration_id, m.timestamp) for m in _drain(b)] == [(0x300, end_high)]
        assert [m.arbitration_id for m in _drain(c)] == [0x100, 0x300]
        assert a.recv(0) is None
        assert a.timing is not None
        assert a.timing.frames == 2
        assert a.timing.busy_bits == bits_low + bits_high + 2 * canbits.INTERFRAME_BITS
    finally:
        for bus in (a, b, c):
            bus.shutdown()


def test_a_frame_ready_during_a_transmission_contends_at_the_next_idle(channel: str) -> None:
    clock = FakeClock()
    a, b, c = _timed(channel, clock, bitrate=125_000)
    try:
        first = _msg(0x400, bytes(8), ts=0.0)
        waiting = _msg(0x300, bytes(8), ts=0.0001)  # ready while `first` is on the wire
        later_lower = _msg(0x200, bytes(8), ts=0.0005)  # ready later still, but a lower ID
        same_id_again = _msg(0x200, b"\x01" * 8, ts=0.0005)  # same ID, same node: send order
        a.send(first)
        b.send(waiting)
        clock.now_s = 0.00005
        assert c.recv(0) is None  # runs the wire: `first` has started alone
        a.send(later_lower)
        a.send(same_id_again)
        clock.now_s = 1.0
        heard = _drain(c)
        assert [m.arbitration_id for m in heard] == [0x400, 0x200, 0x200, 0x300]
        assert [bytes(m.data)[0] for m in heard[1:3]] == [0, 1]
        gaps = [t1.timestamp - t0.timestamp for t0, t1 in itertools.pairwise(heard)]
        for gap, msg in zip(gaps, heard[1:], strict=True):
            assert gap == pytest.approx((canbits.frame_bits(msg) + 3) / 125_000)
    finally:
        for bus in (a, b, c):
            bus.shutdown()


def test_a_bitrate_belongs_to_the_wire(channel: str) -> None:
    with OdocanBus(channel, bitrate=250_000) as first:
        with pytest.raises(can.CanInitializationError, match="250000 bit/s, not 500000"):
            OdocanBus(channel, bitrate=500_000)
        with OdocanBus(channel) as follower:  # no bitrate: joins the wire as it is
            assert follower.timing is first.timing
        with pytest.raises(can.CanOperationError, match="FD"):
            first.send(can.Message(arbitration_id=1, is_fd=True, data=bytes(12)))
    with OdocanBus(channel), pytest.raises(can.CanInitializationError, match="instant"):
        OdocanBus(channel, bitrate=500_000)
    for bad in (0, -5, 1.5, True):
        with pytest.raises(can.CanInitializationError, match="positive integer"):
            OdocanBus(channel + "-bad", bitrate=bad)  # type: ignore[arg-type]


def test_a_blocked_receiver_gets_a_bit_timed_frame_on_the_wall_clock(channel: str) -> None:
    with OdocanBus(channel, bitrate=10_000) as tx, OdocanBus(channel) as rx:
        sent_at = time.time()
        tx.send(_msg(0x123, bytes(8)))  # about 11 ms at 10 kbit/s
        got = rx.recv(5.0)
        assert got is not None
        assert got.arbitration_id == 0x123
        assert got.timestamp >= sent_at + canbits.frame_bits(got) / 10_000
        assert time.time() >= got.timestamp


def test_flushing_or_closing_a_bit_timed_handle_drops_its_waiting_frames(channel: str) -> None:
    clock = FakeClock()
    a, b, c = _timed(channel, clock)
    try:
        for can_id in (0x100, 0x101, 0x102):
            a.send(_msg(can_id, ts=0.0))
        b.send(_msg(0x200, ts=0.0))
        c.send(_msg(0x300, ts=0.0))
        clock.now_s = 1e-6
        assert b.recv(0) is None  # 0x100 is now on the wire
        a.flush_tx_buffer()  # 0x101 and 0x102 never leave
        c.shutdown()  # 0x300 neither
        clock.now_s = 1.0
        assert [m.arbitration_id for m in _drain(b)] == [0x100]
        assert [m.arbitration_id for m in _drain(a)] == [0x200]
    finally:
        for bus in (a, b, c):
            bus.shutdown()
