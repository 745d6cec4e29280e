"""The live judge's placement of its reference after a stall or a gap (``host.judge.tracking``):
moved out of ``tracking.py`` (at its 500 lines) unchanged."""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livefit import rebase

if TYPE_CHECKING:
    from odocan.host.judge.livepose import FramePose
    from odocan.host.judge.tracking import PoseTracker


def place_reference(tracker: PoseTracker, pose: FramePose, raw: FramePose) -> FramePose:
    """Move the reference's position (now and at the frames heard since ``raw``) to where the
    firmware is, within the pose's rounding, while its heading goes on exact; bounded as
    ``analyze`` places it (``liveplace.StallPlacer``); the start fit's correction is taken into
    the reference first and the fit goes on (``livefit.rebase``). Returns the moved reference
    at ``raw``'s frame."""
    line = tracker.raw  # (livereference: its pose at the frames heard since moves too)
    odometry = line.odometry
    assert odometry is not None and tracker.integrator is not None
    if not tracker.placer.due(pose.seq):  # a gap after its frame: placed at a later sample's
        return raw  # (a sample held, ``livelaphold``, is compared after the gaps heard since)
    ref = tracker.fit.correct(raw)
    shift = tracker.placer.shift(pose, ref, tracker.stall.last_compared, tracker.window,
                                 (tracker.geometry, tracker.counter_bits, tracker.integrator),
                                 tracker.fit.placed_shift_m())
    line.at, tracker.fit, placed = rebase(tracker.fit, odometry, line.at, ref, shift)
    tracker.stall.place_at_next = tracker.placer.gapped  # a gap after a held sample's frame
    return placed
