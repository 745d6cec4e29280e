"""How far a firmware that stalled can lie from the reference's fine steps (issue #11).

A firmware whose loop stalled (SIGSTOP, lost time) takes the encoder frames it missed when it
runs again, merged: it steps from one frame it took to the next it takes (the counts on the wire
are cumulative), skipping the ones between, each step one step of its integrator over the
merged counts (``losses.step_vector``, as the firmware and the reference take a step). The
log heard every frame, so the firmware's path over them is the reference's fine steps grouped
into runs of consecutive frames, each run taken whole. Its heading at every run's end is the
reference's exactly (the heading is linear in the counts), so its position after them differs
from the reference's by the sum of the runs' own differences, each rotated:

    E = sum_g R(h_g) (m_g - f_g),  |E| <= sum_g |m_g - f_g|,

``m_g`` the run taken as one step, ``f_g`` its fine steps, both from the run's start heading
(the difference's length does not depend on it). ``merged_allowance_m`` is the largest right
side over every grouping of the frames (a dynamic programme over where the runs end): a true
bound, far tighter than ``gapbound``'s (which bounds any steps within the speed bound, the
frames themselves unknown there): on a steady arc a run's step is the arc's (the exact
integrator) and the bound is a few float roundings."""

from __future__ import annotations

import numpy as np

from odocan.host.judge.breaks import MAX_MERGE_FRAMES, path_bound_m
from odocan.host.judge.losses import step_vector
from odocan.host.judge.reference import Geometry, integrate
from odocan.host.judge.samples import SILENCE_CYCLES, FloatArray


def merged_allowance_m(d_left: np.ndarray, d_right: np.ndarray, geometry: Geometry,
                       integrator: str) -> float:
    """The largest distance (m) between the reference's position after the count steps
    (``d_left``, ``d_right``: element k into frame k + 1) taken one by one and a firmware's
    that took them in runs of consecutive frames, each run as one merged step (module
    docstring). Beyond ``breaks.MAX_MERGE_FRAMES`` steps, ``breaks.path_bound_m`` (analyze's own
    for long spans: the table here grows as the square of the steps, 1 GB at a minute's)."""
    n = len(d_left)
    if n < 2:
        return 0.0
    if n > MAX_MERGE_FRAMES:
        return path_bound_m(int(np.sum(np.abs(d_left))), int(np.sum(np.abs(d_right))), geometry)
    fine = integrate(d_left, d_right, geometry, integrator)
    x = np.concatenate(([0.0], fine.x_m))
    y = np.concatenate(([0.0], fine.y_m))
    heading = np.concatenate(([0.0], fine.heading_rad))
    cum_left = np.concatenate(([0], np.cumsum(np.asarray(d_left, dtype=np.int64))))
    cum_right = np.concatenate(([0], np.cumsum(np.asarray(d_right, dtype=np.int64))))
    start, end = np.triu_indices(n + 1, k=1)  # a run from frame start to frame end
    mx, my = step_vector(cum_left[end] - cum_left[start], cum_right[end] - cum_right[start],
                         heading[start], heading[end], geometry, integrator)
    error = np.zeros((n + 1, n + 1))
    error[start, end] = np.hypot(mx - (x[end] - x[start]), my - (y[end] - y[start]))
    best = np.zeros(n + 1)
    for j in range(1, n + 1):
        best[j] = float(np.max(best[:j] + error[:j, j]))
    return float(best[n])


def silent_inside(sent_s: FloatArray, cycle_s: float | None, before: int | None,
                  after: int) -> bool:
    """Whether every silence of the firmware (``SILENCE_CYCLES`` encoder cycles ``cycle_s`` or
    more between two samples' bus times ``sent_s``) from the sample before ``before`` (the
    life's first when None) to the one after ``after`` lies between ``before`` and ``after``:
    neither is the first sample after a stall, which may name a frame of its backlog (a long
    stall's first pose names an old frame whose counter a recent one repeats). False when the
    DBC gives no cycle time."""
    if cycle_s is None:
        return False
    gaps = np.flatnonzero(np.diff(sent_s) >= SILENCE_CYCLES * cycle_s)
    low = 0 if before is None else before
    near = gaps[(gaps >= low - 1) & (gaps <= after)]
    return bool(np.all((near >= low) & (near < after)))
