"""``host.judge.twosenders.SenderWatch``: one sender is never taken for two, two are told.

One sender's frames (COUNTER +1 a frame, mod 16) heard with losses of fewer than 12 frames over
any 5 gaps in a row, duplicated frames (CAN's double reception) and a sender that starts
anywhere: no signature; one whose COUNTER laps once (14 frames lost): one signature, not told.
Two senders of different content, each in its own sequence, merged in any order: the signatures
counted are those of a model written here (a repeated COUNTER with other bytes, or a frame
continuing an earlier frame but not the one before it).
"""

from __future__ import annotations

from itertools import pairwise

from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.judge.twosenders import LAP_FRAMES, RECENT, SenderWatch


def _frame(counter: int, payload: int) -> bytes:
    return bytes([0, (counter & 0xF) | ((payload & 0xF) << 4), payload & 0xFF, 0, 0, 0, 0, 0])


@settings(max_examples=300, deadline=None)
@given(start=st.integers(0, 15), steps=st.lists(
    st.tuples(st.integers(0, 14), st.booleans(), st.integers(0, 255)), min_size=1, max_size=60))
def test_one_sender_is_never_two(start: int, steps: list[tuple[int, bool, int]]) -> None:
    """Fewer than 12 frames lost over any ``RECENT`` + 1 gaps in a row (each loss capped so):
    no signature at all (one needs 17 - m lost over m <= ``RECENT`` + 1 gaps)."""
    watch, counter, losses = SenderWatch("ODOM_CONFIG"), start, [0] * RECENT
    for k, (wanted, duplicated, payload) in enumerate(steps):
        lost = max(0, min(wanted, 11 - sum(losses[-RECENT:])))
        losses.append(lost)
        counter = (counter + 1 + lost) & 0xF
        frame = _frame(counter, payload)
        assert watch.heard(frame, k * 0.01) is None
        if duplicated:
            assert watch.heard(frame, k * 0.01) is None
    assert watch.count == 0


def test_one_sender_whose_counter_laps_once_is_not_told() -> None:
    """14 frames lost in a row, then in sequence: one interleaving signature, not told."""
    watch = SenderWatch("ODOM_CONFIG")
    counters = [1, 2, 3, 4, (4 + 15) & 0xF, 4, 5, 6, 7]  # 3: continues 2, not 3
    said = [watch.heard(_frame(c, 0), k * 0.01) for k, c in enumerate(counters)]
    assert said == [None] * len(counters)
    assert watch.count == 1


@settings(max_examples=300, deadline=None)
@given(a_start=st.integers(0, 15), b_start=st.integers(0, 15),
       order=st.lists(st.booleans(), min_size=2, max_size=40))
def test_two_senders_are_told_when_their_frames_show_it(
    a_start: int, b_start: int, order: list[bool],
) -> None:
    """Sender A's frames carry payload 1, B's payload 2; ``order``: whose frame comes next."""
    watch, counters = SenderWatch("ODOM_CONFIG"), {True: a_start, False: b_start}
    heard: list[bytes] = []
    said: list[str] = []
    interleaving: list[int] = []  # the frames continuing an earlier one (the model's)
    expected = 0
    for k, is_a in enumerate(order):
        frame = _frame(counters[is_a], 1 if is_a else 2)
        counters[is_a] = (counters[is_a] + 1) & 0xF
        signature = _model_signature(heard, frame)
        expected += signature
        if signature and not _repeat(heard[-1], frame):
            interleaving.append(k)
        said += [d for d in [watch.heard(frame, k * 0.01)] if d is not None]
        heard.append(frame)
    assert watch.count == expected
    told = any(_repeat(a, b) for a, b in pairwise(heard)) or any(
        b - a <= LAP_FRAMES for a, b in pairwise(interleaving))
    assert bool(said) is told, (heard, said)


def _repeat(first: bytes, then: bytes) -> bool:
    return (first[1] & 0xF) == (then[1] & 0xF) and first != then


def _model_signature(heard: list[bytes], frame: bytes) -> bool:
    if not heard:
        return False
    counter, previous = frame[1] & 0xF, heard[-1][1] & 0xF
    if counter == previous:
        return frame != heard[-1]
    if counter == (previous + 1) & 0xF:
        return False
    return any(counter == ((f[1] & 0xF) + 1) & 0xF for f in heard[-RECENT - 1:-1])


def test_interleaved_configs_from_one_counter_are_told_at_the_first_differing_frame() -> None:
    watch = SenderWatch("ODOM_CONFIG")
    said = [watch.heard(_frame(c, p), c * 0.001) for c in range(4) for p in (1, 1 + (c == 3))]
    assert said[:7] == [None] * 7  # identical frames: duplicates
    assert said[7] is not None
    assert said[7].startswith("two senders on ODOM_CONFIG: COUNTER 3 repeated with other")
