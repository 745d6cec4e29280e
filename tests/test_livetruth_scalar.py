"""The live truth judge's plain-float carry and rebase (``livetruth.carried_to``, ``rebased``)
give the bits of ``compare.carried`` and ``compare.rebase_truth`` (numpy), which the whole-log
and streamed judges use: the live judge must carry and rebase alike, bit for bit."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.judge.compare import carried, rebase_truth
from odocan.host.judge.livepose import FramePose
from odocan.host.judge.livetruth import carried_to, rebased

metres = st.floats(-1e4, 1e4, allow_nan=False)
radians = st.floats(-1e3, 1e3, allow_nan=False)
poses = st.tuples(metres, metres, radians)


@settings(max_examples=2000, deadline=None)
@given(poses, poses, poses)
def test_carried_to_is_compare_carried_bit_for_bit(
    pose: tuple[float, float, float], at: tuple[float, float, float],
    ref: tuple[float, float, float],
) -> None:
    got = carried_to(FramePose(0, *pose), FramePose(1, *at), FramePose(7, *ref))
    want = carried(pose, at, ref)
    assert got.seq == 7
    assert [type(v) for v in got[1:]] == [float, float, float]
    assert got[1:] == tuple(float(v) for v in want)


@settings(max_examples=2000, deadline=None)
@given(poses, poses)
def test_rebased_is_compare_rebase_truth_bit_for_bit(
    truth: tuple[float, float, float], origin: tuple[float, float, float],
) -> None:
    want = rebase_truth(np.array([truth[0]]), np.array([truth[1]]), np.array([truth[2]]), origin)
    got = rebased(*truth, origin)
    assert [type(v) for v in got] == [float, float, float]
    assert got == tuple(float(v[0]) for v in want)
