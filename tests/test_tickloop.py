"""sim.tickloop: the one tick loop of every rig, on real python-can virtual buses."""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import can
import pytest

from odocan.sim.board import TICK_S
from odocan.sim.clock import LockstepClock
from odocan.sim.framebatch import FrameBatchListener, Received
from odocan.sim.tickloop import TickLoop, deliver
from odocan.sim.transport import OdocanBus


class _Heard(can.Listener):
    def __init__(self, name: str, log: list[tuple[str, int]]) -> None:
        self.name = name
        self.log = log

    def on_message_received(self, msg: can.Message) -> None:
        self.log.append((self.name, msg.arbitration_id))


@pytest.fixture
def pair() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    """A sender and a host handle on one virtual channel of their own."""
    channel = f"odocan-tickloop-{uuid.uuid4().hex}"
    buses = [can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
             for _ in range(2)]
    yield buses[0], buses[1]
    for bus in buses:
        bus.shutdown()


def _send(bus: can.BusABC, can_id: int) -> None:
    bus.send(can.Message(arbitration_id=can_id, is_extended_id=False, data=b"\x00"))


def test_deliver_hands_each_frame_to_every_listener_in_bus_order(
    pair: tuple[can.BusABC, can.BusABC],
) -> None:
    sender, host = pair
    for can_id in (0x100, 0x200, 0x300):
        _send(sender, can_id)
    log: list[tuple[str, int]] = []
    assert deliver(host, [_Heard("a", log), _Heard("b", log)]) == 3
    assert log == [("a", 0x100), ("b", 0x100), ("a", 0x200), ("b", 0x200),
                   ("a", 0x300), ("b", 0x300)]
    assert deliver(host, [_Heard("a", log)]) == 0  # nothing left on the bus


def test_each_tick_moves_the_clock_then_works_then_delivers(
    pair: tuple[can.BusABC, can.BusABC],
) -> None:
    sender, host = pair
    clock = LockstepClock()
    log: list[tuple[str, int]] = []
    seen: list[tuple[int, float, int]] = []  # (k, clock at the work, frames heard before it)

    def work(k: int) -> None:
        seen.append((k, clock.now_s(), len(log)))
        _send(sender, 0x100 + k)

    loop = TickLoop(work, host, [_Heard("h", log)], clock, start_s=12.5)
    loop.run(3)
    assert loop.ticks == 3
    assert seen == [(0, 12.5, 0), (1, 12.5 + TICK_S, 1), (2, 12.5 + 2 * TICK_S, 2)]
    assert log == [("h", 0x100), ("h", 0x101), ("h", 0x102)]  # each in its own tick


def test_progress_every_simulated_second_and_at_the_end(
    pair: tuple[can.BusABC, can.BusABC],
) -> None:
    _, host = pair
    calls: list[tuple[int, int]] = []
    TickLoop(lambda _k: None, host, []).run(250, lambda done, total: calls.append((done, total)))
    assert calls == [(100, 250), (200, 250), (250, 250)]


def test_run_until_stops_at_the_first_tick_done_holds_or_at_the_timeout(
    pair: tuple[can.BusABC, can.BusABC],
) -> None:
    _, host = pair
    ticks: list[int] = []
    loop = TickLoop(ticks.append, host, [])
    assert loop.run_until(lambda: len(ticks) == 4, timeout_ticks=10)
    assert ticks == [0, 1, 2, 3]
    assert not loop.run_until(lambda: False, timeout_ticks=5)
    assert ticks == list(range(9))


def test_run_to_and_a_set_tick_count_continue_from_there(
    pair: tuple[can.BusABC, can.BusABC],
) -> None:
    _, host = pair
    ticks: list[int] = []
    loop = TickLoop(ticks.append, host, [])
    loop.ticks = 40  # a robot of a staggered fleet
    loop.run_to(43)
    loop.run_to(42)  # already past: nothing
    assert ticks == [40, 41, 42]


def test_without_a_clock_tick_k_only_works_and_delivers(
    pair: tuple[can.BusABC, can.BusABC],
) -> None:
    sender, host = pair
    log: list[tuple[str, int]] = []
    loop = TickLoop(lambda k: _send(sender, k), host, [_Heard("h", log)])
    loop.tick(7)  # as sim.realtime.PeriodicLoop calls it
    assert log == [("h", 7)]
    assert loop.ticks == 0  # the real-time loop counts its own ticks


