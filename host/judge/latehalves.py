"""The two halves of one pose named together by the late-naming rule (``host.judge.latenames``;
issue #11: its first cut moved the ODOM_POSE_Y half of poses it read 120 ms late and left
their on-time X half where heard, so X and Y of one pose named frames 12 apart: a heading
error of exactly 2*pi and 48.3 mm off a correct firmware under ``delay=0.1:200``).

The firmware sends ODOM_POSE_X and ODOM_POSE_Y of one pose at one tick with one COUNTER and
one ENC_COUNTER. A half the rule moves to the place it was sent has its partner: the accepted
half of the other message with the same COUNTER and ENC_COUNTER heard within half a COUNTER
lap of it (unique there: the pair laps in 16 pose periods). Where the partner's send (its own
reading) lies within half a period of the moved half's, both are named at one place, the
partner's when it was heard in order (its bus place is where the pose was sent). Where it lies
elsewhere, the partner contradicts the move, which is undone: the half is named where it was
heard, as without the rule. A half without a partner keeps its move (its partner was lost or
refused: nothing to name it with).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, POSE_PERIOD_S

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
AGREE_PERIODS = 0.5  # two halves' sends this close: one tick's
NEAR_PERIODS = ENC_COUNTER_LAP // 2  # a partner heard within half a lap: the one of that pair


@dataclass
class Half:
    """One message's accepted pose frames: bus positions and stamps as heard, the place and
    send time the rule names each at (``latenames.sent_places``), COUNTER and ENC_COUNTER."""

    index: IntArray
    stamp_s: FloatArray
    place: IntArray
    sent_s: FloatArray
    counter: IntArray
    enc_counter: IntArray

    def moved(self) -> npt.NDArray[np.intp]:
        """Where the rule named a frame elsewhere than where it was heard."""
        return np.flatnonzero(self.place != self.index)

    def undo(self, k: int) -> None:
        """Frame ``k`` named where it was heard."""
        self.place[k], self.sent_s[k] = self.index[k], self.stamp_s[k]


def halves_together(x: Half, y: Half, period_s: float = POSE_PERIOD_S) -> None:
    """Each moved half of ``x`` and ``y`` named with its partner, or where heard (module
    docstring); in place."""
    for own, other in ((x, y), (y, x)):
        for k in own.moved().tolist():
            _with_partner(own, other, k, period_s)


def _with_partner(own: Half, other: Half, k: int, period_s: float) -> None:
    """Moved frame ``k`` of ``own`` named with its partner in ``other`` (module docstring)."""
    near = np.abs(other.stamp_s - own.stamp_s[k]) < NEAR_PERIODS * period_s
    partner = np.flatnonzero(near & (other.counter == own.counter[k])
                             & (other.enc_counter == own.enc_counter[k]))
    if len(partner) == 0:
        return
    j = int(partner[np.argmin(np.abs(other.sent_s[partner] - own.sent_s[k]))])
    if abs(float(other.sent_s[j] - own.sent_s[k])) > AGREE_PERIODS * period_s:
        own.undo(k)
        return
    if other.place[j] == other.index[j]:  # heard in order: where the pose was sent
        own.place[k], own.sent_s[k] = other.index[j], other.stamp_s[j]
