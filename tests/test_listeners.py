"""A failing listener neither stops python-can's Notifier nor starves the listeners after it."""

from __future__ import annotations

import threading
import time

import can
import pytest

from odocan.host.io.listeners import Isolated, isolate


class Counting(can.Listener):
    def __init__(self) -> None:
        self.count = 0

    def on_message_received(self, msg: can.Message) -> None:
        self.count += 1


class Flaky(can.Listener):
    """Raises on every third frame."""

    def __init__(self) -> None:
        self.seen = 0

    def on_message_received(self, msg: can.Message) -> None:
        self.seen += 1
        if self.seen % 3 == 0:
            raise ValueError("malformed telemetry")


def _pump(listeners: list[can.Listener], frames: int) -> can.Notifier:
    channel = f"listeners-{time.monotonic_ns()}"
    with (
        can.Bus(interface="virtual", channel=channel) as rx,
        can.Bus(interface="virtual", channel=channel) as tx,
    ):
        notifier = can.Notifier(rx, listeners, timeout=0.01)
        for i in range(frames):
            tx.send(can.Message(arbitration_id=0x100, is_extended_id=False, data=[i & 0xFF]))
        deadline = time.monotonic() + 5
        while listeners[-1].listener.count < frames and time.monotonic() < deadline:  # type: ignore[attr-defined]
            time.sleep(0.01)
        notifier.stop()
    return notifier


def test_isolated_listeners_keep_the_notifier_and_the_others_going() -> None:
    flaky, counting = Flaky(), Counting()
    listeners = isolate([flaky, counting])
    notifier = _pump(listeners, 300)
    assert counting.count == 300
    assert flaky.seen == 300
    assert isinstance(listeners[0], Isolated)
    assert listeners[0].errors == 100
    assert notifier.exception is None


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_without_isolation_python_can_starves_the_next_listener() -> None:
    """The behaviour the wrapper exists for: the raw Notifier loses frames after a failure."""
    flaky, counting = Flaky(), Counting()
    channel = f"raw-{time.monotonic_ns()}"
    with (
        can.Bus(interface="virtual", channel=channel) as rx,
        can.Bus(interface="virtual", channel=channel) as tx,
    ):
        notifier = can.Notifier(rx, [flaky, counting], timeout=0.01)
        for i in range(30):
            tx.send(can.Message(arbitration_id=0x100, is_extended_id=False, data=[i]))
        (reader,) = notifier._readers  # the Notifier's one thread for this bus
        assert isinstance(reader, threading.Thread)
        reader.join(10)  # it dies with the listener's exception: an event, not a delay
        assert not reader.is_alive()
        notifier.stop()
    assert flaky.seen == 3  # the third frame raised ...
    assert counting.count == 2  # ... and nothing after it reached the next listener
