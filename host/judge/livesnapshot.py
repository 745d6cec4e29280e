"""The live judge's snapshot (``PoseTracker.snapshot``): the latest on-board pose, reference and
truth, how the reference was started and placed, and the three error statistics, as the monitor
and the bridge show them."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from odocan.host.judge.livepose import pose_dict

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker


def tracker_snapshot(tracker: PoseTracker) -> dict[str, Any]:
    """``pose``, ``reference``, ``truth`` (None until known) and ``error`` (vs reference with
    ``loss_allowance_m`` at the latest sample and ``max_dpos_beyond_allowance_m``)."""
    stats = tracker.vs_reference.as_dict()
    vs_ref = None if stats is None else {**stats, "loss_allowance_m": tracker.allowance_m(),
                                         "max_dpos_beyond_allowance_m":
                                         tracker.max_beyond_allowance_m}
    return {
        "pose": pose_dict(tracker.pose),
        "reference": {**(pose_dict(tracker.reference) or {}), "integrator": tracker.integrator,
                      "starts": tracker.reference_starts,
                      "counter_restarts": tracker.counter_restarts, "stalls": tracker.stall.stalls,
                      "unseen_restarts": tracker.placer.dark.new_starts,  # host.judge.livedark
                      "breaks": tracker.placer.watch_breaks()},
        "truth": pose_dict(tracker.truth),
        "truth_origin": tracker.life_truth.as_dict(),
        "error": {
            "pose_vs_reference": vs_ref,
            "pose_vs_truth": tracker.vs_truth.as_dict(),
            "reference_vs_truth": tracker.reference_vs_truth.as_dict(),
        },
    }
