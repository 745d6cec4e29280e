"""``liveskip.LiveSkips``: the live DISTANCE judge's allowance where the firmware's ENC_E2E_OK
grew by less than the host's accepted frames, page by page: the whole log's
(``losses.ok_count_spans`` then ``skipdefect.SkipDown``) at every frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from odocan.host.judge.liveskip import KEPT_FRAMES, LiveSkips, span_units
from odocan.host.judge.losses import ok_count_spans
from odocan.host.judge.skipdefect import MAX_RUN, UNITS_PER_M, SkipDown

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
    # past MAX_RUN: the judge's union (liveunion), as analyze's merged_path_m takes them
    whole = SkipDown([span for span in spans if span[2] <= MAX_RUN]).feed(np.arange(FRAMES),
                                                                           steps)
    live = LiveSkips()
    for seq in range(FRAMES):
        live.on_step(seq, float(steps[seq]))
    live.start(0)
    for k, seq in enumerate(upto.tolist()[1:], start=1):
        live.on_page(int(ok[k]), seq)
    at = [live.allowance_m(e) for e in range(FRAMES)]
    assert max(at) > 0
    assert np.allclose(at, whole, rtol=0, atol=1e-12)
    assert live.merged == [(a, z + 1) for a, z, n in spans if n > MAX_RUN]


def test_no_span_where_the_counts_agree() -> None:
    live = LiveSkips()
    for seq in range(100):
        live.on_step(seq, (-1.0) ** seq * 1e-3)  # reversing every frame: any merge is short
    live.on_page(500, 10)
    live.on_page(500 + 60, 70)  # 60 frames taken, 60 counted
    live.on_page(0xFFFF, 95)  # a wrap of ENC_E2E_OK: (0xFFFF - 560) & 0xFFFF > 25 frames
    assert [live.allowance_m(e) for e in range(100)] == [0.0] * 100


class _EveryFrame:
    """``LiveSkips`` as it summed its steps before (``_at`` brought up to date at every frame,
    every frame's sums from 0): the model the batched sums must equal to the bit."""

    def __init__(self) -> None:
        self.live = LiveSkips()
        self.at: dict[int, tuple[int, int]] = {}
        self.sums = (0, 0)
        self.live._span_units = self._span_units  # type: ignore[method-assign]

    def on_step(self, seq: int, signed_m: float) -> None:
        units = round(signed_m * UNITS_PER_M)
        signed, absolute = self.sums
        self.at[seq] = self.sums = (signed + units, absolute + abs(units))
        self.at.pop(seq - KEPT_FRAMES, None)

    def _span_units(self, first: int, end: int, n: int) -> int:
        return span_units(self.at, first, end, n)  # the window rule on every frame's sums


def _allowance(live: LiveSkips, e: int) -> float:
    """``allowance_m``, nan where it raises (a gap in the numbering inside a span: as before)."""
    try:
        return live.allowance_m(e)
    except KeyError:
        return math.nan


def _units(live: LiveSkips, first: int, end: int, n: int) -> int | None:
    """``_span_units``, None where it raises (as ``_allowance``)."""
    try:
        return live._span_units(first, end, n)
    except KeyError:
        return None


@pytest.mark.parametrize("seed", range(8))
def test_the_steps_summed_in_batches_give_every_frames_allowance(seed: int) -> None:
    """Pages, steps and allowances interleaved over many ``KEPT_FRAMES`` (the steps kept,
    trimmed and summed in batches) as the live judge calls them: the same allowance, to the
    bit, as summing every frame; seeds 6, 7 number the frames with gaps (summed, none dropped)."""
    rng = np.random.default_rng(seed)
    live, model = LiveSkips(), _EveryFrame()
    seq, ok, start = 0, 1, int(rng.integers(0, 3000))
    seq = page_at = start
    for seq_k in range(start, start + 12 * KEPT_FRAMES):
        seq = seq_k if seed < 6 else seq + int(rng.choice([1, 1, 1, 2]))
        signed_m = float(rng.normal(0.0, 1e-3))
        kept = len(live._steps)
        live.on_step(seq, signed_m)
        model.on_step(seq, signed_m)
        trimmed = len(live._steps) <= kept  # (the steps' edge: right after a trim, checked)
        if seq >= page_at:  # a page: the firmware counted 0..3 (or 20) frames less
            ok = (ok + 25 - int(rng.choice([0, 0, 0, 1, 2, 3, 20]))) & 0xFFFF
            for judge in (live, model.live):
                judge.on_page(ok, seq)
            page_at = seq + int(rng.choice([25, 25, 25, KEPT_FRAMES - 1, KEPT_FRAMES,
                                            KEPT_FRAMES + 1]))  # (spans at the steps' edge)
        if trimmed or rng.random() < (1 / 3 if seed % 2 else 1 / (3 * KEPT_FRAMES)):
            e = seq - int(rng.integers(0, 2 * KEPT_FRAMES))
            got, want = _allowance(live, e), _allowance(model.live, e)
            assert got == want or (math.isnan(got) and math.isnan(want))
            back = [KEPT_FRAMES, KEPT_FRAMES - 1, *rng.integers(0, 3 * KEPT_FRAMES, 8).tolist()]
            for first in [seq - b for b in back]:  # spans at the steps' edge and within
                end, n = min(seq, first + int(rng.integers(1, 40))), int(rng.choice([1, 3, 40]))
                assert _units(live, first, end, n) == _units(model.live, first, end, n)
    assert live._done_units == model.live._done_units
    assert live._done_units != 0
    assert len(live._steps) <= 2 * KEPT_FRAMES or seed >= 6
