"""``skipdefect.SkipDown``: the allowance where the firmware took n fewer of the log's encoder
frames than the host (its ENC_E2E_OK), the same fed whole or chunk by chunk."""

from __future__ import annotations

import numpy as np

from odocan.host.judge.skipdefect import MAX_RUN, SkipDown


def test_a_reversal_inside_the_span_is_allowed_and_nothing_elsewhere() -> None:
    steps = np.array([1.0, 1.0, 2.0, -1.0, 1.0, 1.0, 1.0, 1.0])  # m into frames 0..7
    down = SkipDown([(1, 4, 1)]).feed(np.arange(8), steps)
    # one frame skipped among 2..4: the worst merge is 2 then -1 (|2| + |-1| - |1| = 2)
    assert down.tolist() == [0.0, 0.0, 0.0, 2.0, 2.0, 2.0, 2.0, 2.0]
    same_sign = SkipDown([(1, 4, 1)]).feed(np.arange(8), np.abs(steps))
    assert not same_sign.any()


def test_chunked_is_whole_bit_for_bit() -> None:
    rng = np.random.default_rng(5)
    steps = rng.normal(0.0, 1e-3, 5000)
    spans = [(int(a), int(a) + 40, int(n)) for a, n in
             zip(rng.integers(0, 4900, 60), rng.integers(1, MAX_RUN + 4, 60), strict=True)]
    whole = SkipDown(spans).feed(np.arange(5000), steps)
    for size in (1, 7, 97, 1000):
        judge = SkipDown(spans)
        parts = [judge.feed(np.arange(k, min(k + size, 5000)), steps[k:k + size])
                 for k in range(0, 5000, size)]
        assert np.array_equal(np.concatenate(parts), whole), size
