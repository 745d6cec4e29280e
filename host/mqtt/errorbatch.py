"""The samples behind one ``error`` publication of the bridge (``host.mqtt.telemetry``).

The bridge publishes the latest sample at most ``publish_hz`` times a second; the samples
between are judged (``status.pose_wrongs`` latches them) but not published. The live judge's
holds (``livenewstart``: a new start's first second, ``livelaphold``: a lap of the stamps,
``livepagelaps``: the pages' numbering) release the samples they held all at once, so a batch
of a second of samples came out as its last one alone: a wrong sample among them was never on
``error`` (the straight 32-bit drive of ``tests/test_live_unseen_restart.py`` with X 3 LSB off at
one pose in the new start's hold: 51 samples released together, the wrong one not published).

``SinceLast`` counts the samples compared since the previous ``error`` publication (this one
included) and keeps the worst of those beyond ``analyze``'s limit (``livefit.pose_wrong``, with
each one's loss allowance as it stands); ``error.since_last`` carries them when there was one
(``samples``, ``wrong``, ``worst``: ``t_s``, ``enc_seq``, ``pose_vs_reference``,
``allowance_m``), so a wrong sample is never hidden behind a right last one. A drive with no
sample wrong publishes exactly what it did (no ``since_last``). The check costs a ``hypot`` per
sample: a sample within one LSB of position and of raw heading is right whatever its allowance.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

from odocan.host.judge.livefit import pose_wrong
from odocan.host.judge.livepose import Sample, difference
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M


class SinceLast:
    """The samples compared since the last ``error`` publication (module docstring)."""

    __slots__ = ("samples", "worst", "worst_lsb", "wrong")

    def __init__(self) -> None:
        self.samples = 0
        self.wrong = 0
        self.worst: dict[str, Any] | None = None
        self.worst_lsb = 0.0

    def add(self, samples: Iterable[Sample], allowance_m: Callable[[int], float]) -> None:
        """Samples settled (any order); ``allowance_m``: their loss allowance by frame (m)."""
        for sample in samples:
            pose, ref = sample.pose, sample.reference
            if ref is None or ref.seq != pose.seq:
                continue
            self.samples += 1
            if (math.hypot(pose.x_m - ref.x_m, pose.y_m - ref.y_m) <= POSITION_LSB_M
                    and abs(pose.heading_rad - ref.heading_rad) <= HEADING_LSB_RAD):
                continue  # right whatever its allowance (the usual sample: no dict made)
            self._judge(sample, allowance_m(pose.seq))

    def _judge(self, sample: Sample, allowed_m: float) -> None:
        assert sample.reference is not None
        vs_ref = difference(sample.pose, sample.reference)
        if not pose_wrong(vs_ref["dpos_m"], vs_ref["dheading_rad"], allowed_m):
            return
        self.wrong += 1
        lsb = max((vs_ref["dpos_m"] - allowed_m) / POSITION_LSB_M,
                  abs(vs_ref["dheading_rad"]) / HEADING_LSB_RAD)
        if lsb > self.worst_lsb:
            self.worst_lsb = lsb
            self.worst = {"t_s": sample.t_s, "enc_seq": sample.pose.seq,
                          "pose_vs_reference": vs_ref, "allowance_m": allowed_m}

    def take(self) -> dict[str, Any] | None:
        """``since_last`` for the ``error`` published now (None when no sample since the last
        one was wrong), and start counting afresh."""
        out = (None if not self.wrong else
               {"samples": self.samples, "wrong": self.wrong, "worst": self.worst})
        self.samples = self.wrong = 0
        self.worst, self.worst_lsb = None, 0.0
        return out