class _Batches(FrameBatchListener):
    def __init__(self, log: list[object]) -> None:
        self.log = log

    def on_message_received(self, msg: can.Message) -> None:
        self.log.append(("msg", msg.arbitration_id))

    def on_frames(self, frames: list[Received]) -> None:
        self.log.append(("batch", [f[1] if isinstance(f, tuple) else f.arbitration_id
                                   for f in frames]))


@pytest.fixture
def lean() -> Iterator[tuple[OdocanBus, OdocanBus]]:
    """A sender and a host (hearing itself) on one ``odocan`` channel of their own."""
    channel = f"odocan-tickloop-{uuid.uuid4().hex}"
    buses = (OdocanBus(channel, preserve_timestamps=True),
             OdocanBus(channel, preserve_timestamps=True, receive_own_messages=True))
    yield buses
    for bus in buses:
        bus.shutdown()


def test_on_a_lean_handle_batch_listeners_get_the_tick_as_one_list(
    lean: tuple[OdocanBus, OdocanBus],
) -> None:
    sender, host = lean
    for can_id in (0x100, 0x200):
        sender.send_data(can_id, b"\x00", 0.0)
    _send(sender, 0x300)  # a Message (send) among the DataFrames (send_data)
    log: list[object] = []
    assert deliver(host, [_Batches(log), _Batches(log)]) == 3
    assert log == [("batch", [0x100, 0x200, 0x300])] * 2
    assert deliver(host, [_Batches(log)]) == 0
    assert len(log) == 2


def test_with_any_plain_listener_each_frame_goes_to_every_listener_as_a_message(
    lean: tuple[OdocanBus, OdocanBus],
) -> None:
    sender, host = lean
    for can_id in (0x100, 0x200):
        sender.send_data(can_id, b"\x00", 0.0)
    log: list[object] = []
    heard: list[tuple[str, int]] = []

    class Answering(_Heard):
        def on_message_received(self, msg: can.Message) -> None:
            super().on_message_received(msg)
            if msg.arbitration_id == 0x100:  # heard again in this very delivery, as with recv
                host.send(can.Message(arbitration_id=0x101, is_extended_id=False))

    assert deliver(host, [_Batches(log), Answering("a", heard)]) == 3
    assert log == [("msg", 0x100), ("msg", 0x200), ("msg", 0x101)]
    assert heard == [("a", 0x100), ("a", 0x200), ("a", 0x101)]


class _Passive(_Batches):
    passive = True


def test_passive_listeners_hear_a_run_once_per_simulated_second_the_same_frames(
    lean: tuple[OdocanBus, OdocanBus],
) -> None:
    sender, host = lean
    log: list[object] = []
    heard_at_progress: list[int] = []

    def frames_heard() -> int:
        return sum(len(entry[1]) for entry in log if isinstance(entry, tuple))

    loop = TickLoop(lambda k: sender.send_data(k, b"\x00", 0.0), host, [_Passive(log)])
    loop.run(250, lambda done, _total: heard_at_progress.append(frames_heard()))
    assert loop.ticks == 250
    assert log == [("batch", list(range(0, 100))), ("batch", list(range(100, 200))),
                   ("batch", list(range(200, 250)))]
    assert heard_at_progress == [100, 200, 250]  # all of them before each progress call
    # Next to a plain listener, it hears every tick (as a Message, as before).
    log.clear()
    heard: list[tuple[str, int]] = []
    TickLoop(lambda k: sender.send_data(k, b"\x00", 0.0), host,
             [_Passive(log), _Heard("h", heard)]).run(3)
    assert log == [("msg", 0), ("msg", 1), ("msg", 2)]
    assert heard == [("h", 0), ("h", 1), ("h", 2)]


def test_a_run_that_raises_still_hands_passive_listeners_what_ran(
    lean: tuple[OdocanBus, OdocanBus],
) -> None:
    sender, host = lean
    log: list[object] = []

    def work(k: int) -> None:
        sender.send_data(k, b"\x00", 0.0)
        if k == 42:
            raise KeyboardInterrupt  # tick 42 sent a frame, then stopped

    loop = TickLoop(work, host, [_Passive(log)])
    with pytest.raises(KeyboardInterrupt):
        loop.run(100)
    assert loop.ticks == 42
    assert log == [("batch", list(range(42)))]
    assert deliver(host, [_Passive(log)]) == 1  # tick 42's frame stays queued, as step leaves it
