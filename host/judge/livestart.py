"""The live reference's start (``host.judge.tracking``): a ``ReferenceOdometry`` at a pose, primed
on the encoder frame it names, caught up over the frames heard since and the poses heard since
compared (the first life's backlog, a reboot's held samples)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from odocan.host.judge.livefit import LiveFit
from odocan.host.judge.livepose import FramePose, StepGate
from odocan.host.judge.livewindow import Counted
from odocan.host.judge.reference import ReferenceOdometry

if TYPE_CHECKING:
    from odocan.host.judge.tracking import PoseTracker


def start_reference(tracker: PoseTracker, pose: FramePose, counts: list[Counted],
                    poses: list[FramePose]) -> None:
    """Start ``tracker``'s reference at ``pose``, primed on the first of ``counts`` (the frame
    ``pose`` names on, stepped as heard: ``Counted``), catch up, compare the ``poses`` heard
    since."""
    assert tracker.integrator is not None
    tracker.choice.decide()  # the samples held are judged by the reference they named
    ref = tracker._ref = ReferenceOdometry(
        tracker.geometry, tracker.integrator, tracker.counter_bits,
        x_m=pose.x_m, y_m=pose.y_m, heading_rad=pose.heading_rad,
    )
    tracker.reference_starts += 1
    tracker.fit = LiveFit.start(pose)
    tracker.newstart.started(tracker.fit.exact)  # after an unseen restart: held (livenewstart)
    tracker._ref_at = {}
    tracker.placer.restart()
    tracker._gate = StepGate(tracker.geometry, tracker.counter_bits, tracker.restarts)
    for frame in counts:
        step = tracker._gate.step(frame)  # the first primes: stays at pose
        if step is not None:
            ref.step_deltas(*step)
        tracker._keep_ref(FramePose(frame[0], ref.x_m, ref.y_m, ref.heading_rad))
        if tracker.choice.pending is not None:  # the twin steps along (livechoice)
            tracker.choice.stepped(frame[0], step)
    for heard in poses:
        at = tracker._ref_at.get(heard.seq)
        held = tracker._held.pop(heard.seq, None)
        if at is not None and held is not None:  # settled again, judged now
            tracker.settled.append(held._replace(reference=tracker._record(heard, at)))
        elif at is not None:
            tracker._record(heard, at)
