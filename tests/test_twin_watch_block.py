"""``TwinWatch.hear_block`` (the log judges' whole chunk at once) leaves the watch as ``hear``
frame by frame does: the same pairs, the same telling, the same frames kept for the next chunk.

The block's shortcut (no frame within the pair window after one of its COUNTER: the one sender's
usual log, 139 k pose frames a 1 M-frame log, 0.28 s of a 1.6 s ``odocan analyze`` frame by
frame) must never miss a pair: random pose streams of one sender, one sender reordered, two
senders and a stuck COUNTER, cut into random chunks, both ways.
"""

from __future__ import annotations

import numpy as np
import pytest

from odocan.host.judge.livestreams import LAP_S, TwinWatch
from odocan.host.protocol.busfacts import POSE_PERIOD_S


def _stream(kind: str, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(8-byte frames, bus times) of ``kind``: byte 1's low nibble the COUNTER, bytes 2.. vary."""
    t = np.arange(n) * POSE_PERIOD_S + rng.uniform(0, 1e-4, n)
    counter = np.arange(n) % 16
    if kind == "two":  # a second sender from the middle, its own phase and COUNTER
        half = n // 2
        t = np.r_[t, t[half:] + rng.uniform(0, LAP_S)]
        counter = np.r_[counter, (np.arange(n - half) + rng.integers(16)) % 16]
    if kind == "stuck":
        counter[:] = 0
    if kind == "delayed":  # some frames held back up to 7 periods, the log in bus order
        t = t + np.where(rng.random(len(t)) < 0.3, rng.uniform(0, 7 * POSE_PERIOD_S, len(t)), 0)
    data = rng.integers(0, 256, (len(t), 8), dtype=np.uint8)
    data[:, 1] = (data[:, 1] & 0xF0) | counter
    order = np.argsort(t, kind="stable")
    return data[order], t[order]


def _state(watch: TwinWatch) -> tuple[object, ...]:
    return (watch.heard, watch.paired, watch.told, watch.last_paired,
            [list(d) for d in watch._recent], list(watch._periods))


@pytest.mark.parametrize("kind", ["one", "delayed", "two", "stuck"])
@pytest.mark.parametrize("seed", range(6))
def test_a_block_is_heard_as_its_frames_one_by_one(kind: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    data, t = _stream(kind, rng, 600)
    positions = np.arange(len(t), dtype=np.int64) * 3
    cuts = np.sort(rng.choice(np.arange(1, len(t)), 5, replace=False))
    by_frame, by_block = TwinWatch(), TwinWatch()
    for i in range(len(t)):
        by_frame.hear(data[i].tobytes(), float(t[i]), int(positions[i]))
    for part in np.split(np.arange(len(t)), cuts):
        by_block.hear_block(data[part], t[part], positions[part])
    assert _state(by_block) == _state(by_frame)
    assert (by_frame.told is not None) == (kind == "two")
