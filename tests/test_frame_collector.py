"""host.io.frames.FrameCollector: batches (``on_frames``, the lockstep rig's) record exactly what
the same frames recorded one ``Message`` at a time do, whatever the mix, the payload lengths or
where the bulk flushes fall."""

from __future__ import annotations

import random

import can
import numpy as np
import pytest

from odocan.host.io.frames import FrameArrays, FrameCollector
from odocan.sim.framebatch import DataFrame, Received
from odocan.sim.transport import OdocanBus

_FLUSH = 4096  # host.io.frames._FLUSH_FRAMES, crossed on purpose below


def _message(frame: Received) -> can.Message:
    """What a receiving handle makes of a queued frame (``OdocanBus.as_message``)."""
    if isinstance(frame, can.Message):
        return frame
    stamp_s, can_id, data = frame
    return can.Message(timestamp=stamp_s, arbitration_id=can_id, is_extended_id=False,
                       data=data)


def _odd_message(rng: random.Random, t_s: float) -> can.Message:
    kind = rng.randrange(4)
    if kind == 0:
        return can.Message(timestamp=t_s, arbitration_id=rng.randrange(1 << 29),
                           is_extended_id=True, data=bytes(rng.randrange(9)))
    if kind == 1:
        return can.Message(timestamp=t_s, arbitration_id=0x123, is_remote_frame=True, dlc=5)
    if kind == 2:
        return can.Message(timestamp=t_s, is_error_frame=True, arbitration_id=0)
    return can.Message(timestamp=t_s, arbitration_id=0x55, is_fd=True,
                       data=bytes(range(rng.randrange(9))))


def _frames(rng: random.Random, n: int, odd: float, short: float) -> list[Received]:
    """``n`` frames in bus order: mostly 8-byte DataFrames, some shorter, some Messages."""
    out: list[Received] = []
    for i in range(n):
        t_s = i * 0.001
        if rng.random() < odd:
            out.append(_odd_message(rng, t_s))
        else:
            size = rng.randrange(8) if rng.random() < short else 8
            frame: DataFrame = (t_s, rng.randrange(0x800), rng.randbytes(size))
            out.append(frame)
    return out


def _one_by_one(frames: list[Received]) -> FrameArrays:
    collector = FrameCollector()
    for frame in frames:
        collector.on_message_received(_message(frame))
    return collector.arrays()


def _assert_same(got: FrameArrays, want: FrameArrays) -> None:
    for field in ("timestamp_s", "can_id", "dlc", "data", "flags"):
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)
        assert getattr(got, field).dtype == getattr(want, field).dtype


@pytest.mark.parametrize(
    ("n", "odd", "short"),
    [(10, 0.0, 0.0), (3 * _FLUSH + 17, 0.0, 0.0), (2 * _FLUSH + 5, 0.0, 0.01),
     (2 * _FLUSH + 5, 0.001, 0.0), (300, 0.3, 0.3)],
)
def test_batches_record_what_messages_one_by_one_record(
    n: int, odd: float, short: float
) -> None:
    rng = random.Random(n * 7 + int(odd * 1000) + int(short * 100))
    frames = _frames(rng, n, odd, short)
    batched = FrameCollector()
    i = 0
    while i < n:  # uneven batches, a Message now and then handed one by one in between
        size = rng.randrange(1, 9)
        batched.on_frames(frames[i:i + size])
        i += size
        assert len(batched) == min(i, n)
    _assert_same(batched.arrays(), _one_by_one(frames))


def test_a_message_between_batches_keeps_its_place() -> None:
    collector = FrameCollector()
    collector.on_frames([(0.0, 0x10, b"\x01" * 8), (0.1, 0x11, b"\x02" * 8)])
    collector.on_message_received(can.Message(timestamp=0.2, arbitration_id=0x12, data=b"\x03"))
    collector.on_frames([(0.3, 0x13, b"\x04" * 8)])
    got = collector.arrays()
    assert got.can_id.tolist() == [0x10, 0x11, 0x12, 0x13]
    assert got.dlc.tolist() == [8, 8, 1, 8]
    assert got.data[2].tolist() == [3, 0, 0, 0, 0, 0, 0, 0]
    collector.on_frames([(0.4, 0x14, b"")])
    assert len(collector) == 5
    assert collector.arrays().can_id.tolist() == [0x10, 0x11, 0x12, 0x13, 0x14]


def test_the_frames_of_a_lean_wire_drained_and_batched_equal_the_messages_received() -> None:
    channel = "test-frame-collector"
    sender = OdocanBus(channel, preserve_timestamps=True)
    by_recv, by_drain = OdocanBus(channel), OdocanBus(channel)
    rng = random.Random(5)
    for i in range(_FLUSH + 100):
        if i % 500 == 0:
            sender.send(can.Message(timestamp=i * 0.01, arbitration_id=0x1ABCDEF,
                                    is_extended_id=True, data=b"\x09\x08"))
        else:
            sender.send_data(rng.randrange(0x800), rng.randbytes(8), i * 0.01)
    one, batched = FrameCollector(), FrameCollector()
    while (msg := by_recv.recv(0)) is not None:
        one.on_message_received(msg)
    batched.on_frames(by_drain.drain())
    _assert_same(batched.arrays(), one.arrays())
    for bus in (sender, by_recv, by_drain):
        bus.shutdown()
