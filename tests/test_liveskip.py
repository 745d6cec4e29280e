"""``liveskip.LiveSkips``: the live DISTANCE judge's allowance where the firmware's ENC_E2E_OK
grew by less than the host's accepted frames, page by page: the whole log's
(``losses.ok_count_spans`` then ``skipdefect.SkipDown``) at every frame."""

from __future__ import annotations

import numpy as np
import pytest

from odocan.host.judge.liveskip import LiveSkips
from odocan.host.judge.losses import ok_count_spans
from odocan.host.judge.skipdefect import SkipDown

FRAMES = 400


@pytest.mark.parametrize("seed", range(6))
def test_the_live_allowance_is_the_whole_logs(seed: int) -> None:
    rng = np.random.default_rng(seed)
    steps = rng.normal(0.0, 1e-3, FRAMES) * rng.choice([1.0, -1.0], FRAMES)
    upto = np.unique(np.concatenate(([0], rng.integers(1, FRAMES - 2, 12))))  # pages' frames
    skipped = rng.choice([0, 0, 1, 2, 3, 20], len(upto) - 1)  # frames the firmware skipped
    ok = np.concatenate(([1], 1 + np.cumsum(np.diff(upto) - skipped))) & 0xFFFF
    spans = ok_count_spans(ok, upto, upto)
    assert spans  # some span made, one of them past MAX_RUN for some seeds
    whole = SkipDown(spans).feed(np.arange(FRAMES), steps)
    live = LiveSkips()
    for seq in range(FRAMES):
        live.on_step(seq, float(steps[seq]))
    live.start(0)
    for k, seq in enumerate(upto.tolist()[1:], start=1):
        live.on_page(int(ok[k]), seq)
    at = [live.allowance_m(e) for e in range(FRAMES)]
    assert max(at) > 0
    assert np.allclose(at, whole, rtol=0, atol=1e-12)


def test_no_span_where_the_counts_agree() -> None:
    live = LiveSkips()
    for seq in range(100):
        live.on_step(seq, (-1.0) ** seq * 1e-3)  # reversing every frame: any merge is short
    live.on_page(500, 10)
    live.on_page(500 + 60, 70)  # 60 frames taken, 60 counted
    live.on_page(0xFFFF, 95)  # a wrap of ENC_E2E_OK: (0xFFFF - 560) & 0xFFFF > 25 frames
    assert [live.allowance_m(e) for e in range(100)] == [0.0] * 100
