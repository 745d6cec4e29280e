"""A second ambiguous hole while the live judge's choice waits for pages (issue #11, one judge;
rule 3: a FAIL must never blame a correct firmware; ``host.judge.livechoice``).

The whole log's judge chooses at every evidenceless ambiguous gap on its own
(``host.judge.evidencechoice``): from the firmware's pose before the gap, the steps to its
first pose after it, once re-primed and once with the gap's step taken; the nearer wins. The
live judge held one choice at a time, and a hole heard while that one waited for its pages
(up to ``livechoice.PAGES_WAIT_S``) fell back to the re-prime. On the slow16 robot (2^24
counts per revolution, 16-bit counters, ``tests/test_trial37.py``) random seed 43 under
``stall=3:0.05,delay=0.1:30``, the frame held back from 3.05 to 3.08 s came 14 COUNTERs after
the last taken, a step too long to read by its periods: ``analyze`` took it (its next pose
fits the step), the live judges re-primed, lost a period of motion (0.3 mm) and said POSE
WRONG.

Now such a second hole holds a choice of its own (``Second``), made as ``analyze`` makes it:
at the first on-board sample naming its frame or later, from the latest sample held before
it, both candidates' paths (the reference re-primed, and its twin that took the step) moved
rigidly onto that sample (the steps from a pose are the same motion from any other) and
compared with the sample in LSBs (strictly nearer: taken). The first choice's twin keeps a
twin of its own that took the step, so either way of the first stays whole. Not where the
pages heard prove the hole missed, and without a sample before it to move from (the re-prime,
as before). When the first choice is made before the second's sample comes, the second falls
back to the re-prime (as before). Bounded: one second choice, two twins.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from odocan.host.judge.livepose import FramePose, difference
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M

if TYPE_CHECKING:
    from odocan.host.judge.liveplace import Gap
    from odocan.host.judge.reference import ReferenceOdometry


@dataclass
class Second:
    """A second hole's choice: its frame and span (bus times), the sample held before it (the
    rigid move's base), the twins that took its step (of the reference, of the first choice's
    twin) and their poses by frame, and its gap (a placement part when taken)."""

    seq: int
    span_s: tuple[float, float]
    base: FramePose
    twin: ReferenceOdometry
    first_twin: ReferenceOdometry
    gap: Gap | None
    twin_at: dict[int, FramePose] = field(default_factory=dict)
    first_twin_at: dict[int, FramePose] = field(default_factory=dict)


def opened(seq: int, span_s: tuple[float, float], base: FramePose, twins: tuple[
        ReferenceOdometry, ReferenceOdometry], taken: tuple[int, int], gap: Gap | None) -> Second:
    """A second choice at encoder frame ``seq`` (``span_s``), its step ``taken`` (counts): the
    ``twins`` (the reference, the first choice's twin) copied and stepped by it."""
    twin, first_twin = copy.copy(twins[0]), copy.copy(twins[1])
    twin.step_deltas(*taken)
    first_twin.step_deltas(*taken)
    return Second(seq, span_s, base, twin, first_twin, gap)


def stepped(second: Second, seq: int, step: tuple[int, int] | None) -> None:
    """Encoder frame ``seq`` stepped the reference by ``step``: both twins step too (not at
    the hole's frame, which they stepped at ``opened``) and keep their poses there."""
    if step is not None and seq != second.seq:
        second.twin.step_deltas(*step)
        second.first_twin.step_deltas(*step)
    second.twin_at[seq] = _pose(seq, second.twin)
    second.first_twin_at[seq] = _pose(seq, second.first_twin)


def take(second: Second, at: dict[int, FramePose], pose: FramePose) -> bool:
    """Whether the on-board ``pose`` (the first naming the hole's frame or later) lies strictly
    nearer the twin that took the step than the reference (its poses ``at``), both moved
    rigidly from their poses at the base sample's frame onto that sample (module docstring)."""
    base = second.base
    ref_base, ref_pose = at.get(base.seq), at.get(pose.seq)
    took = second.twin_at.get(pose.seq)
    if ref_base is None or ref_pose is None or took is None:
        return False
    return _lsbs(pose, _moved(took, ref_base, base)) < _lsbs(pose, _moved(ref_pose, ref_base,
                                                                          base))


def _moved(p: FramePose, a: FramePose, b: FramePose) -> FramePose:
    """``p`` moved by the rigid motion that takes pose ``a`` onto pose ``b``."""
    turn = b.heading_rad - a.heading_rad
    c, s = math.cos(turn), math.sin(turn)
    dx, dy = p.x_m - a.x_m, p.y_m - a.y_m
    return FramePose(p.seq, b.x_m + c * dx - s * dy, b.y_m + s * dx + c * dy,
                     p.heading_rad + turn)


def _pose(seq: int, ref: ReferenceOdometry) -> FramePose:
    return FramePose(seq, ref.x_m, ref.y_m, ref.heading_rad)


def _lsbs(pose: FramePose, ref: FramePose) -> float:
    """How far ``pose`` lies from ``ref``: position and heading in LSBs, summed."""
    off = difference(pose, ref)
    return off["dpos_m"] / POSITION_LSB_M + abs(off["dheading_rad"]) / HEADING_LSB_RAD
