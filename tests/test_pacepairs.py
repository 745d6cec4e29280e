"""``host.judge.pacepairs``: the one-step intervals of encoder frames in any order (the bus's pace,
``livepace``; ``tests/test_reboot_delay_live.py`` for the drive that took a live bus reordered
by ``delay=0.5:20`` for a replay at 0.7x)."""

from __future__ import annotations

import random

import pytest

from odocan.host.judge.pacepairs import EncoderPairs

PERIOD_S = 0.01


def _payload(seq: int) -> bytes:
    """A frame's payload, distinct per sequence (its counts move), COUNTER = seq mod 16."""
    return bytes([0, seq & 0xF]) + seq.to_bytes(6, "little")


def _heard(frames: list[tuple[float, int]]) -> list[float]:
    """The intervals ``EncoderPairs`` gives for (bus time, sequence) frames, in that order."""
    pairs = EncoderPairs()
    return [i for t, seq in frames for i in pairs.intervals(t, seq & 0xF, _payload(seq))]


@pytest.mark.parametrize("seed", range(5))
def test_reordered_frames_sum_to_their_span(seed: int) -> None:
    """Each frame held back 20 or 55 ms with probability 0.5 (two and 5.5 periods), heard in
    stamp order: every pair once, the intervals' mean exactly the period."""
    rng = random.Random(seed)
    for held_s in (0.02, 0.055):
        sent = [(k * PERIOD_S + (held_s if rng.random() < 0.5 else 0.0), k) for k in range(500)]
        intervals = _heard(sorted(sent))
        assert len(intervals) == 499
        assert sum(intervals) == pytest.approx(sent[-1][0] - sent[0][0])
        assert any(i < 0 for i in intervals)


def test_a_silence_a_repetition_and_the_clock_going_back() -> None:
    """A silence of 12 periods (the COUNTER 13 on, read behind by 3 but that slot heard with
    another payload): no interval across it; the same frame again: none; a frame stamped before
    its neighbour heard earlier: none."""
    pairs = EncoderPairs()
    for k in range(5):
        pairs.intervals(k * PERIOD_S, k, _payload(k))
    assert pairs.intervals(17 * PERIOD_S, 17 & 0xF, _payload(17)) == []
    assert pairs.intervals(18 * PERIOD_S, 18 & 0xF, _payload(18)) == [pytest.approx(PERIOD_S)]
    assert pairs.intervals(18.5 * PERIOD_S, 18 & 0xF, _payload(18)) == []
    assert pairs.intervals(10 * PERIOD_S, 19 & 0xF, _payload(19)) == []
